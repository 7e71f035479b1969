"""Batch MAP refinement of a recovered trajectory with the map fixed (Gauss–Newton / LM).

Minimises ``½ Σ rᵀ W r`` over all grid poses ``X`` (N × 3) with

* a prior ``X₀ − x̄₀`` (angle wrapped), ``W = P₀⁻¹``;
* one motion residual per step ``between(X_k, X_{k+1}) − u_k`` (angle wrapped),
  ``W = (Σ_k + ε_k I)⁻¹`` — the increment model of :mod:`recovery.models`; ``ε_k = 1e-6
  tr(Σ_k)/3 + 1e-14`` regularises the rank-2 covariance of the velocity model (a lateral
  slip with a standard deviation of 0.1% of the model's noise);
* one range-bearing residual per measurement the filter used, ``z − h(X_k, l)`` (bearing
  wrapped), ``W = (R + H_l Σ_l H_lᵀ)⁻¹`` (the landmark's marginal covariance).

The normal equations are block tridiagonal (each measurement touches one pose, the map is
fixed); they are assembled as a ``scipy.sparse`` matrix and solved with SuperLU; Levenberg's
damping ``λ diag(H)`` is raised when a step does not reduce the cost. Per-pose covariances are
the diagonal blocks of ``H⁻¹`` at the solution, computed by the extended filter/RTS
covariance recursion linearised at the solution (exact for a block-tridiagonal information
matrix, and vectorised like the smoother).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.sparse.linalg import spsolve

from recovery.ekf import FilterInput, run_filter
from recovery.models import range_bearing
from recovery.smoother import smooth
from relation_metric import se2
from relation_metric.arrays import Array
from relation_metric.errors import DivergenceError

__all__ = ["BatchResult", "refine", "normal_equations"]


@dataclass(frozen=True)
class BatchResult:
    """Refined poses (N, 3), covariances (N, 3, 3), iterations and costs (½ rᵀ W r)."""

    poses: Array
    covariances: Array
    iterations: int
    cost_initial: float
    cost_final: float


def regularised_sigma(sigma: Array) -> Array:
    """``Σ_k + ε_k I`` with ``ε_k = 1e-6 tr(Σ_k)/3 + 1e-14`` (see module doc)."""
    eps = 1e-6 * np.trace(sigma, axis1=1, axis2=2) / 3.0 + 1e-14
    return sigma + eps[:, None, None] * np.eye(3)


def _residuals(  # type: ignore[no-untyped-def]
    inp: FilterInput,
    x: Array,
    w_motion: Array,
    used: NDArray[np.int64],
    robust: Array | None = None,
):
    """Residuals, weights and Jacobians of all factors at ``x``.

    ``robust`` (J,): the filter's robust weight per measurement; the measurement information
    ``(R + H_l Σ_l H_lᵀ)⁻¹`` is multiplied by it (the filter divides the same matrix by it).
    """
    rp = x[0] - inp.x0
    rp[2] = se2.wrap_angle(rp[2])
    rm = se2.between(x[:-1], x[1:]) - inp.u
    rm[:, 2] = se2.wrap_angle(rm[:, 2])
    k = inp.meas_grid[used]
    li = inp.meas_landmark[used]
    z_hat, h_x, h_l = range_bearing(x[k], inp.map_xy[li])
    rz = inp.meas_z[used] - z_hat
    rz[:, 1] = se2.wrap_angle(rz[:, 1])
    reff = inp.r + h_l @ inp.map_marginals[li] @ h_l.transpose(0, 2, 1)
    wz = np.linalg.inv(reff)
    if robust is not None:
        wz = wz * robust[used][:, None, None]
    return rp, rm, rz, wz, h_x, k


def _cost(rp: Array, wp: Array, rm: Array, wm: Array, rz: Array, wz: Array) -> float:
    return 0.5 * float(
        rp @ wp @ rp + np.einsum("ni,nij,nj->", rm, wm, rm) + np.einsum("ni,nij,nj->", rz, wz, rz)
    )


def normal_equations(
    inp: FilterInput,
    x: Array,
    used: NDArray[np.int64],
    sigma: Array | None = None,
    robust: Array | None = None,
):  # type: ignore[no-untyped-def]
    """Sparse ``H = Jᵀ W J`` (3N × 3N), gradient ``g = Jᵀ W r`` (3N,) and the cost at ``x``."""
    n = x.shape[0]
    wp = np.linalg.inv(inp.p0 + 1e-15 * np.eye(3))
    wm = np.linalg.inv(regularised_sigma(inp.sigma if sigma is None else sigma))
    rp, rm, rz, wz, h_x, k = _residuals(inp, x, wm, used, robust)
    _, ja, jb = se2.between(x[:-1], x[1:], jacobians=True)
    jat_w = ja.transpose(0, 2, 1) @ wm
    jbt_w = jb.transpose(0, 2, 1) @ wm
    diag = np.zeros((n, 3, 3))
    diag[0] += wp
    diag[:-1] += jat_w @ ja
    diag[1:] += jbt_w @ jb
    off = jat_w @ jb
    jz = -h_x
    jzt_w = jz.transpose(0, 2, 1) @ wz
    np.add.at(diag, k, jzt_w @ jz)
    g = np.zeros((n, 3))
    g[0] += wp @ rp
    g[:-1] += np.einsum("nij,nj->ni", jat_w, rm)
    g[1:] += np.einsum("nij,nj->ni", jbt_w, rm)
    np.add.at(g, k, np.einsum("nij,nj->ni", jzt_w, rz))
    ii, jj = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
    bd = 3 * np.arange(n)[:, None, None]
    bo = 3 * np.arange(n - 1)[:, None, None]
    rows = np.concatenate(((bd + ii).ravel(), (bo + ii).ravel(), (bo + 3 + jj).ravel()))
    cols = np.concatenate(((bd + jj).ravel(), (bo + 3 + jj).ravel(), (bo + ii).ravel()))
    data = np.concatenate((diag.ravel(), off.ravel(), off.ravel()))
    h = sp.coo_array((data, (rows, cols)), shape=(3 * n, 3 * n)).tocsc()
    cost = _cost(rp, wp, rm, wm, rz, wz)
    return h, g.ravel(), cost, (wp, wm)


def _cost_at(  # type: ignore[no-untyped-def]
    inp: FilterInput, x: Array, used: NDArray[np.int64], wp: Array, wm: Array, robust=None
) -> float:
    rp, rm, rz, wz, _, _ = _residuals(inp, x, wm, used, robust)
    return _cost(rp, wp, rm, wm, rz, wz)


def refine(
    inp: FilterInput,
    start: Array,
    *,
    used: NDArray[np.bool_],
    weights: Array | None = None,
    max_iterations: int = 50,
    tolerance: float = 1e-10,
) -> BatchResult:
    """Levenberg–Marquardt from ``start`` (N, 3) over all poses, map fixed (see module doc).

    Parameters
    ----------
    inp : FilterInput
    start : ndarray, shape (N, 3)
        Initial poses (the smoothed trajectory).
    used : ndarray of bool, shape (J,)
        Measurements that enter (those the filter used).
    weights : ndarray, shape (J,), optional
        The filter's robust weights (:attr:`recovery.ekf.FilterResult.weights`): the batch
        uses the same robust model as the filter and the smoother.
    max_iterations : int
    tolerance : float
        Stop when the relative cost reduction or the largest step falls below it.

    Returns
    -------
    BatchResult
    """
    idx = np.flatnonzero(used)
    x = np.array(start, dtype=np.float64, copy=True)
    h, g, cost, (wp, wm) = normal_equations(inp, x, idx, robust=weights)
    cost0 = cost
    lam = 1e-6
    iterations = 0
    for _ in range(max_iterations):
        iterations += 1
        d = h.diagonal()
        while True:
            a = h + sp.diags_array(lam * d)
            step = -spsolve(a.tocsc(), g).reshape(-1, 3)
            if not np.isfinite(step).all():
                raise DivergenceError("batch refinement: the normal equations are singular")
            trial = x + step
            new_cost = _cost_at(inp, trial, idx, wp, wm, weights)
            if new_cost <= cost:
                break
            lam *= 10.0
            if lam > 1e12:
                break
        if new_cost > cost:
            break
        x = trial
        reduction = (cost - new_cost) / max(cost, 1e-300)
        lam = max(lam / 10.0, 1e-12)
        h, g, cost, _ = normal_equations(inp, x, idx, robust=weights)
        if reduction < tolerance or np.abs(step).max() < tolerance:
            break
    x[:, 2] = se2.wrap_angle(x[:, 2])
    covs = batch_covariances(inp, x, used, weights)
    return BatchResult(x, covs, iterations, cost0, cost)


def batch_covariances(
    inp: FilterInput, x: Array, used: NDArray[np.bool_], weights: Array | None = None
) -> Array:
    """Diagonal blocks of ``H⁻¹`` at ``x``: filter + RTS covariance pass linearised at ``x``."""
    reg = replace(inp, sigma=regularised_sigma(inp.sigma), map_covariance=None)
    fr = run_filter(reg, linearize_at=x, use=used, weights=weights, max_outlier_run=None)
    return smooth(fr).covariances
