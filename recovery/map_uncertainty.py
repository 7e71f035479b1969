"""How a map's uncertainty enters the recovery: one rule for every form a bundle gives it.

A bundle states its map's uncertainty in one of three forms: the joint covariance
(``map_covariance.npy``), per-landmark covariances only (``map.csv``'s ``cxx,cxy,cyy``), or
none. :func:`map_uncertainty` turns each into one joint covariance ``Σ_m`` (2M × 2M,
landmarks in ``map.csv`` order, ``[x, y]`` each):

* ``joint``: ``Σ_m`` as given (without ``map_covariance.npy``: as ``marginal``);
* ``marginal``: the block-diagonal ``Σ_m = blockdiag(Σ_1, …, Σ_M)`` of the per-landmark
  covariances — landmark errors independent of each other, and *fixed over the run* (each
  landmark's error is the same at every sighting, so ten sightings of one landmark do not
  average its error away);
* ``ignore``: ``Σ_m = 0``, the map taken as exact.

Every estimator uses that one ``Σ_m`` the same way, as the covariance of a map error that is
fixed over the run: the filter as a Schmidt ("consider") state (the pose–map
cross-covariance is carried, the map never changed: :mod:`recovery.ekf`), the smoother and
the batch as a prior on a map correction estimated with the poses (:mod:`recovery.batch_refinement`:
``m = m̂ + L η``, ``η ~ N(0, I)``, ``Σ_m = L Lᵀ``). :attr:`MapUncertainty.factor` is that
``L``: the eigenvectors of ``Σ_m`` scaled by the square roots of its eigenvalues, those below
``RANK_TOLERANCE`` times the largest dropped (exact directions carry no correction), one
eigendecomposition per landmark for the block-diagonal form.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from recovery.bundle import Bundle
from recovery.constants import MAP_MODES
from relation_metric.arrays import Array
from relation_metric.errors import InputError
from relation_metric.trajectory import readonly

__all__ = [
    "MapUncertainty",
    "map_uncertainty",
    "covariance_factor",
    "block_factor",
    "RANK_TOLERANCE",
]

#: Eigenvalues of ``Σ_m`` below this fraction of the largest are taken as exact directions.
RANK_TOLERANCE = 1e-12

_RULES = {
    "joint": "the joint map covariance (map_covariance.npy) as the covariance of a map error "
    "fixed over the run",
    "marginal": "the per-landmark covariances as a block-diagonal joint covariance: landmark "
    "errors independent of each other and fixed over the run",
    "ignore": "none: the map taken as exact",
    "exact": "none: the bundle states no map covariance (map.csv without covariance columns, "
    "no map_covariance.npy), so the map is taken as exact",
}


@dataclass(frozen=True)
class MapUncertainty:
    """The map uncertainty every estimator of a recovery uses (see module doc).

    Attributes
    ----------
    mode : {"joint", "marginal", "ignore", "exact"}
        The form used (``joint`` asked of a bundle without a joint covariance is
        ``marginal``; ``joint`` or ``marginal`` asked of a bundle that states no map
        covariance at all is ``exact``, not reported as a form it does not have).
    rule : str
        The assumption, in words (written into every recovery report).
    covariance : ndarray, shape (2M, 2M) or None
        ``Σ_m``; ``None`` when it is zero (no map uncertainty).
    marginals : ndarray, shape (M, 2, 2)
        Its diagonal blocks.
    factor : ndarray, shape (2M, r)
        ``L`` with ``L Lᵀ = Σ_m`` (``r = 0`` without map uncertainty).
    """

    mode: str
    rule: str
    covariance: Array | None
    marginals: Array
    factor: Array

    @property
    def rank(self) -> int:
        """``r``, the number of independent map-error directions."""
        return int(self.factor.shape[1])

    def as_dict(self) -> dict[str, object]:
        return {"mode": self.mode, "rule": self.rule, "rank": self.rank}


def map_uncertainty(bundle: Bundle, mode: str = "joint") -> MapUncertainty:
    """The one ``Σ_m`` of ``bundle`` under ``mode`` (``joint``, ``marginal``, ``ignore``).

    Raises
    ------
    InputError
        For an unknown ``mode``.
    """
    if mode not in MAP_MODES:
        raise InputError(f"unknown map mode {mode!r}; expected one of {', '.join(MAP_MODES)}")
    m = bundle.map_xy.shape[0]
    if mode == "joint" and bundle.map_covariance is None:
        mode = "marginal"
    if mode == "marginal" and not bundle.map_marginals.any():
        mode = "exact"  # no covariance stated: the map is exact, and said so
    if mode in ("ignore", "exact"):
        cov = None
        marg = np.zeros((m, 2, 2))
        factor = np.zeros((2 * m, 0))
    elif mode == "joint":
        assert bundle.map_covariance is not None
        cov = 0.5 * (bundle.map_covariance + bundle.map_covariance.T)
        ar = np.arange(m)
        marg = cov.reshape(m, 2, m, 2)[ar, :, ar, :]  # the diagonal blocks, (M, 2, 2)
        factor = covariance_factor(cov)
    else:
        marg = 0.5 * (bundle.map_marginals + bundle.map_marginals.transpose(0, 2, 1))
        blocks = np.zeros((m, 2, m, 2))
        ar = np.arange(m)
        blocks[ar, :, ar, :] = marg
        cov = blocks.reshape(2 * m, 2 * m)
        factor = block_factor(marg)
    if factor.shape[1] == 0:
        cov = None
    return MapUncertainty(
        mode=mode,
        rule=_RULES[mode],
        covariance=None if cov is None else readonly(cov),
        marginals=readonly(marg),
        factor=readonly(factor),
    )


def covariance_factor(cov: Array) -> Array:
    """``L`` (2M, r) with ``L Lᵀ = cov``: its Cholesky factor (r = 2M) when ``cov`` is
    positive definite with every pivot above :data:`RANK_TOLERANCE` of the largest diagonal
    entry, else from its eigendecomposition with the small eigenvalues dropped (r < 2M).

    Any ``L`` with ``L Lᵀ = Σ_m`` gives the same map error law ``L η``, ``η ~ N(0, I)``: the
    factor only chooses the coordinates ``η``; Cholesky, when it succeeds, is the cheaper one
    (benchmarks/README.md).
    """
    if cov.size == 0:
        return np.zeros((cov.shape[0], 0))
    try:
        chol = np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        chol = None
    if chol is not None:
        piv = np.diagonal(chol) ** 2
        if piv.min() > RANK_TOLERANCE * float(np.diagonal(cov).max()):
            return np.asarray(chol, dtype=np.float64)
    w, v = np.linalg.eigh(cov)
    top = float(w.max(initial=0.0))
    keep = w > RANK_TOLERANCE * top if top > 0.0 else np.zeros(w.shape, dtype=bool)
    return np.asarray(v[:, keep] * np.sqrt(w[keep]), dtype=np.float64)


def block_factor(marg: Array) -> Array:
    """``L`` (2M, r) of ``blockdiag(marg)``, ``marg`` (M, 2, 2): each landmark's own
    directions, in landmark order."""
    m = marg.shape[0]
    if m == 0:
        return np.zeros((0, 0))
    w, v = np.linalg.eigh(marg)  # (M, 2), (M, 2, 2)
    top = float(w.max(initial=0.0))
    keep = w > RANK_TOLERANCE * top if top > 0.0 else np.zeros(w.shape, dtype=bool)
    lm, which = np.nonzero(keep)
    factor = np.zeros((2 * m, lm.shape[0]))
    cols = np.arange(lm.shape[0])
    scale = np.sqrt(w[lm, which])
    factor[2 * lm, cols] = v[lm, 0, which] * scale
    factor[2 * lm + 1, cols] = v[lm, 1, which] * scale
    return factor
