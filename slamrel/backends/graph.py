"""Full least-squares SLAM on a planar pose graph with point landmarks.

The state is all poses ``w_T_k = [x, y, θ]`` and landmark positions ``w_p_l``; the factors
are

* pose–pose ``z_ij ≈ x_i⁻¹ ∘ x_j`` with residual
  ``e = [R_iᵀ (t_j − t_i) − z_t, wrap(θ_j − θ_i − z_θ)]`` (the usual planar SLAM form),
* pose–landmark ``z_kl ≈ x_k⁻¹ · l`` with residual ``e = R_kᵀ (l − t_k) − z``,
* a prior on the first pose that fixes the gauge.

Each residual is whitened by the upper Cholesky factor of its information matrix and the sum
of squares is minimised by Levenberg–Marquardt (Marquardt's diagonal scaling) on the sparse
normal equations; Jacobians are analytic and assembled without Python loops over factors.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import ArrayLike, NDArray

from relation_metric import se2
from relation_metric.errors import DivergenceError, InputError
from relation_metric.trajectory import readonly

__all__ = ["PoseGraph", "GraphSolution", "solve_graph", "initial_landmarks", "pose_covariances"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class PoseGraph:
    """A planar pose graph with landmarks.

    Parameters
    ----------
    poses : array_like, shape (N, 3)
        Initial guess of the poses.
    landmarks : array_like, shape (L, 2)
        Initial guess of the landmarks (see :func:`initial_landmarks`).
    pp_i, pp_j : array_like of int, shape (E,)
        Pose–pose factors ``x_i⁻¹ ∘ x_j``.
    pp_z : array_like, shape (E, 3)
    pp_info : array_like, shape (E, 3, 3)
        Information (inverse covariance) of each pose–pose measurement.
    pl_k, pl_l : array_like of int, shape (F,)
        Pose–landmark factors: pose index, landmark index.
    pl_z : array_like, shape (F, 2)
        The landmark in the pose frame, ``x_k⁻¹ · l``.
    pl_info : array_like, shape (F, 2, 2)
    """

    poses: Array
    landmarks: Array
    pp_i: NDArray[np.int64]
    pp_j: NDArray[np.int64]
    pp_z: Array
    pp_info: Array
    pl_k: NDArray[np.int64] = field(default_factory=lambda: np.empty(0, np.int64))
    pl_l: NDArray[np.int64] = field(default_factory=lambda: np.empty(0, np.int64))
    pl_z: Array = field(default_factory=lambda: np.empty((0, 2)))
    pl_info: Array = field(default_factory=lambda: np.empty((0, 2, 2)))

    def __post_init__(self) -> None:
        n = np.asarray(self.poses).shape[0]
        m = np.asarray(self.landmarks).reshape(-1, 2).shape[0]
        conv = {
            "poses": ((n, 3), np.float64),
            "landmarks": ((m, 2), np.float64),
            "pp_i": (None, np.int64),
            "pp_j": (None, np.int64),
            "pp_z": (None, np.float64),
            "pp_info": (None, np.float64),
            "pl_k": (None, np.int64),
            "pl_l": (None, np.int64),
            "pl_z": (None, np.float64),
            "pl_info": (None, np.float64),
        }
        for name, (_, dtype) in conv.items():
            arr = np.asarray(getattr(self, name), dtype=dtype)
            if name == "landmarks":
                arr = arr.reshape(-1, 2)
            object.__setattr__(self, name, readonly(arr, dtype))
        e = self.pp_i.shape[0]
        f = self.pl_k.shape[0]
        shapes = {
            "pp_j": (e,),
            "pp_z": (e, 3),
            "pp_info": (e, 3, 3),
            "pl_l": (f,),
            "pl_z": (f, 2),
            "pl_info": (f, 2, 2),
        }
        for name, shape in shapes.items():
            if getattr(self, name).shape != shape:
                raise InputError(f"{name} must have shape {shape}, got {getattr(self, name).shape}")
        for name, idx, size in (
            ("pose-pose i", self.pp_i, n),
            ("pose-pose j", self.pp_j, n),
            ("pose-landmark pose", self.pl_k, n),
            ("pose-landmark landmark", self.pl_l, m),
        ):
            if idx.size and (idx.min() < 0 or idx.max() >= size):
                raise InputError(f"{name} index out of range 0..{size - 1}")
        for name in ("poses", "landmarks", "pp_z", "pp_info", "pl_z", "pl_info"):
            if not np.isfinite(getattr(self, name)).all():
                raise InputError(f"{name} contains non-finite values")

    @property
    def n_poses(self) -> int:
        return int(self.poses.shape[0])

    @property
    def n_landmarks(self) -> int:
        return int(self.landmarks.shape[0])


@dataclass(frozen=True)
class GraphSolution:
    """Result of :func:`solve_graph`.

    Attributes
    ----------
    poses : ndarray, shape (N, 3)
    landmarks : ndarray, shape (L, 2)
    cost : ndarray, shape (iterations + 1,)
        ``½ Σ ‖W e‖²`` after each accepted step (first entry: the initial guess).
    iterations : int
    converged : bool
    """

    poses: Array
    landmarks: Array
    cost: Array
    iterations: int
    converged: bool


def initial_landmarks(
    poses: ArrayLike, pl_k: ArrayLike, pl_l: ArrayLike, pl_z: ArrayLike, n_landmarks: int
) -> Array:
    """Landmark guesses from their first observation: ``x_k · z`` (vectorised)."""
    k = np.asarray(pl_k, dtype=np.int64)
    lm = np.asarray(pl_l, dtype=np.int64)
    out = np.full((n_landmarks, 2), np.nan)
    order = np.lexsort((np.arange(lm.size), lm))
    first = order[np.concatenate(([True], np.diff(lm[order]) != 0))] if lm.size else order
    out[lm[first]] = se2.transform_points(np.asarray(poses)[k[first]], np.asarray(pl_z)[first])
    missing = np.flatnonzero(~np.isfinite(out[:, 0]))
    if missing.size:
        raise InputError(f"landmark {int(missing[0])} is never observed; cannot initialise it")
    return out


def _upper_sqrt(info: Array) -> Array:
    """``W`` with ``Wᵀ W = info`` for a stack of SPD matrices (upper Cholesky factor)."""
    try:
        low = np.linalg.cholesky(info)
    except np.linalg.LinAlgError:
        raise InputError("an information matrix is not positive definite") from None
    return np.swapaxes(low, -1, -2)


def _residuals_and_jacobian(
    g: PoseGraph, x: Array, lm: Array, w_pp: Array, w_pl: Array, prior: tuple[Array, Array]
) -> tuple[Array, sp.csr_matrix]:
    n = x.shape[0]
    # --- pose-pose -------------------------------------------------------------------
    xi, xj = x[g.pp_i], x[g.pp_j]
    c, s = np.cos(xi[:, 2]), np.sin(xi[:, 2])
    dt = xj[:, :2] - xi[:, :2]
    e_pp = np.empty((xi.shape[0], 3))
    e_pp[:, 0] = c * dt[:, 0] + s * dt[:, 1] - g.pp_z[:, 0]
    e_pp[:, 1] = -s * dt[:, 0] + c * dt[:, 1] - g.pp_z[:, 1]
    e_pp[:, 2] = se2.wrap_angle(xj[:, 2] - xi[:, 2] - g.pp_z[:, 2])
    # Jacobian blocks (E, 3, 3) w.r.t. x_i and x_j
    ji = np.zeros((xi.shape[0], 3, 3))
    ji[:, 0, 0], ji[:, 0, 1] = -c, -s
    ji[:, 1, 0], ji[:, 1, 1] = s, -c
    ji[:, 0, 2] = -s * dt[:, 0] + c * dt[:, 1]
    ji[:, 1, 2] = -c * dt[:, 0] - s * dt[:, 1]
    ji[:, 2, 2] = -1.0
    jj = np.zeros_like(ji)
    jj[:, 0, 0], jj[:, 0, 1] = c, s
    jj[:, 1, 0], jj[:, 1, 1] = -s, c
    jj[:, 2, 2] = 1.0
    # --- pose-landmark -----------------------------------------------------------------
    xk = x[g.pl_k]
    ck, sk = np.cos(xk[:, 2]), np.sin(xk[:, 2])
    d = lm[g.pl_l] - xk[:, :2]
    e_pl = np.empty((xk.shape[0], 2))
    e_pl[:, 0] = ck * d[:, 0] + sk * d[:, 1] - g.pl_z[:, 0]
    e_pl[:, 1] = -sk * d[:, 0] + ck * d[:, 1] - g.pl_z[:, 1]
    jk = np.zeros((xk.shape[0], 2, 3))
    jk[:, 0, 0], jk[:, 0, 1] = -ck, -sk
    jk[:, 1, 0], jk[:, 1, 1] = sk, -ck
    jk[:, 0, 2] = -sk * d[:, 0] + ck * d[:, 1]
    jk[:, 1, 2] = -ck * d[:, 0] - sk * d[:, 1]
    jl = np.zeros((xk.shape[0], 2, 2))
    jl[:, 0, 0], jl[:, 0, 1] = ck, sk
    jl[:, 1, 0], jl[:, 1, 1] = -sk, ck
    # --- prior on pose 0 (gauge) -------------------------------------------------------
    p_mean, p_w = prior
    e_pr = x[0] - p_mean
    e_pr[2] = se2.wrap_angle(e_pr[2])
    # --- whiten and assemble -----------------------------------------------------------
    wpp_e = np.einsum("eab,eb->ea", w_pp, e_pp)
    wpl_e = np.einsum("eab,eb->ea", w_pl, e_pl)
    r = np.concatenate((wpp_e.ravel(), wpl_e.ravel(), p_w @ e_pr))
    ji_w = w_pp @ ji
    jj_w = w_pp @ jj
    jk_w = w_pl @ jk
    jl_w = w_pl @ jl
    e_n, f_n = xi.shape[0], xk.shape[0]
    rows_pp = (3 * np.arange(e_n))[:, None, None] + np.arange(3)[None, :, None]
    rows_pl = 3 * e_n + (2 * np.arange(f_n))[:, None, None] + np.arange(2)[None, :, None]
    cols_i = (3 * g.pp_i)[:, None, None] + np.arange(3)[None, None, :]
    cols_j = (3 * g.pp_j)[:, None, None] + np.arange(3)[None, None, :]
    cols_k = (3 * g.pl_k)[:, None, None] + np.arange(3)[None, None, :]
    cols_l = 3 * n + (2 * g.pl_l)[:, None, None] + np.arange(2)[None, None, :]
    prior_rows = 3 * e_n + 2 * f_n + np.arange(3)
    rows = np.concatenate(
        [
            np.broadcast_to(rows_pp, ji_w.shape).ravel(),
            np.broadcast_to(rows_pp, jj_w.shape).ravel(),
            np.broadcast_to(rows_pl, jk_w.shape).ravel(),
            np.broadcast_to(rows_pl, jl_w.shape).ravel(),
            np.repeat(prior_rows, 3),
        ]
    )
    cols = np.concatenate(
        [
            np.broadcast_to(cols_i, ji_w.shape).ravel(),
            np.broadcast_to(cols_j, jj_w.shape).ravel(),
            np.broadcast_to(cols_k, jk_w.shape).ravel(),
            np.broadcast_to(cols_l, jl_w.shape).ravel(),
            np.tile(np.arange(3), 3),
        ]
    )
    vals = np.concatenate([ji_w.ravel(), jj_w.ravel(), jk_w.ravel(), jl_w.ravel(), p_w.ravel()])
    size = 3 * n + 2 * lm.shape[0]
    jac = sp.csr_matrix((vals, (rows, cols)), shape=(r.size, size))
    return r, jac


def _apply(x: Array, lm: Array, delta: Array) -> tuple[Array, Array]:
    n = x.shape[0]
    x_new = x + delta[: 3 * n].reshape(n, 3)
    x_new[:, 2] = se2.wrap_angle(x_new[:, 2])
    lm_new = lm + delta[3 * n :].reshape(-1, 2)
    return x_new, lm_new


def solve_graph(
    graph: PoseGraph,
    *,
    max_iterations: int = 100,
    tolerance: float = 1e-9,
    prior_sigma: float = 1e-6,
) -> GraphSolution:
    """Levenberg–Marquardt on the whitened residuals of ``graph``.

    Parameters
    ----------
    graph : PoseGraph
    max_iterations : int
    tolerance : float
        Stop when the relative cost decrease falls below it.
    prior_sigma : float
        Standard deviation of the gauge prior that holds pose 0 at its initial value.

    Returns
    -------
    GraphSolution

    Raises
    ------
    DivergenceError
        When the cost becomes non-finite.
    """
    w_pp = _upper_sqrt(graph.pp_info)
    w_pl = _upper_sqrt(graph.pl_info) if graph.pl_k.size else np.empty((0, 2, 2))
    prior = (graph.poses[0].copy(), np.eye(3) / prior_sigma)
    x = np.array(graph.poses, dtype=np.float64)
    lm = np.array(graph.landmarks, dtype=np.float64)
    r, jac = _residuals_and_jacobian(graph, x, lm, w_pp, w_pl, prior)
    cost = 0.5 * float(r @ r)
    costs = [cost]
    lam = 1e-4
    converged = False
    it = 0
    for it in range(1, max_iterations + 1):
        jt = jac.T.tocsr()
        h = (jt @ jac).tocsc()
        grad = jt @ r
        diag = h.diagonal()
        improved = False
        for _ in range(20):
            damped = h + sp.diags(lam * np.maximum(diag, 1e-12), format="csc")
            delta = spla.spsolve(damped, -grad)
            if not np.isfinite(delta).all():
                raise DivergenceError("the normal equations are singular (unobserved states?)")
            x_new, lm_new = _apply(x, lm, delta)
            r_new, jac_new = _residuals_and_jacobian(graph, x_new, lm_new, w_pp, w_pl, prior)
            cost_new = 0.5 * float(r_new @ r_new)
            if not np.isfinite(cost_new):
                raise DivergenceError(f"non-finite cost at iteration {it}")
            if cost_new < cost:
                improved = True
                break
            lam *= 10.0
        if not improved:
            converged = True  # no descent possible: at a minimum to working precision
            break
        rel = (cost - cost_new) / max(cost, 1e-300)
        x, lm, r, jac, cost = x_new, lm_new, r_new, jac_new, cost_new
        costs.append(cost)
        lam = max(lam / 10.0, 1e-12)
        if rel < tolerance:
            converged = True
            break
    return GraphSolution(
        poses=readonly(x),
        landmarks=readonly(lm),
        cost=readonly(np.asarray(costs)),
        iterations=it,
        converged=converged,
    )


def pose_covariances(
    graph: PoseGraph,
    solution: GraphSolution,
    indices: ArrayLike | None = None,
    *,
    prior_sigma: float = 1e-6,
) -> Array:
    """Marginal covariances of poses at the solution, ``(H⁻¹)_kk`` with ``H = JᵀJ``.

    Parameters
    ----------
    graph, solution :
        The problem and its solution (the gauge prior of :func:`solve_graph` included).
    indices : array_like of int, optional
        Poses whose 3 × 3 marginals are wanted (default: all).

    Returns
    -------
    ndarray, shape (K, 3, 3)
        Computed with one sparse LU factorisation and a multi-right-hand-side solve.
    """
    w_pp = _upper_sqrt(graph.pp_info)
    w_pl = _upper_sqrt(graph.pl_info) if graph.pl_k.size else np.empty((0, 2, 2))
    prior = (graph.poses[0].copy(), np.eye(3) / prior_sigma)
    _, jac = _residuals_and_jacobian(
        graph, np.asarray(solution.poses), np.asarray(solution.landmarks), w_pp, w_pl, prior
    )
    h = (jac.T @ jac).tocsc()
    idx = np.arange(graph.n_poses) if indices is None else np.asarray(indices, dtype=np.int64)
    cols = (3 * idx[:, None] + np.arange(3)[None, :]).ravel()
    rhs = np.zeros((h.shape[0], cols.size))
    rhs[cols, np.arange(cols.size)] = 1.0
    sol = spla.splu(h).solve(rhs)
    blocks = sol[cols, :].reshape(idx.size, 3, idx.size, 3)
    out = blocks[np.arange(idx.size), :, np.arange(idx.size), :]
    return 0.5 * (out + np.swapaxes(out, 1, 2))
