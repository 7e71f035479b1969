"""Lever SGD: a tree-parameterised stochastic gradient descent that is *not* TORO.

slamrel's earlier "TORO-style" optimiser, kept as a separate, named method because it gets
closer to the optimum than TORO on small, dense graphs (the pose-only study's Method 2
graphs), while on large graphs started from odometry it is far worse: far from the optimum
after hundreds of iterations on an Olson-style graph, and farther from the truth than the
odometry on ``city10000`` (the figures: benchmarks/README.md). It differs from TORO
(:mod:`slamrel.backends.toro_optimiser`) in its heading Jacobian: translational residuals
also move headings (the lever term below), while the positions down the tree do not move
with them; a breadth-first tree, input-order visits, a constant preconditioner and a step
capped per constraint.

Reimplemented from the papers (Olson, Leonard & Teller, ICRA 2006; Grisetti, Stachniss,
Grzonka & Burgard, RSS 2007), not from TORO's code:

* **Tree parameterisation** (Grisetti et al.). A spanning tree of the constraint graph is
  grown breadth-first from pose 0 (so tree paths are short, unlike Olson's incremental
  chain). Each pose's parameter is its difference from its parent in the global frame,
  ``x_k = p_k − p_parent(k)`` (angle included and wrapped: ``se2.minus``), so ``p_k`` is the
  sum of the parameters on the tree path from the root; the root is held fixed.
* **Residual**. For a constraint ``(i, j)`` with measurement ``δ`` the residual is taken in the
  global frame, ``r = (p_i ⊕ δ) − p_j`` (angle wrapped: ``se2.minus``). It depends only on
  the parameters on the tree path ``P_ij`` between ``i`` and ``j`` (below their lowest common
  ancestor), with Jacobian blocks ``±I``.
* **Spherical covariances**. As in TORO, a constraint's information is replaced by
  ``diag(ω_t, ω_t, ω_θ)`` (``ω_t`` the mean of the translational diagonal, ``ω_θ`` the angular
  entry, cross terms dropped), which makes the global-frame residual's weight independent of
  the frame it is expressed in.
* **Preconditioner and update** (Olson et al.). One iteration visits every constraint in
  turn; the parameters ``x_k`` on its path move by ``Δx_k = −λ M_k⁻¹ J_kᵀ Ω r`` with the
  Jacobi preconditioner ``M = diag(Σ_c J_cᵀ Ω_c J_c)`` (constant here). ``J_k`` is ``−I`` on
  the ``j`` side of the path and ``[[I, S R_i δ_t], [0, 1]]`` on the ``i`` side (a heading
  change turns the measured translation), so the fixed point is the least-squares optimum
  of the spherical problem. A visit never overshoots: the step is scaled so that the
  predicted change ``−λ A Ω r`` of the constraint's own residual
  (``A = Σ_k J_k M_k⁻¹ J_kᵀ``) has spectral radius at most 1 (Grisetti et al.'s clipping).
* **Learning rate** ``λ_t = 1 / (γ ρ̃ t)`` in iteration ``t`` (the harmonic schedule of both
  papers), with ``ρ̃`` the median over constraints of ``ρ_c``, the spectral radius of
  ``A_c Ω_c`` (the fraction of its residual a unit-rate visit removes), so that ``γ`` does not
  depend on how densely the graph is connected. ``γ = 0.1`` by default: the best of 0.1, 0.3
  and 1 over a seeded 30-pose ring and the pose-only Method 2 graph of hu-simple1, noise a,
  seed 0 (the costs reached: benchmarks/README.md).
* **Result**: the iterate of lowest cost (stochastic steps make the cost fluctuate).

Positions and headings are separate parameters (the 2-D parameterisation of the RSS paper),
so a heading change does not rotate the positions further down the tree. The result is an
approximate optimum — stochastic gradient descent with a decaying rate stops short of the
minimum — which is what Hu et al. compare with least squares (Tables II–IV).

The visit of one constraint is sequential by the nature of stochastic gradient descent; its
arithmetic is vectorised over the path.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.sparse.csgraph import breadth_first_order

from relation_metric import se2
from relation_metric.arrays import Array
from relation_metric.errors import InputError
from relation_metric.trajectory import readonly
from slamrel.backends.graph import PoseGraph
from slamrel.backends.toro_optimiser import TreeSolution, spanning_tree, spherical_information

__all__ = ["lever_sgd_optimize"]


def _ancestry(parent: NDArray[np.int64]) -> tuple[NDArray[np.int64], list[NDArray[np.int64]]]:
    """Depth of each node and its root-to-node path (root excluded), built level by level."""
    n = parent.size
    depth = np.zeros(n, dtype=np.int64)
    paths: list[NDArray[np.int64]] = [np.empty(0, np.int64)] * n
    order = breadth_first_order(
        sp.coo_matrix((np.ones(n - 1), (parent[1:], np.arange(1, n))), shape=(n, n)).tocsr(),
        0,
        directed=True,
        return_predecessors=False,
    )
    for k in order[1:]:
        p = parent[k]
        depth[k] = depth[p] + 1
        paths[k] = np.append(paths[p], k)
    return depth, paths


def _poses_from_parameters(
    x: Array, levels: list[NDArray[np.int64]], parent: NDArray[np.int64]
) -> Array:
    p = x.copy()
    for nodes in levels[1:]:
        p[nodes] += p[parent[nodes]]
    return p


def _cost(p: Array, g: PoseGraph, omega: Array) -> float:
    r = se2.minus(se2.compose(p[g.pp_i], g.pp_z), p[g.pp_j])
    return 0.5 * float(np.einsum("ea,eab,eb->", r, omega, r))


def _constraint_sides(
    anc: list[NDArray[np.int64]], pp_i: NDArray[np.int64], pp_j: NDArray[np.int64]
) -> tuple[list[NDArray[np.int64]], list[NDArray[np.int64]]]:
    """The path of each constraint below the lowest common ancestor of its two poses in the
    tree (``anc``: root-first ancestors of each pose): the i side, then the j side."""
    side_i: list[NDArray[np.int64]] = []
    side_j: list[NDArray[np.int64]] = []
    for i, j in zip(pp_i.tolist(), pp_j.tolist()):
        ai, aj = anc[i], anc[j]
        m = min(ai.size, aj.size)
        common = int(np.argmin(np.append(ai[:m] == aj[:m], False)))  # shared prefix length
        side_i.append(ai[common:])
        side_j.append(aj[common:])
    return side_i, side_j


def _preconditioner(
    n: int,
    w: Array,
    z: Array,
    side_i: list[NDArray[np.int64]],
    side_j: list[NDArray[np.int64]],
) -> tuple[Array, Array]:
    """``M⁻¹`` (shape ``(n, 3)``, the inverse of ``diag(Σ J_kᵀ Ω J_k)``, 0 where no constraint
    acts) and ``ρ_c`` per constraint (shape ``(E,)``), the spectral radius of ``A_c Ω_c``.

    On the i side the angle also turns ``R_i δ_t``, whose length ``|δ_t|`` does not depend on
    the state, so ``M`` is constant. ``ρ_c`` says how much of its own residual a unit-rate
    visit removes (rotation-invariant: ``M`` and ``Ω`` are spherical in x, y).
    """
    e_n = len(side_i)
    lever = w[:, 0] * np.sum(z[:, :2] ** 2, axis=1)
    m_diag = np.zeros((n, 3))
    if e_n:
        owner_i = np.repeat(np.arange(e_n), [q.size for q in side_i])
        owner_j = np.repeat(np.arange(e_n), [q.size for q in side_j])
        np.add.at(m_diag, np.concatenate(side_j), w[owner_j])
        wi = w[owner_i].copy()
        wi[:, 2] += lever[owner_i]
        np.add.at(m_diag, np.concatenate(side_i), wi)
    m_inv = np.zeros_like(m_diag)
    np.divide(1.0, m_diag, out=m_inv, where=m_diag > 0)
    sum_i = np.array([m_inv[q].sum(axis=0) for q in side_i]).reshape(-1, 3)
    sum_j = np.array([m_inv[q].sum(axis=0) for q in side_j]).reshape(-1, 3)
    jac = np.broadcast_to(np.eye(3), (e_n, 3, 3)).copy()
    jac[:, 0, 2], jac[:, 1, 2] = -z[:, 1], z[:, 0]
    a_all = (jac * sum_i[:, None, :]) @ np.swapaxes(jac, 1, 2) + sum_j[:, :, None] * np.eye(3)
    rho_all = np.max(np.abs(np.linalg.eigvals(a_all * w[:, None, :])), axis=1) if e_n else w[:, 0]
    return m_inv, rho_all


def lever_sgd_optimize(
    graph: PoseGraph,
    *,
    iterations: int = 100,
    gamma: float = 0.1,
) -> TreeSolution:
    """Optimise a pose graph (pose–pose constraints only) by lever SGD (module docstring).

    Parameters
    ----------
    graph : PoseGraph
        Its poses are the start; pose 0 is the root and stays fixed. Landmark factors are not
        supported (TORO optimises pose graphs).
    iterations : int
        Passes over all constraints.
    gamma : float
        Learning-rate scale, ``λ_t = 1 / (γ ρ̃ t)``.

    Returns
    -------
    TreeSolution
    """
    if graph.pl_k.size:
        raise InputError("the lever SGD optimiser takes pose graphs only (no landmark factors)")
    if iterations < 0 or gamma <= 0:
        raise InputError(f"need iterations >= 0 and gamma > 0, got {iterations}, {float(gamma):g}")
    n = graph.n_poses
    parent = spanning_tree(n, graph.pp_i, graph.pp_j)
    depth, anc = _ancestry(parent)
    levels = [np.flatnonzero(depth == d) for d in range(int(depth.max()) + 1)]
    omega = spherical_information(graph.pp_info)
    w = np.column_stack((omega[:, 0, 0], omega[:, 1, 1], omega[:, 2, 2]))
    p0 = np.array(graph.poses, dtype=np.float64)
    x = p0.copy()
    x[1:] = se2.minus(p0[1:], p0[parent[1:]])
    e_n = graph.pp_i.size
    z = np.asarray(graph.pp_z)
    side_i, side_j = _constraint_sides(anc, graph.pp_i, graph.pp_j)
    m_inv, rho_all = _preconditioner(n, w, z, side_i, side_j)
    scale = float(np.median(rho_all)) if e_n else 1.0
    anc_i = [anc[i] for i in graph.pp_i.tolist()]
    anc_j = [anc[j] for j in graph.pp_j.tolist()]
    mi_i = [m_inv[q] for q in side_i]  # preconditioner rows of each path side
    mi_j = [m_inv[q] for q in side_j]
    zz = z.tolist()
    ww = w.tolist()
    inv_rho = (1.0 / rho_all).tolist()
    rt = float(x[0, 2])  # the root heading (positions cancel in the residual)
    costs = [_cost(_poses_from_parameters(x, levels, parent), graph, omega)]
    best_cost, best_x = costs[0], x.copy()
    for t in range(1, iterations + 1):
        lam = 1.0 / (gamma * scale * t)
        for e in range(e_n):
            si, sj = side_i[e], side_j[e]
            if si.size + sj.size == 0:
                continue
            pi = x[anc_i[e]].sum(axis=0).tolist()
            pj = x[anc_j[e]].sum(axis=0).tolist()
            th = rt + pi[2]
            c, s_ = math.cos(th), math.sin(th)
            zx, zy, zt = zz[e]
            dx, dy = c * zx - s_ * zy, s_ * zx + c * zy  # R_i δ_t
            r0 = pi[0] + dx - pj[0]
            r1 = pi[1] + dy - pj[1]
            r2 = se2.wrap_angle_float(pi[2] + zt - pj[2])
            w0, w1, w2 = ww[e]
            wr = np.array((w0 * r0, w1 * r1, w2 * r2))  # Ω r
            # Jacobians: i side [[I, S R_i δ_t], [0, 1]], j side −I; the step is capped so
            # that the predicted change −λ A Ω r of the constraint's own residual
            # (A = Σ_k J_k M_k⁻¹ J_kᵀ) has spectral radius ≤ 1: ρ(A Ω) is rotation-invariant
            # (M and Ω are spherical in x, y), so it was computed once
            step = min(lam, inv_rho[e])
            if si.size:
                g_i = np.array((wr[0], wr[1], -dy * wr[0] + dx * wr[1] + wr[2]))
                x[si] -= step * mi_i[e] * g_i
            if sj.size:
                x[sj] += step * mi_j[e] * wr
        costs.append(_cost(_poses_from_parameters(x, levels, parent), graph, omega))
        if costs[-1] < best_cost:
            best_cost, best_x = costs[-1], x.copy()
    p = _poses_from_parameters(best_x, levels, parent)
    p[:, 2] = se2.wrap_angle(p[:, 2])
    return TreeSolution(
        readonly(p), readonly(np.asarray(costs)), int(iterations), readonly(parent, np.int64)
    )
