"""Do two estimates of one trajectory agree within their stated covariances? No truth needed.

For a filter (``a``: the estimate of pose ``k`` from the data up to ``k``) and a smoother
(``b``: from all the data) of the same model, the smoother's error ``e_b = x − x̂_b`` is
orthogonal to every function of the data, so to ``x̂_b − x̂_a``; hence
``Cov(e_a, e_b) = Cov(e_b + (x̂_b − x̂_a), e_b) = P_b`` and the difference
``d = x̂_a − x̂_b = e_b − e_a`` has

    Cov(d) = P_a + P_b − 2 P_b = P_a − P_b.

This holds for any estimator ``a`` that is a function of the data and whose ``P_a`` is its
true error covariance (a Schmidt filter's is), and for the online estimate of a filter against
the recovered smoother of the same posterior. With consistent covariances
``T_k = d_kᵀ (P_a − P_b)⁻¹ d_k`` is χ²(3) at every pose; a filter that diverges, or
covariances that are too small, make it large. The statistic needs no ground truth.

``P_a − P_b`` is singular where the smoother adds nothing (the last pose) and, after
relinearisation, need not be exactly positive semi-definite. So ``T_k`` is taken in the
directions where the smoother removed at least :data:`MIN_GAIN` of the filter's variance:
whitened by ``P_a = L Lᵀ``, ``G = I − L⁻¹ P_b L⁻ᵀ`` has eigenvalues ``g`` in ``[0, 1]`` for a
consistent pair (the share of each direction's variance the smoother removed), ``T_k`` sums
``(uᵀ L⁻¹ d)² / g`` over the eigenvectors with ``g ≥ MIN_GAIN`` and its dof is their number;
directions with ``g < −MIN_GAIN`` (the smoother more uncertain than the filter) are counted.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relation_metric.se2 import wrap_angle

__all__ = ["MIN_GAIN", "Agreement", "estimate_agreement"]

#: Smallest share of a direction's filter variance the smoother must remove for the
#: direction to count (below it ``d`` and ``g`` are both rounding).
MIN_GAIN = 1e-3


@dataclass(frozen=True)
class Agreement:
    """Per pose ``T_k`` and its dof (``(N,)`` each; dof 0: no direction counted), and the
    number of directions where the later estimate claimed more variance than the earlier."""

    values: NDArray[np.float64]
    dof: NDArray[np.int64]
    negative: int

    @property
    def q(self) -> float:
        """``Σ T_k / Σ dof_k``: 1 for consistent estimates (NaN without any dof)."""
        n = int(self.dof.sum())
        return float(self.values.sum() / n) if n else float("nan")

    @property
    def per_dof(self) -> NDArray[np.float64]:
        """``T_k / dof_k`` at the poses with a dof (for the effective sample size)."""
        keep = self.dof > 0
        return self.values[keep] / self.dof[keep]


def estimate_agreement(x_a: ArrayLike, p_a: ArrayLike, x_b: ArrayLike, p_b: ArrayLike) -> Agreement:
    """:class:`Agreement` of an earlier estimate ``a`` (poses ``(N, 3)`` ``[x, y, θ]``,
    covariances ``(N, 3, 3)``) with a later one ``b`` of the same poses (module doc).
    ``d = x_a − x_b`` componentwise, heading wrapped. Poses whose ``P_a`` is not finite
    positive definite get dof 0."""
    xa, xb = np.asarray(x_a, dtype=np.float64), np.asarray(x_b, dtype=np.float64)
    pa, pb = np.asarray(p_a, dtype=np.float64), np.asarray(p_b, dtype=np.float64)
    d = xa - xb
    d[:, 2] = wrap_angle(d[:, 2])
    n = d.shape[0]
    ok: NDArray[np.bool_] = np.asarray(
        np.isfinite(pa).all(axis=(1, 2))
        & np.isfinite(pb).all(axis=(1, 2))
        & np.isfinite(d).all(axis=1)
    )
    ok[ok] = np.linalg.eigvalsh(pa[ok]).min(axis=1) > 0.0
    values, dof = np.zeros(n), np.zeros(n, dtype=np.int64)
    if not ok.any():
        return Agreement(values, dof, 0)
    low = np.linalg.cholesky(pa[ok])  # P_a = L Lᵀ
    inv = np.linalg.inv(low)
    g = np.eye(3) - inv @ pb[ok] @ np.swapaxes(inv, 1, 2)
    gain, u = np.linalg.eigh(0.5 * (g + np.swapaxes(g, 1, 2)))
    z = np.einsum("kji,kj->ki", u, np.einsum("kij,kj->ki", inv, d[ok]))  # uᵀ L⁻¹ d
    use = gain >= MIN_GAIN
    values[ok] = np.where(use, z * z / np.where(use, gain, 1.0), 0.0).sum(axis=1)
    dof[ok] = use.sum(axis=1)
    return Agreement(values, dof, int((gain < -MIN_GAIN).sum()))
