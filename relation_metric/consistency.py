"""Filter consistency: normalised estimation error squared (NEES) and its χ² gates.

For an estimate ``x̂`` with covariance ``P`` of a true state ``x`` (d dimensions), the NEES is
``ε = (x − x̂)ᵀ P⁻¹ (x − x̂)`` (Bar-Shalom, Li & Kirubarajan 2001, Sec. 5.4). For a consistent
Gaussian estimator ``ε ~ χ²(d)``; averaged over R independent Monte Carlo runs,
``R · ε̄ ~ χ²(R d)``, so the two-sided ``p`` band of the average NEES is
``[χ²⁻¹((1 − p)/2; R d) / R, χ²⁻¹((1 + p)/2; R d) / R]``. For SE(2) poses the error is taken
as ``[x − x̂, y − ŷ, wrap(θ − θ̂)]`` (the filter's own parameterisation).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relation_metric import se2
from relation_metric.errors import InputError

__all__ = ["nees", "pose_nees", "nees_band", "NeesSummary", "summarize_nees"]


def nees(errors: ArrayLike, covariances: ArrayLike) -> NDArray[np.float64]:
    """``eᵀ P⁻¹ e`` for each of N errors.

    Parameters
    ----------
    errors : array_like, shape (N, d)
    covariances : array_like, shape (N, d, d)
        Symmetric positive definite.

    Returns
    -------
    ndarray, shape (N,)
    """
    e = np.asarray(errors, dtype=np.float64)
    p = np.asarray(covariances, dtype=np.float64)
    if e.ndim != 2 or p.shape != e.shape + (e.shape[1],):
        raise InputError(
            f"errors (N, d) and covariances (N, d, d) expected, got {e.shape}, {p.shape}"
        )
    try:
        low = np.linalg.cholesky(p)
    except np.linalg.LinAlgError:
        raise InputError("a covariance is not positive definite") from None
    w = np.linalg.solve(low, e[..., None])[..., 0]  # L⁻¹ e, so ‖w‖² = eᵀ P⁻¹ e
    return np.einsum("nd,nd->n", w, w)


def pose_nees(estimate: ArrayLike, truth: ArrayLike, covariances: ArrayLike) -> NDArray[np.float64]:
    """NEES of SE(2) poses ``[x, y, θ]`` (angle difference wrapped), shape (N,)."""
    e = np.asarray(truth, dtype=np.float64) - np.asarray(estimate, dtype=np.float64)
    e[..., 2] = se2.wrap_angle(e[..., 2])
    return nees(e.reshape(-1, 3), np.asarray(covariances).reshape(-1, 3, 3))


def nees_band(dof: int, runs: int = 1, probability: float = 0.95) -> tuple[float, float]:
    """Two-sided ``probability`` band of the average NEES over ``runs`` runs of ``dof`` dims."""
    if dof < 1 or runs < 1 or not 0 < probability < 1:
        raise InputError(
            f"need dof >= 1, runs >= 1, 0 < probability < 1; got {dof}, {runs}, {probability}"
        )
    from scipy.stats import chi2  # here, not at import: scipy.stats costs start-up

    lo, hi = chi2.ppf([(1 - probability) / 2, (1 + probability) / 2], dof * runs)
    return float(lo / runs), float(hi / runs)


@dataclass(frozen=True)
class NeesSummary:
    """Average NEES against its χ² band.

    Attributes
    ----------
    mean : float
        NEES averaged over runs and time steps.
    band : tuple of float
        The band of the per-step average over ``runs`` runs.
    inside : float
        Fraction of time steps whose run-average lies inside the band.
    runs, dof : int
    """

    mean: float
    band: tuple[float, float]
    inside: float
    runs: int
    dof: int

    def as_dict(self) -> dict[str, object]:
        return {
            "mean": self.mean,
            "band": list(self.band),
            "inside": self.inside,
            "runs": self.runs,
            "dof": self.dof,
        }


def summarize_nees(values: ArrayLike, *, dof: int, probability: float = 0.95) -> NeesSummary:
    """Summarise NEES values of shape (runs, steps) (or (steps,) for one run)."""
    v = np.atleast_2d(np.asarray(values, dtype=np.float64))
    runs = v.shape[0]
    band = nees_band(dof, runs, probability)
    avg = v.mean(axis=0)
    inside = float(np.mean((avg >= band[0]) & (avg <= band[1]))) if avg.size else float("nan")
    return NeesSummary(float(v.mean()), band, inside, runs, dof)
