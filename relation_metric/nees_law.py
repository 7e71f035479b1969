"""The law of a mean NEES when the poses' errors share one error (a map's).

The mean NEES of ``N`` poses, ``Q = (1/N) Σ_k e_kᵀ P_k⁻¹ e_k``, is a quadratic form
``eᵀ A e`` in the stacked errors ``e`` (Nd,), ``A = blockdiag(P_k⁻¹) / N``. For jointly
Gaussian errors ``e ~ N(0, Σ)`` (any cross-covariances ``Σ_kl``):

* ``E[Q] = tr(A Σ)`` — ``d`` when ``P_k = Σ_kk``, whatever the cross terms;
* ``Var[Q] = 2 tr(A Σ A Σ)`` — the cross terms widen it: ``2d/N`` for independent poses,
  up to ``2d`` when every pose carries the same error.

``Q`` is a weighted sum of ``χ²(1)`` values (the eigenvalues of ``Σ^{1/2} A Σ^{1/2}``); matched
on these two moments by a scaled ``g χ²(h)`` (Welch–Satterthwaite), ``g = Var / (2 E)``,
``h = 2 E² / Var``. The lamp's interval of a mean of ``n`` independent ``χ²(d)`` values is
``χ²(n d) / (n d)``, so ``n_eff = h / d`` is the honest effective number of poses.

**The shared-map form** (:func:`shared_error_law`). A pose recovered in a map carries the
map's error: ``e_k = a_k + V_k ξ``, ``ξ ~ N(0, I_r)`` the same for every pose (``V`` the
loadings of :meth:`recovery.batch_refinement._JointProblem.map_loadings`), ``a_k`` the log's
share, ``Cov(a_k) = P_k − V_k V_kᵀ``. Whitened by ``P_k = L_k L_kᵀ``, ``U_k = L_k⁻¹ V_k``,
``D_k = I − U_k U_kᵀ``, and with the ``a_k`` taken independent between poses:

``tr(AΣAΣ) N² = Σ_k ‖D_k‖²_F + 2 Σ_k tr(U_kᵀ D_k U_k) + ‖Σ_k U_kᵀ U_k‖²_F``

— O(N d r²), no (Nd × Nd) matrix. The log's own errors are correlated in time too (an odometry
chain between sightings); ``local_factor`` ``τ ≥ 1`` multiplies their two terms for that
(the caller's estimate of their integrated autocorrelation time; 1: independent).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from relation_metric.errors import InputError

__all__ = ["NeesLaw", "quadratic_form_law", "shared_error_law"]


@dataclass(frozen=True)
class NeesLaw:
    """The first two moments of a mean NEES ``Q`` (per pose, ``d`` dof each)."""

    mean: float
    variance: float
    dof: int

    @property
    def chi2_dof(self) -> float:
        """``h = 2 E² / Var`` of the moment-matched ``g χ²(h)``."""
        return 2.0 * self.mean**2 / self.variance if self.variance > 0 else math.inf

    @property
    def scale(self) -> float:
        """``g = Var / (2 E)``."""
        return self.variance / (2.0 * self.mean)

    @property
    def n_eff(self) -> float:
        """``h / d``: the number of independent ``χ²(d)`` values whose mean has this law."""
        return self.chi2_dof / self.dof


def quadratic_form_law(covariances: ArrayLike, sigma: ArrayLike) -> NeesLaw:
    """``E`` and ``Var`` of ``Q = (1/N) Σ e_kᵀ P_k⁻¹ e_k`` for ``e ~ N(0, sigma)``, directly:
    ``tr(AΣ)`` and ``2 tr(AΣAΣ)`` with the dense ``A`` (for checks and small ``N``).

    ``covariances`` (N, d, d) the ``P_k``; ``sigma`` (Nd, Nd) the errors' joint covariance,
    pose-major (rows ``k d … k d + d − 1`` pose ``k``).
    """
    p = np.asarray(covariances, dtype=np.float64)
    s = np.asarray(sigma, dtype=np.float64)
    n, d = p.shape[0], p.shape[1]
    if s.shape != (n * d, n * d):
        raise InputError(f"sigma must be ({n * d}, {n * d}) for {n} poses of {d}; got {s.shape}")
    a = np.zeros((n * d, n * d))
    inv = np.linalg.inv(p) / n
    for k in range(n):  # a check, not a hot path
        a[k * d : (k + 1) * d, k * d : (k + 1) * d] = inv[k]
    m = a @ s
    return NeesLaw(float(np.trace(m)), float(2.0 * np.sum(m * m.T)), d)


def shared_error_law(
    covariances: ArrayLike, loadings: ArrayLike, *, local_factor: float = 1.0
) -> NeesLaw:
    """The law of the mean NEES of poses whose errors share ``ξ`` (module doc).

    Parameters
    ----------
    covariances : array_like, shape (N, d, d)
        The stated ``P_k`` (positive definite), each the total covariance of ``e_k``.
    loadings : array_like, shape (N, d, r)
        ``V_k``: ``e_k = a_k + V_k ξ``, ``ξ ~ N(0, I_r)``; ``r = 0``: no shared error.
    local_factor : float
        ``τ ≥ 1`` on the log's terms (their correlation in time; 1: independent).

    Raises
    ------
    InputError
        For mismatched shapes or a covariance that is not positive definite.
    """
    p = np.asarray(covariances, dtype=np.float64)
    v = np.asarray(loadings, dtype=np.float64)
    if p.ndim != 3 or v.ndim != 3 or v.shape[:2] != p.shape[:2] or p.shape[1] != p.shape[2]:
        raise InputError(
            f"covariances (N, d, d) and loadings (N, d, r) expected; got {p.shape}, {v.shape}"
        )
    n, d = p.shape[0], p.shape[1]
    try:
        chol = np.linalg.cholesky(p)
    except np.linalg.LinAlgError as e:
        raise InputError("a covariance is not positive definite") from e
    u = np.linalg.solve(chol, v)  # L_k⁻¹ V_k, (N, d, r)
    dd = np.eye(d) - u @ u.transpose(0, 2, 1)
    local = float(np.sum(dd * dd))
    cross = float(np.einsum("nia,nij,nja->", u, dd, u))
    flat = u.reshape(n * d, -1)
    g = flat.T @ flat if flat.shape[1] <= flat.shape[0] else flat @ flat.T
    var = 2.0 * (max(local_factor, 1.0) * (local + 2.0 * cross) + float(np.sum(g * g))) / n**2
    return NeesLaw(float(d), var, d)
