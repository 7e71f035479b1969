"""Full least-squares SLAM on a planar pose graph with point landmarks.

The state is all poses ``w_T_k = [x, y, θ]`` and landmark positions ``w_p_l``; the factors
are

* pose–pose ``z_ij ≈ x_i⁻¹ ∘ x_j`` with residual
  ``e = [R_iᵀ (t_j − t_i) − z_t, wrap(θ_j − θ_i − z_θ)]`` (the usual planar SLAM form),
* pose–landmark ``z_kl ≈ x_k⁻¹ · l`` with residual ``e = R_kᵀ (l − t_k) − z``,
* a prior on the first pose that fixes the gauge.

Each residual is whitened by the upper Cholesky factor of its information matrix and the sum
of squares is minimised by the estimation layer's Levenberg–Marquardt
(:mod:`recovery.lm`, Marquardt's diagonal scaling) on the sparse normal
equations; Jacobians are analytic and assembled without Python loops over factors.
The damped normal equations are factorised by :mod:`slamrel.backends.sparse_cholesky`
(QDLDL with its symbolic factorisation reused across iterations; CHOLMOD with the ``fast``
extra on graphs with much fill; SuperLU as the fallback): see there for the choice.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import ArrayLike, NDArray

from recovery.lm import Linearisation, LMOptions, levenberg_marquardt
from relation_metric import se2
from relation_metric.arrays import Array
from relation_metric.errors import InputError
from relation_metric.trajectory import readonly
from slamrel.backends import sparse_cholesky
from slamrel.backends.graph import PoseGraph, first_of_each

__all__ = [
    "GraphSolution",
    "solve_graph",
    "solve_graph_incremental",
    "pose_covariances",
    "joint_covariance",
    "ABSOLUTE_COST_TOLERANCE",
    "LAMBDA_INITIAL",
]

ABSOLUTE_COST_TOLERANCE = 1e-12
"""An accepted step lowering the cost (χ²/2) by less than this ends the solve as converged."""

LAMBDA_INITIAL = 1e-5
"""Levenberg–Marquardt's first damping ``λ`` (on ``diag(H)``), GTSAM's default too.

Measured against the earlier 1e-4 (2026-12-02, same stopping rule, ``solve``'s schemes):
never more iterations, the same cost to 10 digits and poses within 2.4·10⁻⁶ m (2.3·10⁻⁵ m on
a pose-only study graph) on Manhattan 10³ / 3.5·10³ / 10⁴ (seeds 0–2; one iteration fewer on
8 of 9, e.g. 7 → 6 on 10⁴), Victoria Park (86 → 83, cost 3091.9662), city10000 (7 and 7,
cost 15965.706), Victoria Park's pose-only M1/M2 graphs and 16 study graphs (hu-simple1/2,
hu-complex1/2, noise a and c, two seeds; full and M2: 5 of 32 one or more fewer, e.g.
12 → 6, none more). The graphs start from chained odometry, whose first Gauss–Newton steps
are good: less damping takes them whole.
"""


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
    linear_solver : str
        The sparse Cholesky back-end that factorised the normal equations
        (:mod:`~slamrel.backends.sparse_cholesky`: ``"cholmod"``, ``"qdldl"``,
        ``"superlu"``; of the last sub-problem for :func:`solve_graph_incremental`; a
        description for solutions that no factorisation made, e.g. TORO's in the study).
    faster_solver : str or None
        A back-end that is not installed and would have been chosen for this graph (CHOLMOD
        without the ``fast`` extra on a graph with much fill), else None.
    """

    poses: Array
    landmarks: Array
    cost: Array
    iterations: int
    converged: bool
    linear_solver: str
    faster_solver: str | None


def _upper_sqrt(info: Array) -> Array:
    """``W`` with ``Wᵀ W = info`` for a stack of SPD matrices (upper Cholesky factor)."""
    try:
        low = np.linalg.cholesky(info)
    except np.linalg.LinAlgError:
        raise InputError("an information matrix is not positive definite") from None
    return np.swapaxes(low, -1, -2)


class _Linearised(NamedTuple):
    """Whitened residuals and Jacobian blocks of every factor at one state.

    ``r`` is ordered pose–pose (3 per factor), pose–landmark (2 per factor), prior (3);
    ``ji, jj`` are the (E, 3, 3) blocks w.r.t. ``x_i, x_j``; ``jk`` (F, 2, 3) and ``jl``
    (F, 2, 2) w.r.t. ``x_k`` and ``l``; ``jp`` (3, 3) the prior's w.r.t. ``x_0``.
    """

    r: Array
    ji: Array
    jj: Array
    jk: Array
    jl: Array
    jp: Array


def _residuals(
    g: PoseGraph, x: Array, lm: Array, w_pp: Array, w_pl: Array, prior: tuple[Array, Array]
) -> tuple[Array, tuple[Array, ...]]:
    """Whitened residual vector, and the intermediate terms the Jacobian reuses."""
    xi, xj = x[g.pp_i], x[g.pp_j]
    c, s = np.cos(xi[:, 2]), np.sin(xi[:, 2])
    dt = xj[:, :2] - xi[:, :2]
    e_pp = np.empty((xi.shape[0], 3))
    e_pp[:, 0] = c * dt[:, 0] + s * dt[:, 1] - g.pp_z[:, 0]
    e_pp[:, 1] = -s * dt[:, 0] + c * dt[:, 1] - g.pp_z[:, 1]
    e_pp[:, 2] = se2.wrap_angle(xj[:, 2] - xi[:, 2] - g.pp_z[:, 2])
    xk = x[g.pl_k]
    ck, sk = np.cos(xk[:, 2]), np.sin(xk[:, 2])
    d = lm[g.pl_l] - xk[:, :2]
    e_pl = np.empty((xk.shape[0], 2))
    e_pl[:, 0] = ck * d[:, 0] + sk * d[:, 1] - g.pl_z[:, 0]
    e_pl[:, 1] = -sk * d[:, 0] + ck * d[:, 1] - g.pl_z[:, 1]
    p_mean, p_w = prior
    e_pr = se2.minus(x[0], p_mean)
    wpp_e = np.einsum("eab,eb->ea", w_pp, e_pp)
    wpl_e = np.einsum("eab,eb->ea", w_pl, e_pl)
    r = np.concatenate((wpp_e.ravel(), wpl_e.ravel(), p_w @ e_pr))
    return r, (c, s, dt, ck, sk, d)


def _linearise(
    g: PoseGraph, x: Array, lm: Array, w_pp: Array, w_pl: Array, prior: tuple[Array, Array]
) -> _Linearised:
    """Residuals and whitened Jacobian blocks at ``(x, lm)`` (vectorised over factors)."""
    r, (_, _, _, ck, sk, d) = _residuals(g, x, lm, w_pp, w_pl, prior)
    _, ji, jj = se2.between(x[g.pp_i], x[g.pp_j], jacobians=True)
    jk = np.zeros((ck.size, 2, 3))
    jk[:, 0, 0], jk[:, 0, 1] = -ck, -sk
    jk[:, 1, 0], jk[:, 1, 1] = sk, -ck
    jk[:, 0, 2] = -sk * d[:, 0] + ck * d[:, 1]
    jk[:, 1, 2] = -ck * d[:, 0] - sk * d[:, 1]
    jl = np.zeros((ck.size, 2, 2))
    jl[:, 0, 0], jl[:, 0, 1] = ck, sk
    jl[:, 1, 0], jl[:, 1, 1] = -sk, ck
    return _Linearised(r, w_pp @ ji, w_pp @ jj, w_pl @ jk, w_pl @ jl, prior[1])


def _residuals_and_jacobian(
    g: PoseGraph, x: Array, lm: Array, w_pp: Array, w_pl: Array, prior: tuple[Array, Array]
) -> tuple[Array, sp.csr_matrix]:
    """Whitened residuals and the sparse Jacobian (rows as :class:`_Linearised`)."""
    n = x.shape[0]
    lin = _linearise(g, x, lm, w_pp, w_pl, prior)
    ji_w, jj_w, jk_w, jl_w, p_w = lin.ji, lin.jj, lin.jk, lin.jl, lin.jp
    e_n, f_n = ji_w.shape[0], jk_w.shape[0]
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
    jac = sp.csr_matrix((vals, (rows, cols)), shape=(lin.r.size, size))
    return lin.r, jac


def _half_sum_sq(r: Array) -> float:
    """``½ rᵀr``, without BLAS: OpenBLAS runs a long ``ddot`` on two threads and leaves the
    second one spinning after it, burning CPU (measured in benchmarks/README.md)."""
    return 0.5 * float(np.einsum("i,i->", r, r))


def _apply(x: Array, lm: Array, delta: Array) -> tuple[Array, Array]:
    n = x.shape[0]
    x_new = x + delta[: 3 * n].reshape(n, 3)
    x_new[:, 2] = se2.wrap_angle(x_new[:, 2])
    lm_new = lm + delta[3 * n :].reshape(-1, 2)
    return x_new, lm_new


def _block_order_permutation(pattern: sp.csc_matrix, n: int, m: int) -> NDArray[np.int64]:
    """New index of each variable when the blocks (3 per pose, 2 per landmark) are put in a
    symmetric minimum-degree order of the block ``pattern`` (shape ``(n + m, n + m)``, SPD)."""
    block_pos = spla.splu(
        pattern, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True}
    ).perm_c  # new position of each block
    bsize = np.concatenate((np.full(n, 3), np.full(m, 2)))
    order = np.argsort(block_pos)
    start = np.empty(n + m, dtype=np.int64)
    start[order] = np.cumsum(bsize[order]) - bsize[order]
    old_start = np.concatenate((3 * np.arange(n), 3 * n + 2 * np.arange(m)))
    perm = np.empty(3 * n + 2 * m, dtype=np.int64)
    for k in range(3):
        has = bsize > k
        perm[old_start[has] + k] = start[has] + k
    return perm


class _NormalEquations:
    """``H = JᵀJ`` and ``Jᵀr`` assembled block by block into a sparsity pattern fixed per problem.

    Built once per :func:`solve_graph` call: the pattern of ``H`` (CSC) and, for every entry
    of every factor's block product, the slot of ``H.data`` it adds into. Each iteration then
    costs one ``np.bincount`` for ``H`` and one for the gradient (no sparse matrix products,
    no COO→CSR sorting), and each trial step one factorisation of ``H + λ D`` by
    :class:`~slamrel.backends.sparse_cholesky.SparseCholesky`, built once for the fixed
    pattern (QDLDL reuses its ordering and symbolic factorisation across all of them;
    CHOLMOD, with the ``fast`` extra, is taken when the factor is large; SuperLU is the
    fallback):

    * QDLDL (AMD) and CHOLMOD (AMD) order the scalar matrix themselves: the variables
      keep their natural order (which gave a sparser factor than the block order below on a
      10⁴-pose Manhattan graph; benchmarks/README.md). The
      expected work ``27 Σ c²`` (``c``: column counts of the Cholesky factor of the *block*
      graph, one node per pose and landmark, 3 × 3 blocks) picks between the two
      (:func:`~slamrel.backends.sparse_cholesky.choose_backend`; CHOLMOD only when
      installed — otherwise ``solve`` says when it would have been chosen).
    * SuperLU fallback: the variables are stored pre-permuted by a symmetric minimum-degree
      ordering of the block graph (:func:`_block_order_permutation`), computed once.
      SuperLU's own ordering on top of it breaks ties far better than on the natural order
      (factorisations about twice as fast for the same fill: benchmarks/README.md).
    """

    def __init__(self, g: PoseGraph, n: int, m: int) -> None:
        size = 3 * n + 2 * m
        self.size = size
        # --- block ordering ---------------------------------------------------------------
        nb = n + m
        pl_b = n + g.pl_l
        brow = np.concatenate((g.pp_i, g.pp_j, g.pl_k, pl_b, np.arange(nb)))
        bcol = np.concatenate((g.pp_j, g.pp_i, pl_b, g.pl_k, np.arange(nb)))
        pattern = sp.csc_matrix((np.ones(brow.size), (brow, bcol)), shape=(nb, nb))
        pattern.data[:] = 1.0
        pattern = (pattern + sp.diags(np.asarray(pattern.sum(axis=0)).ravel() + 1.0)).tocsc()
        if sparse_cholesky.BACKENDS[0] == "superlu":  # no Cholesky library: order for SuperLU
            perm = _block_order_permutation(pattern, n, m)
            flops = None
        else:  # QDLDL and CHOLMOD order the scalar matrix themselves
            perm = np.arange(size)
            flops = 27.0 * sparse_cholesky.factor_flops(pattern)
        self.perm = perm
        #: the back-end that would be chosen with every library installed (``solve`` says so
        #: when it is not the one used: CHOLMOD needs the optional ``fast`` extra)
        self.wanted = sparse_cholesky.choose_backend(flops, have=sparse_cholesky.ALL_BACKENDS)
        # --- variables of every factor, in the new numbering ------------------------------
        pi = perm[3 * g.pp_i[:, None] + np.arange(3)]
        pj = perm[3 * g.pp_j[:, None] + np.arange(3)]
        pk = perm[3 * g.pl_k[:, None] + np.arange(3)]
        pl = perm[3 * n + 2 * g.pl_l[:, None] + np.arange(2)]
        p0 = perm[np.arange(3)]
        # rows/cols of the entries of the blocks, in the order `_h_values` lists them
        pairs = ((pi, pi), (pi, pj), (pj, pi), (pj, pj), (pk, pk), (pk, pl), (pl, pk), (pl, pl))
        rows = [np.broadcast_to(a[:, :, None], (a.shape[0], a.shape[1], b.shape[1])).ravel()
                for a, b in pairs]  # fmt: skip
        cols = [np.broadcast_to(b[:, None, :], (a.shape[0], a.shape[1], b.shape[1])).ravel()
                for a, b in pairs]  # fmt: skip
        rows.append(np.repeat(p0, 3))
        cols.append(np.tile(p0, 3))
        key = np.concatenate(cols) * size + np.concatenate(rows)
        uniq, self.slot = np.unique(key, return_inverse=True)
        col, row = np.divmod(uniq, size)
        self.indices = row.astype(np.int32)
        self.indptr = np.concatenate(([0], np.cumsum(np.bincount(col, minlength=size)))).astype(
            np.int32
        )
        self.nnz = uniq.size
        self.diag = np.flatnonzero(row == col)  # slots of H_vv, v in the new numbering
        self.grad_index = np.concatenate((pi.ravel(), pj.ravel(), pk.ravel(), pl.ravel(), p0))
        # the blocks in the natural order: the supernodal analysis orders the block graph
        # that factor_flops has just ordered (kept, not redone)
        blocks = None if flops is None else np.concatenate((np.full(n, 3), np.full(m, 2)))
        self.cholesky = sparse_cholesky.SparseCholesky(
            self.indptr, self.indices, size, flops=flops, blocks=blocks
        )

    def assemble(self, lin: _Linearised) -> tuple[Array, Array]:
        """``H.data`` (in the stored pattern) and the gradient ``Jᵀr``, both in the new order."""
        e_n, f_n = lin.ji.shape[0], lin.jk.shape[0]
        ji_t, jj_t = np.swapaxes(lin.ji, 1, 2), np.swapaxes(lin.jj, 1, 2)
        jk_t, jl_t = np.swapaxes(lin.jk, 1, 2), np.swapaxes(lin.jl, 1, 2)
        vals = np.concatenate(
            [
                (ji_t @ lin.ji).ravel(),
                (ji_t @ lin.jj).ravel(),
                (jj_t @ lin.ji).ravel(),
                (jj_t @ lin.jj).ravel(),
                (jk_t @ lin.jk).ravel(),
                (jk_t @ lin.jl).ravel(),
                (jl_t @ lin.jk).ravel(),
                (jl_t @ lin.jl).ravel(),
                (lin.jp.T @ lin.jp).ravel(),
            ]
        )
        # numpy's stubs type bincount as NDArray[intp] always; with weights it is float64.
        h: Array = np.bincount(self.slot, weights=vals, minlength=self.nnz)  # type: ignore[assignment]
        r_pp = lin.r[: 3 * e_n].reshape(e_n, 3)
        r_pl = lin.r[3 * e_n : 3 * e_n + 2 * f_n].reshape(f_n, 2)
        r_pr = lin.r[3 * e_n + 2 * f_n :]
        gvals = np.concatenate(
            [
                np.einsum("eab,ea->eb", lin.ji, r_pp).ravel(),
                np.einsum("eab,ea->eb", lin.jj, r_pp).ravel(),
                np.einsum("fab,fa->fb", lin.jk, r_pl).ravel(),
                np.einsum("fab,fa->fb", lin.jl, r_pl).ravel(),
                lin.jp.T @ r_pr,
            ]
        )
        grad: Array = np.bincount(self.grad_index, weights=gvals, minlength=self.size)  # type: ignore[assignment]
        return h, grad

    def solve(self, h: Array, damping: Array, rhs: Array) -> Array:
        """``(H + diag(damping))⁻¹ rhs`` in the new order; the solution in the old order."""
        data = h.copy()
        data[self.diag] += damping
        self.cholesky.factor(data)
        return self.cholesky.solve(rhs)[self.perm]


def check_connected(
    graph: PoseGraph,
    *,
    pose_ids: NDArray[np.int64] | None = None,
    landmark_ids: NDArray[np.int64] | None = None,
) -> None:
    """Refuse a graph whose poses and landmarks are not one connected component.

    The gauge prior holds pose 0 only: a component without it has no prior, its placement
    is whatever the damping leaves (a silent wrong number). The components are found with
    :func:`scipy.sparse.csgraph.connected_components` over poses and landmarks joined by
    the pose–pose and pose–landmark factors.

    Raises
    ------
    InputError
        Naming how many components there are, their sizes and a pose (or landmark) of
        the first that does not hold pose 0 — by its file id when ``pose_ids`` and
        ``landmark_ids`` (graph index → file id) are given, else by its graph index.
    """
    from scipy.sparse.csgraph import connected_components

    n, m = graph.n_poses, graph.n_landmarks
    if n + m <= 1:
        return
    a = np.concatenate((graph.pp_i, graph.pl_k))
    b = np.concatenate((graph.pp_j, n + graph.pl_l))
    adj = sp.coo_matrix((np.ones(a.size), (a, b)), shape=(n + m, n + m))
    count, label = connected_components(adj, directed=False)
    if count == 1:
        return
    sizes = np.bincount(label)
    other = np.flatnonzero(label != label[0])
    k = int(other[0])
    if k < n:
        node = f"pose #{k} (0-based, in id order)" if pose_ids is None else f"pose {pose_ids[k]}"
    elif landmark_ids is None:
        node = f"landmark #{k - n} (0-based, in id order)"
    else:
        node = f"landmark {landmark_ids[k - n]}"
    first = "pose 0" if pose_ids is None else f"pose {pose_ids[0]}"
    poses_out = int(np.count_nonzero(label[:n] != label[0]))
    lms_out = int(np.count_nonzero(label[n:] != label[0]))
    raise InputError(
        f"the graph falls into {count} disconnected parts (sizes "
        f"{', '.join(str(int(x)) for x in sizes[:6])}{' ...' if count > 6 else ''}); "
        f"{poses_out} pose(s) and {lms_out} landmark(s), e.g. {node}, share no factor with "
        f"{first}, which holds the gauge: their placement would be the "
        "damping's guess. Expected one connected graph (add the missing edges, or solve each "
        "part as its own file)"
    )


def solve_graph(
    graph: PoseGraph,
    *,
    max_iterations: int = 100,
    tolerance: float = 1e-9,
    prior_sigma: float = 1e-6,
) -> GraphSolution:
    """Levenberg–Marquardt on the whitened residuals of ``graph``.

    The estimation layer's :func:`~recovery.lm.levenberg_marquardt`: Marquardt's
    damping ``H + λ diag(H)`` (λ from :data:`LAMBDA_INITIAL`, ×10 on a rejected step, ÷10 on
    an accepted one, at most 20 tries per iteration). The normal equations are assembled
    block-wise into a fixed pattern and factorised in a fill-reducing block ordering without
    pivoting (see :class:`_NormalEquations`); a trial step evaluates residuals only, the
    Jacobian is formed once a step is accepted.

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
        When the cost becomes non-finite or the normal equations are singular.
    """
    check_connected(graph)
    return _levenberg_marquardt(
        graph, max_iterations=max_iterations, tolerance=tolerance, prior_sigma=prior_sigma
    )[0]


def _dof(graph: PoseGraph) -> int:
    """Residuals minus unknowns (the gauge prior's 3 residuals included)."""
    return 3 * graph.pp_i.size + 2 * graph.pl_k.size + 3 - 3 * graph.n_poses - 2 * graph.n_landmarks


class _GraphProblem:
    """:class:`PoseGraph` as a :class:`~recovery.lm.Problem`; state ``(x, lm)``."""

    def __init__(self, graph: PoseGraph, prior_sigma: float) -> None:
        self.graph = graph
        self.w_pp, self.w_pl, self.prior = _whitening(graph, prior_sigma)
        self.normal = _NormalEquations(graph, graph.n_poses, graph.n_landmarks)

    def linearise(self, state: tuple[Array, Array]) -> Linearisation:
        lin = _linearise(self.graph, *state, self.w_pp, self.w_pl, self.prior)
        h, grad = self.normal.assemble(lin)
        return Linearisation(_half_sum_sq(lin.r), grad, h[self.normal.diag], h)

    def cost(self, state: tuple[Array, Array]) -> float:
        r, _ = _residuals(self.graph, *state, self.w_pp, self.w_pl, self.prior)
        return _half_sum_sq(r)

    def solve(self, lin: Linearisation, damping: Array) -> Array:
        return self.normal.solve(lin.system, damping, -lin.gradient)

    def retract(self, state: tuple[Array, Array], delta: Array) -> tuple[Array, Array]:
        return _apply(*state, delta)


def _whitening(graph: PoseGraph, prior_sigma: float) -> tuple[Array, Array, tuple[Array, Array]]:
    """Upper Cholesky factors of the pose–pose and pose–landmark informations; the prior."""
    w_pp = _upper_sqrt(graph.pp_info)
    w_pl = _upper_sqrt(graph.pl_info) if graph.pl_k.size else np.empty((0, 2, 2))
    return w_pp, w_pl, (graph.poses[0].copy(), np.eye(3) / prior_sigma)


def _levenberg_marquardt(
    graph: PoseGraph,
    *,
    max_iterations: int,
    tolerance: float,
    prior_sigma: float,
    stall_chi2: float | None = None,
) -> tuple[GraphSolution, bool]:
    """:func:`solve_graph`; with ``stall_chi2``, give up (second value True) at a *stall*.

    A stall is an accepted step that removes less than half the cost while the normalised
    cost ``2·cost/dof`` is still above ``stall_chi2``: far from a consistent solution and
    no longer converging fast, the signature of the wrong basin (Victoria Park from
    odometry stalls at its 2nd step; where one batch works, each step removes most of the
    cost until χ²/dof is near 1; benchmarks/README.md).
    """
    dof = _dof(graph)

    def stall(cost: float, cost_new: float) -> bool:
        rel = (cost - cost_new) / max(cost, 1e-300)
        return stall_chi2 is not None and rel < 0.5 and 2.0 * cost_new > stall_chi2 * dof > 0

    x0 = (np.array(graph.poses, dtype=np.float64), np.array(graph.landmarks, dtype=np.float64))
    # a decrease below ABSOLUTE_COST_TOLERANCE changes no statistic of the solution (cost =
    # chi2 / 2): converged, even where the relative decrease of a near-zero cost is large
    options = LMOptions(
        lambda_initial=LAMBDA_INITIAL,
        max_iterations=max_iterations,
        ftol=tolerance,
        atol=ABSOLUTE_COST_TOLERANCE,
    )
    problem = _GraphProblem(graph, prior_sigma)
    res = levenberg_marquardt(problem, x0, options, stop=stall)
    x, lm = res.x
    used, wanted = problem.normal.cholesky.backend, problem.normal.wanted
    solution = GraphSolution(
        poses=readonly(x),
        landmarks=readonly(lm),
        cost=readonly(res.costs),
        iterations=res.iterations,
        converged=res.converged,
        linear_solver=used,
        faster_solver=wanted if wanted not in sparse_cholesky.BACKENDS else None,
    )
    return solution, res.stopped


def solve_graph_incremental(
    graph: PoseGraph,
    *,
    batch: int = 200,
    growth: float = 2.0,
    max_iterations: int = 100,
    tolerance: float = 1e-9,
    prior_sigma: float = 1e-6,
    gate: float = 4.0,
    whole_first: bool = True,
) -> GraphSolution:
    """Levenberg–Marquardt on a problem grown in pose order, ``batch`` poses first.

    Batch least squares started from chained odometry can stop in a poor local minimum on
    long runs: on Victoria Park the accumulated heading error makes revisited landmarks pull
    the wrong way (a cost about 80 times the one from a good start; GTSAM's LM stops in the
    same minimum; benchmarks/README.md). An incremental smoother (iSAM)
    never sees that guess, because each new pose is linearised next to already-optimised
    ones. This driver first tries the whole graph, and grows sub-problems when that stalls:

    0. with ``whole_first``, Levenberg–Marquardt on the whole graph from its guess; it is
       given up at the first *stall* (an accepted step that removes less than half the cost
       while χ²/dof is above ``gate``, see :func:`_levenberg_marquardt`) and the steps below
       start from the graph's own guess;
    1. poses ``0 .. end-1`` with every factor among them and their landmarks form the
       sub-problem;
    2. poses not yet solved keep the initial guess's motion relative to the last solved pose
       (``x_k ← x_{s-1} ∘ (x⁰_{s-1}⁻¹ ∘ x⁰_k)``), landmarks seen for the first time keep
       their initial guess relative to their earliest observing pose ``k``
       (``l ← x_k · (x⁰_k⁻¹ · l⁰)``: the first sighting, for a first-sighting guess);
    3. :func:`solve_graph` solves the sub-problem warm-started; the number of poses added
       next is multiplied by ``growth`` (the first sub-problem has ``batch`` poses);
    4. *stall check*: a sub-problem whose solution has a normalised cost
       ``χ²/dof = 2·cost / (residuals − unknowns)`` above ``gate · max(1, previous χ²/dof)``
       fell into a wrong minimum (as on Victoria Park when thousands of odometry poses are
       added at once); it is undone and retried with the step divided
       by ``growth²`` (not below ``batch``, where it is accepted as it is).

    Why this scheme: a fixed step (``growth=1``) is robust but solves ``N/batch``
    ever larger problems, O(N²/batch) work; one batch is fastest where it works (a
    Manhattan grid) but falls into the wrong minimum on Victoria Park. So the whole graph
    is tried first and abandoned as soon as it stalls (a few per cent of the run); then
    geometric growth solves O(log N) sub-problems whose sizes sum to about twice the last,
    each warm (the solved part starts at its optimum), and the χ² check catches a step that
    grew too far, at the price of one wasted sub-solve. ``growth=2`` reaches the same
    minimum as ``growth=1`` in fewer iterations (the figures: benchmarks/README.md).

    Poses must be indexed in time order (as :func:`~slamrel.formats.isam.read_isam` and
    the g2o reader give them). Landmarks that no pose observes keep their initial guess out
    of the sub-problems and enter with the last one.

    Parameters
    ----------
    graph : PoseGraph
    batch : int
        Poses of the first sub-problem (``≥ N``: one batch solve, :func:`solve_graph`).
    growth : float
        Factor on the number of poses added per sub-problem (1: a fixed step of ``batch``).
    max_iterations, tolerance, prior_sigma :
        As :func:`solve_graph`, for each sub-problem.
    gate : float
        The stall checks' bound: on χ²/dof for the whole-graph try, on its growth between
        sub-problems (``inf``: no checks).
    whole_first : bool
        Try the whole graph first (step 0).

    Returns
    -------
    GraphSolution
        ``cost[0]`` is the cost of the graph's own initial guess, the rest the last (full)
        solve's accepted steps; ``iterations`` counts all sub-problems (undone ones too);
        ``converged`` is the last solve's.
    """
    if batch < 1:
        raise InputError(f"batch must be >= 1, got {batch}")
    if not growth >= 1.0:
        raise InputError(f"growth must be >= 1, got {growth:g}")
    check_connected(graph)
    n = graph.n_poses
    r0, _ = _residuals(graph, graph.poses, graph.landmarks, *_whitening(graph, prior_sigma))
    x = np.array(graph.poses, dtype=np.float64)
    lm = np.array(graph.landmarks, dtype=np.float64)
    placed = np.zeros(graph.n_landmarks, dtype=bool)
    iterations = 0
    if whole_first and batch < n:
        whole, stalled = _levenberg_marquardt(
            graph,
            max_iterations=max_iterations,
            tolerance=tolerance,
            prior_sigma=prior_sigma,
            stall_chi2=gate if np.isfinite(gate) else None,
        )
        if not stalled:
            return whole
        iterations += whole.iterations
    sol: GraphSolution | None = None
    start = 0
    step = float(batch)
    chi2_dof = None  # of the last accepted sub-problem
    while start < n:
        end = min(start + max(int(step), 1), n)
        saved = (x.copy(), lm.copy(), placed.copy())
        sub, used = _sub_problem(graph, x, lm, placed, start, end)
        sol = solve_graph(
            sub, max_iterations=max_iterations, tolerance=tolerance, prior_sigma=prior_sigma
        )
        iterations += sol.iterations
        dof = 3 * sub.pp_i.size + 2 * sub.pl_k.size + 3 - 3 * end - 2 * used.size
        chi2 = 2.0 * float(sol.cost[-1]) / dof if dof > 0 else None
        stalled = chi2 is not None and chi2_dof is not None and chi2 > gate * max(1.0, chi2_dof)
        if stalled and end - start > batch:
            x, lm, placed = saved  # step 4: undo, retry with a smaller step
            step = max(float(batch), step / growth**2)
            continue
        x[:end] = sol.poses
        lm[used] = sol.landmarks
        placed[used] = True
        chi2_dof = chi2 if chi2 is not None else chi2_dof
        start = end
        step *= growth
    assert sol is not None
    return GraphSolution(
        poses=readonly(x),
        landmarks=readonly(lm),
        cost=readonly(np.concatenate(([_half_sum_sq(r0)], sol.cost[1:]))),
        iterations=iterations,
        converged=sol.converged,
        linear_solver=sol.linear_solver,
        faster_solver=sol.faster_solver,
    )


def _sub_problem(
    graph: PoseGraph, x: Array, lm: Array, placed: NDArray[np.bool_], start: int, end: int
) -> tuple[PoseGraph, NDArray[np.int64]]:
    """Steps 1–2 of :func:`solve_graph_incremental`: poses ``0 .. end-1`` and their landmarks.

    Updates ``x[start:]`` (carried along with pose ``start-1``) and the first-seen landmarks
    of ``lm`` in place; returns the sub-graph and the indices of its landmarks in ``lm``.
    """
    x0 = np.asarray(graph.poses)
    if start > 0:
        # step 2: carry the unsolved poses along with the last solved one
        x[start:] = se2.compose(x[start - 1], se2.between(x0[start - 1], x0[start:]))
    pp = (graph.pp_i < end) & (graph.pp_j < end)
    pl = graph.pl_k < end
    if end == graph.n_poses:  # the whole graph, landmarks without observations too
        used, pl_l = np.arange(graph.n_landmarks), graph.pl_l
    else:
        used, pl_l = np.unique(graph.pl_l[pl], return_inverse=True)
    fresh = np.flatnonzero(pl & ~placed[graph.pl_l])  # sightings of unplaced landmarks
    if fresh.size:
        # keep the initial guess's landmark relative to its earliest observing pose
        first = fresh[first_of_each(graph.pl_l[fresh], graph.pl_k[fresh])]
        k, l_ = graph.pl_k[first], graph.pl_l[first]
        lm[l_] = se2.transform_points(
            x[k], se2.inverse_transform_points(x0[k], graph.landmarks[l_])
        )
    sub = PoseGraph(
        poses=x[:end],
        landmarks=lm[used],
        pp_i=graph.pp_i[pp],
        pp_j=graph.pp_j[pp],
        pp_z=graph.pp_z[pp],
        pp_info=graph.pp_info[pp],
        pl_k=graph.pl_k[pl],
        pl_l=pl_l,
        pl_z=graph.pl_z[pl],
        pl_info=graph.pl_info[pl],
    )
    return sub, used


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
    idx = np.arange(graph.n_poses) if indices is None else np.asarray(indices, dtype=np.int64)
    cols = (3 * idx[:, None] + np.arange(3)[None, :]).ravel()
    sol = _inverse_block(graph, solution, cols, prior_sigma)
    blocks = sol.reshape(idx.size, 3, idx.size, 3)
    return blocks[np.arange(idx.size), :, np.arange(idx.size), :]


def _inverse_block(
    graph: PoseGraph, solution: GraphSolution, cols: NDArray[np.int64], prior_sigma: float
) -> Array:
    """``(H⁻¹)[cols][:, cols]`` (symmetrised) with ``H = JᵀJ`` at the solution, gauge prior
    included: one sparse LU factorisation and a multi-right-hand-side solve."""
    _, jac = _residuals_and_jacobian(
        graph,
        np.asarray(solution.poses),
        np.asarray(solution.landmarks),
        *_whitening(graph, prior_sigma),
    )
    h = (jac.T @ jac).tocsc()
    rhs = np.zeros((h.shape[0], cols.size))
    rhs[cols, np.arange(cols.size)] = 1.0
    out = spla.splu(h).solve(rhs)[cols, :]
    return 0.5 * (out + out.T)


def joint_covariance(
    graph: PoseGraph,
    solution: GraphSolution,
    *,
    poses: ArrayLike | None = None,
    landmarks: ArrayLike | None = None,
    prior_sigma: float = 1e-6,
) -> Array:
    """Joint (dense) covariance of chosen poses and landmarks at the solution, from ``H⁻¹``.

    The other states are marginalised out (the block of ``H⁻¹``, not of ``H``), so for a
    full SLAM graph the pose block is the pose covariance with the landmarks marginalised.

    Parameters
    ----------
    graph, solution :
        The problem and its solution (the gauge prior of :func:`solve_graph` included).
    poses : array_like of int, shape (P,), optional
        Pose indices (default: all).
    landmarks : array_like of int, shape (Q,), optional
        Landmark indices (default: none).

    Returns
    -------
    ndarray, shape (3P + 2Q, 3P + 2Q)
        Ordered ``[x_p0, y_p0, θ_p0, x_p1, …, x_l0, y_l0, …]``.
    """
    pi = np.arange(graph.n_poses) if poses is None else np.asarray(poses, dtype=np.int64)
    li = np.empty(0, np.int64) if landmarks is None else np.asarray(landmarks, dtype=np.int64)
    cols = np.concatenate(
        (
            (3 * pi[:, None] + np.arange(3)[None, :]).ravel(),
            (3 * graph.n_poses + 2 * li[:, None] + np.arange(2)[None, :]).ravel(),
        )
    )
    return _inverse_block(graph, solution, cols, prior_sigma)
