"""TORO: pose-graph optimisation by stochastic gradient descent on a tree parameterisation.

Written from the papers (Olson, Leonard & Teller, ICRA 2006, "Fast iterative alignment of
pose graphs with poor initial estimates"; Grisetti, Stachniss, Grzonka & Burgard, RSS 2007,
"A tree parameterization for efficiently computing maximum likelihood maps using gradient
descent"), not from TORO's code (CC BY-NC-SA). OpenSLAM's 2-D ``toro`` was built in a side
folder only to measure against (``benchmarks/bench_toro.py``).

* **Tree** (``tree=``). ``"incremental"`` (the papers' choice for data that arrive in
  order, and TORO's default): poses are inserted in index order and pose ``k``'s parent is
  the lowest-index pose it shares a constraint with (among those before it), so a loop
  closure hangs a new pose below the old pose it revisits and tree paths stay short (on
  ``city10000`` the mean path length is what the real ``toro`` prints: benchmarks/README.md).
  ``"breadth-first"``: a breadth-first spanning tree from pose 0.
* **Parameters**. Pose ``k``'s parameter is its difference from its parent in the global
  frame, ``x_k = p_k − p_parent(k)`` (``x``, ``y`` and the unwrapped heading ``θ``), so
  ``p_k`` is the sum of the parameters on the root-to-``k`` path; the root is fixed.
* **Initial guess** (``initial=``). ``"tree"`` (TORO's default): the poses composed along
  the tree's own constraints from the root (the first constraint of each tree edge, in
  input order). ``"given"``: the graph's poses.
* **Residual** of a constraint ``c = (i, j)`` with measurement ``δ``, in the global frame:
  ``r_c = [t_i + R_i δ_t − t_j, wrap(θ_i + δ_θ − θ_j)]``. Its Jacobian with respect to the
  parameters on the tree path ``P_c`` between ``i`` and ``j`` (the poses below their lowest
  common ancestor) is ``+I`` on the ``i`` side and ``−I`` on the ``j`` side; the heading
  change's lever on ``R_i δ_t`` is neglected, as in both papers, so headings are updated
  from rotational residuals only.
* **Weights**. The information rotated into the global frame, ``R_i Ω_c R_iᵀ``, reduced to
  its diagonal ``W_c`` (per dimension; TORO's spherical ``diag(ω_t, ω_t, ω_θ)`` when the
  translational block is isotropic, e.g. ``city10000``).
* **Preconditioner**, recomputed at the start of every iteration (the headings change):
  ``M_k = Σ_{c : k ∈ P_c} W_c`` per dimension, and ``γ = min_k M_k`` per dimension.
* **Step** (Grisetti et al.'s update). In iteration ``t`` (from 1) a visit to ``c`` removes
  the fraction ``f_c = min(1, 2 |P_c| W_c / (γ t))`` of each dimension of its residual,
  split along its path in proportion to ``M_k⁻¹``:
  ``Δx_k = ∓ f_c r_c M_k⁻¹ / Σ_{m ∈ P_c} M_m⁻¹`` (``−`` on the ``i`` side, ``+`` on the
  ``j`` side), so the constraint's own residual becomes ``(1 − f_c) r_c`` exactly.
* **Rules** (``rules=``). The bullets above are the papers' update (``"papers"``). The
  default, ``"toro"``, is what OpenSLAM's ``toro`` does, measured on it as a black box
  (tiny graphs run for 1–20 iterations and its output compared to 6 digits; its code was
  not read): (1) one constraint per pose pair, the first in the input
  (:func:`first_per_pair`; ``dropped`` counts the others, which the cost still counts);
  (2) fixed weights ``W_c = diag(R(δ_θ) Ω_c R(δ_θ)ᵀ)``, the information turned by the
  measurement's own rotation (:func:`measurement_weights`), so ``M`` is fixed; (3) ``γ`` is
  the smallest ``W_c`` over the constraints (per dimension), not the smallest ``M_k``;
  (4) a visit's correction is ``u = 2|P_c| γ⁻¹ (R_i Ω_c R_iᵀ) r_c / (t + 1)`` with the
  whole rotated information, and a dimension with ``|u| > |r|`` takes ``u = r``; it is
  split along the path as above. On isotropic diagonal information (``city10000``) this is
  the papers' fraction with ``γ = min W`` and ``t + 1``. Reproduced: the three triangles of
  ``tests/test_estimation_toro.py``, two 4-pose graphs and 80 random triangles (random
  information, headings up to ±3 rad) to ``toro``'s printed digits for 1–20 iterations;
  ``city10000`` after 100 and 300 iterations close to ``toro``'s cost; the study's Method 2
  graphs (seed 0) iterate for iterate on hu-simple1 and, for one iteration, on hu-complex1.
  On the complex worlds the iterates of either program depend on the last bits of the data
  (the cap is discontinuous where ``u ≈ −r``): measurements changed by 1e-12 move slamrel's
  cost after a few iterations as much as it differs from ``toro``'s, so the two are compared
  by the median over the graph and five such copies (``benchmarks/bench_toro.py``; the
  ratios are in benchmarks/README.md).
* **Order** (``order=``). ``"depth"`` (the RSS paper's): the constraints sorted by their
  level, the depth of the lowest common ancestor of their two poses, root side first (ties
  in input order). ``"input"``: the input order.

Vectorisation: visits are sequential in the paper's order, but two constraints whose
paths share no pose do not touch each other's parameters, so their visits commute. The
visits are therefore grouped into runs (:func:`_runs`) that keep the order of every two
visits sharing a pose, and each run is applied at once (sparse products over the run): the
same result as one visit at a time in the paper's order. The one quantity outside the paths,
the heading of the lowest common ancestor in ``R_i``, is taken from the start of the
iteration with the papers' rules (on the 4-pose graphs of the tests this moves a pose by a
visible amount after a few iterations against the visits one at a time:
benchmarks/README.md). When every constraint's translational information is isotropic
(``city10000``, TORO's spherical covariances) the weights, hence ``M`` and the splits, are
the same in every iteration, and an iteration's visits are instead two sparse triangular
solves, headings first and translations after (:class:`_TriangularSweep`): the same result
again, up to the order of floating-point sums, without a Python step per run (thousands of
runs per iteration on ``city10000``).

With ``rules="toro"`` the runs are exact: a visit reads the heading of its top pose as
the earlier visits of the iteration left it (the sum of the heading parameters on its root
path), and a run ends where a visit would change a pose another visit of the run reads
(thousands of runs per iteration on hu-complex1, hundreds on hu-simple1:
benchmarks/README.md). The triangular sweep still takes that heading from the iteration's
start.

The result is the last iterate (the papers run a fixed number of iterations; the cost need
not decrease monotonically). The cost reported is ``½ Σ eᵀ Ω e`` with the graph's own
information and the local residual of :mod:`slamrel.backends.least_squares`, so that it is
comparable with least squares'.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.sparse.csgraph import breadth_first_order
from scipy.sparse.linalg import spsolve_triangular

from relation_metric import se2
from relation_metric.arrays import Array
from relation_metric.errors import InputError
from relation_metric.trajectory import readonly
from slamrel.backends.graph import PoseGraph

__all__ = [
    "TORO_TREES",
    "TORO_ORDERS",
    "TORO_INITIAL",
    "TORO_RULES",
    "TreeSolution",
    "spherical_information",
    "spanning_tree",
    "incremental_tree",
    "graph_cost",
    "toro_optimize",
]

TreeKind = Literal["incremental", "breadth-first"]
OrderKind = Literal["depth", "input"]
InitialKind = Literal["tree", "given"]
RulesKind = Literal["toro", "papers"]
TORO_TREES: tuple[TreeKind, ...] = ("incremental", "breadth-first")
TORO_ORDERS: tuple[OrderKind, ...] = ("depth", "input")
TORO_INITIAL: tuple[InitialKind, ...] = ("tree", "given")
TORO_RULES: tuple[RulesKind, ...] = ("toro", "papers")


@dataclass(frozen=True)
class TreeSolution:
    """Result of :func:`toro_optimize` and of :mod:`~slamrel.backends.lever_sgd`.

    Attributes
    ----------
    poses : ndarray, shape (N, 3)
    cost : ndarray, shape (iterations + 1,)
        ``½ Σ eᵀ Ω e`` after each iteration (first: the start).
    iterations : int
    parent : ndarray of int, shape (N,)
        The spanning tree (−1 at the root, pose 0).
    mean_path_length : float
        Mean over constraints of ``|P_c|``, the poses on the tree path between its two poses.
    runs : int
        Runs of constraints with disjoint paths applied at once per iteration (0 if unused).
    dropped : int
        Constraints left out of the optimisation because an earlier one joins the same two
        poses (``rules="toro"``: one constraint per pose pair); the cost still counts them.
    """

    poses: Array
    cost: Array
    iterations: int
    parent: NDArray[np.int64]
    mean_path_length: float = float("nan")
    runs: int = 0
    dropped: int = 0


def spherical_information(info: Array) -> Array:
    """TORO's spherical approximation ``diag(ω_t, ω_t, ω_θ)`` of (E, 3, 3) information."""
    omega = np.asarray(info, dtype=np.float64)
    w_t = 0.5 * (omega[:, 0, 0] + omega[:, 1, 1])
    out = np.zeros_like(omega)
    out[:, 0, 0] = out[:, 1, 1] = w_t
    out[:, 2, 2] = omega[:, 2, 2]
    return out


def spanning_tree(n: int, pp_i: NDArray[np.int64], pp_j: NDArray[np.int64]) -> NDArray[np.int64]:
    """Parents of a breadth-first spanning tree from pose 0 (−1 at the root), shape (N,).

    Raises
    ------
    InputError
        When some pose is not connected to pose 0.
    """
    adj = sp.coo_matrix((np.ones(pp_i.size), (pp_i, pp_j)), shape=(n, n)).tocsr()
    order, pred = breadth_first_order(adj, 0, directed=False, return_predecessors=True)
    if order.size != n:
        missing = np.setdiff1d(np.arange(n), order)
        raise InputError(f"pose {int(missing[0])} is not connected to pose 0 by any constraint")
    parent = pred.astype(np.int64)
    parent[0] = -1
    return parent


def incremental_tree(n: int, pp_i: NDArray[np.int64], pp_j: NDArray[np.int64]) -> NDArray[np.int64]:
    """Parents of the incremental tree (−1 at the root), shape (N,): pose ``k > 0`` hangs
    below the lowest-index pose ``< k`` it shares a constraint with.

    Raises
    ------
    InputError
        When a pose has no constraint to an earlier pose (it cannot be inserted in order;
        the breadth-first tree does not need the order).
    """
    lo = np.minimum(pp_i, pp_j)
    hi = np.maximum(pp_i, pp_j)
    parent = np.full(n, n, dtype=np.int64)
    np.minimum.at(parent, hi, lo)
    parent[0] = -1
    orphan = np.flatnonzero(parent[1:] == n)
    if orphan.size:
        raise InputError(
            f"pose {int(orphan[0]) + 1} has no constraint to an earlier pose; the incremental "
            "tree inserts poses in index order (use the breadth-first tree)"
        )
    return parent


_TWO_PI = 2.0 * np.pi


def graph_cost(poses: Array, graph: PoseGraph) -> float:
    """``½ Σ eᵀ Ω e`` of the pose–pose factors (local residual, the graph's information)."""
    e = se2.between(poses[graph.pp_i], poses[graph.pp_j]) - graph.pp_z
    e[:, 2] = se2.wrap_angle(e[:, 2])
    return 0.5 * float(np.einsum("ea,eab,eb->", e, graph.pp_info, e))


def _depths(parent: NDArray[np.int64]) -> tuple[NDArray[np.int64], list[NDArray[np.int64]]]:
    """Depth of every node and the nodes of each level (level 0: the root)."""
    n = parent.size
    child = sp.csr_matrix((np.ones(n - 1), (parent[1:], np.arange(1, n))), shape=(n, n))
    order = breadth_first_order(child, 0, directed=True, return_predecessors=False)
    depth = np.zeros(n, dtype=np.int64)
    for k in order[1:].tolist():  # once per solve; parents come first in BFS order
        depth[k] = depth[parent[k]] + 1
    levels = [np.flatnonzero(depth == d) for d in range(int(depth.max()) + 1)]
    return depth, levels


@dataclass(frozen=True)
class _Paths:
    """Tree paths of the constraints as a signed incidence matrix.

    ``signed``: (E, N) CSR, ``+1`` for the ``i``-side poses of ``P_c``, ``−1`` for the
    ``j`` side; ``lca``: (E,) lowest common ancestor; ``length``: (E,) ``|P_c|``.
    """

    signed: sp.csr_matrix
    lca: NDArray[np.int64]
    length: NDArray[np.int64]


def _paths(
    parent: NDArray[np.int64], depth: NDArray[np.int64], i: NDArray[np.int64], j: NDArray[np.int64]
) -> _Paths:
    """Climb from both ends of all constraints at once, the deeper end first, until they
    meet (the lowest common ancestor); every pose left on the way is on the path."""
    a, b = i.copy(), j.copy()
    rows: list[NDArray[np.int64]] = []
    cols: list[NDArray[np.int64]] = []
    vals: list[NDArray[np.float64]] = []
    live = np.flatnonzero(a != b)
    while live.size:
        up_a = depth[a[live]] >= depth[b[live]]
        ca, cb = live[up_a], live[~up_a]
        rows += [ca, cb]
        cols += [a[ca], b[cb]]
        vals += [np.ones(ca.size), -np.ones(cb.size)]
        a[ca] = parent[a[ca]]
        b[cb] = parent[b[cb]]
        live = live[a[live] != b[live]]
    e_n, n = i.size, parent.size
    r = np.concatenate(rows) if rows else np.empty(0, np.int64)
    signed = sp.csr_matrix(
        (np.concatenate(vals) if vals else np.empty(0), (r, np.concatenate(cols) if cols else r)),
        shape=(e_n, n),
    )
    signed.sort_indices()
    return _Paths(signed, a, np.diff(signed.indptr).astype(np.int64))


def _root_paths(parent: NDArray[np.int64], nodes: NDArray[np.int64]) -> sp.csr_matrix:
    """Rows of ones over the root-to-``k`` path (``k`` and the root included) of every ``k``
    in ``nodes``, shape (len(nodes), N): ``p_k = Σ`` of the parameters on it. All the
    paths are climbed at once, one level a step."""
    rows: list[NDArray[np.int64]] = []
    cols: list[NDArray[np.int64]] = []
    live = np.arange(nodes.size)
    at = nodes.astype(np.int64)
    while live.size:
        rows.append(live)
        cols.append(at)
        up = parent[at]
        keep = up >= 0
        live, at = live[keep], up[keep]
    r = np.concatenate(rows) if rows else np.empty(0, np.int64)
    c = np.concatenate(cols) if cols else r
    out = sp.csr_matrix((np.ones(r.size), (r, c)), shape=(nodes.size, parent.size))
    out.sort_indices()
    return out


def _runs(
    signed: sp.csr_matrix, order: NDArray[np.int64], reads: sp.csr_matrix | None = None
) -> list[NDArray[np.int64]]:
    """Group the visits of ``order`` into runs applied at once, equivalent to visiting them
    one by one in ``order``: a constraint goes into the run after the last run holding a
    constraint whose path shares a pose with its own (visits with disjoint paths commute),
    so every two visits that touch a common pose keep their order. With ``reads`` (rows in
    the constraints' order: poses a visit reads besides its path), a constraint also goes
    after the last run changing a pose it reads, and a visit changing a pose goes no earlier
    than the last run reading it (a run reads before it writes). The runs, in order, each
    in visit order; their number is the longest chain of such dependencies."""
    next_run = np.zeros(signed.shape[1], dtype=np.int64)
    ptr, idx = signed.indptr, signed.indices
    run_of = np.zeros(order.size, dtype=np.int64)
    if reads is not None:  # also after the last run writing a pose it reads (none reads late)
        last_read = np.zeros(signed.shape[1], dtype=np.int64)
        rptr, ridx = reads.indptr, reads.indices
    for pos, c in enumerate(order.tolist()):  # once per solve
        nodes = idx[ptr[c] : ptr[c + 1]]
        if nodes.size:
            if reads is None:
                k = int(next_run[nodes].max())
            else:
                seen = ridx[rptr[c] : rptr[c + 1]]
                k = max(int(next_run[nodes].max()), int(next_run[seen].max(initial=0)),
                        int(last_read[nodes].max()))  # fmt: skip
                last_read[seen] = np.maximum(last_read[seen], k)  # distinct poses
            run_of[pos] = k
            next_run[nodes] = k + 1
    by_run = np.argsort(run_of, kind="stable")
    cuts = np.flatnonzero(np.diff(run_of[by_run])) + 1
    return [order[g] for g in np.split(by_run, cuts) if g.size]


def _tree_guess(
    graph: PoseGraph, parent: NDArray[np.int64], levels: list[NDArray[np.int64]]
) -> Array:
    """Poses composed from the root along the first constraint of each tree edge."""
    n = graph.n_poses
    fwd = np.full(n, -1, dtype=np.int64)  # constraint parent → k
    bwd = np.full(n, -1, dtype=np.int64)  # constraint k → parent
    e = np.arange(graph.pp_i.size)[::-1]  # the first constraint in input order wins
    hit = parent[graph.pp_j[e]] == graph.pp_i[e]
    fwd[graph.pp_j[e[hit]]] = e[hit]
    hit = parent[graph.pp_i[e]] == graph.pp_j[e]
    bwd[graph.pp_i[e[hit]]] = e[hit]
    use_fwd = (fwd >= 0) & ((bwd < 0) | (fwd <= np.where(bwd < 0, fwd, bwd)))
    step = np.zeros((n, 3))
    step[use_fwd] = graph.pp_z[fwd[use_fwd]]
    back = ~use_fwd
    back[0] = False
    step[back] = se2.inverse(graph.pp_z[bwd[back]])
    p = np.array(graph.poses, dtype=np.float64)
    for nodes in levels[1:]:
        p[nodes] = se2.compose(p[parent[nodes]], step[nodes])
    return p


def _fixed_weights(info: Array) -> bool:
    """Whether every constraint's translational information is isotropic (``ω I``), so its
    global-frame weight does not depend on the heading and the preconditioner is the same
    in every iteration."""
    return bool(
        np.all(info[:, 0, 0] == info[:, 1, 1])
        and np.all(info[:, 0, 1] == 0)
        and np.all(info[:, 1, 0] == 0)
    )


def _smallest(values: Array) -> Array:
    """Per column, the smallest positive entry of ``values`` (2-D; 1 where there is none)."""
    active = values > 0
    return np.where(active.any(axis=0), np.where(active, values, np.inf).min(axis=0), 1.0)


def _diagonal_information(info: Array) -> bool:
    """Whether every information is ``diag(ω_t, ω_t, ω_θ)``: the same in every frame, so
    TORO's step (the rotated information times the residual) is a fixed fraction of each
    dimension of the residual."""
    return _fixed_weights(info) and bool(
        np.all(info[:, 0, 2] == 0)
        and np.all(info[:, 1, 2] == 0)
        and np.all(info[:, 2, 0] == 0)
        and np.all(info[:, 2, 1] == 0)
    )


def first_per_pair(pp_i: NDArray[np.int64], pp_j: NDArray[np.int64]) -> NDArray[np.bool_]:
    """Which constraints TORO keeps, shape (E,): a constraint ``(i, j)`` is left out when an
    earlier one joins ``i`` and ``j`` (in either direction).

    Measured on OpenSLAM's ``toro``: it loads the study's Method 2 graphs, whose odometry
    and landmark constraints share consecutive pose pairs, with one edge per pair, and its
    iterates equal those of the first constraint of each pair alone (the counts:
    benchmarks/README.md). One difference is known: ``toro`` keeps a later ``(j, i)`` with
    ``i < j`` beside an earlier ``(i, j)``; this keeps the first only.
    """
    lo = np.minimum(pp_i, pp_j).astype(np.int64)
    hi = np.maximum(pp_i, pp_j).astype(np.int64)
    keep = np.zeros(lo.size, dtype=bool)
    if lo.size:
        _, first = np.unique(lo * (int(hi.max()) + 1) + hi, return_index=True)
        keep[first] = True
    return keep


def measurement_weights(z: Array, info: Array) -> Array:
    """TORO's weights, shape (E, 3): the diagonal of ``R(δ_θ) Ω R(δ_θ)ᵀ``, the information
    turned by the constraint's own measured rotation (not by a pose's heading), so they are
    the same in every iteration. Measured on OpenSLAM's ``toro``: its first steps on
    anisotropic constraints fit this rotation to its output precision and none of the other
    candidates (the headings of ``i`` or ``j``, ``±δ_θ``, sums of these, none) comes close
    (the residuals: benchmarks/README.md)."""
    return _turned_diagonal(z[:, 2], info)


def _turned_diagonal(theta: Array, info: Array) -> Array:
    """The diagonal of ``R(θ) Ω Rᵀ(θ)`` for every constraint, shape (E, 3)."""
    c, s_ = np.cos(theta), np.sin(theta)
    wxx = c * c * info[:, 0, 0] - 2 * c * s_ * info[:, 0, 1] + s_ * s_ * info[:, 1, 1]
    wyy = s_ * s_ * info[:, 0, 0] + 2 * c * s_ * info[:, 0, 1] + c * c * info[:, 1, 1]
    return np.column_stack((wxx, wyy, info[:, 2, 2]))


#: Largest ``Σ_k n_k²`` (``n_k`` the tree paths through pose ``k``: the work of the coupling
#: products and a bound on their entries) for which :class:`_TriangularSweep` is used;
#: 36.5 M on ``city10000`` (1.36 M entries per coupling matrix, 213 MB peak in all).
_TRIANGULAR_BUDGET = 80_000_000
#: Whether SciPy solves sparse triangular systems in compiled code (SuperLU, from 1.14);
#: before, ``spsolve_triangular`` loops over the rows in Python, slower than the runs.
_COMPILED_TRIANGULAR = tuple(int(v) for v in re.findall(r"\d+", scipy.__version__)[:2]) >= (1, 14)
#: Triangular solves per iteration for the heading wraps before the runs take over.
_WRAP_PASSES = 8


class _TriangularSweep:
    """One iteration's visits as sparse triangular solves (fixed weights only).

    With weights that do not change over the iterations the preconditioner ``M`` and the
    splits are fixed, and a visit is linear in the parameters except for the heading's
    wrap and the rotation ``R_i δ_t``; headings move with rotational residuals only, so the
    headings are swept first and the translations after, with the headings each visit saw.
    In visit order, the residual a visit sees is ``r_c = s_c·x⁰ + b_c − Σ_{c'<c} L_{cc'} r_c'``
    with ``L_{cc'} = (f_c'/σ_c') Σ_{k ∈ P_c ∩ P_c'} ±M_k⁻¹`` (``σ`` the path's ``Σ M⁻¹``),
    so the sweep is the forward substitution ``(I + L) r = S x⁰ + b``, the same result as
    one visit at a time up to the order of floating-point sums. The wrap is an offset of
    ``2π`` per visit: solved with the previous iteration's offsets, then the visits whose
    heading residual falls outside ``[−π, π)`` are corrected and the sweep solved again
    until none does (each pass fixes at least the first such visit, whose predecessors are
    right); after :data:`_WRAP_PASSES` solves the iteration is left to the runs.
    """

    def __init__(
        self,
        signed: sp.csr_matrix,
        lca: NDArray[np.int64],
        length: Array,
        z: Array,
        weight: Array,
        m_inv: Array,
        gamma: Array,
    ) -> None:
        self.signed = signed
        self.signed_t = signed.T.tocsr()
        self.i_side = signed.multiply(signed > 0).tocsr()
        self.lca, self.z, self.m_inv = lca, z, m_inv
        share = abs(signed) @ m_inv  # (E, 2): Σ_P M⁻¹ per dimension (translation, heading)
        self.share = share
        self.scale = 2.0 * length[:, None] * weight / gamma  # f = min(1, scale / t)
        self.lower: list[sp.csc_matrix] = []
        self.unit: list[Array] = []  # the values of L for f/σ = 1
        self.counts: list[NDArray[np.int64]] = []  # entries per column
        # both dimensions from one product: translation real, heading imaginary (the sums
        # of each part are those of a real product; ±1 times a complex number is exact)
        both = self._coupling(signed, m_inv[:, 0] + 1j * m_inv[:, 1])
        for part in (both.data.real, both.data.imag):
            lower = sp.csc_matrix(
                (part.copy(), both.indices.copy(), both.indptr.copy()), shape=both.shape
            )
            lower.has_sorted_indices = True
            self.lower.append(lower)
            self.unit.append(part.copy())
            self.counts.append(np.diff(lower.indptr))
        self.heading = sp.tril(self.i_side @ sp.diags(m_inv[:, 1]) @ signed.T, k=-1, format="csr")
        self.offset: Array | None = None  # 2π wraps of the heading residuals, per visit

    @staticmethod
    def _coupling(signed: sp.csr_matrix, m_inv: Array) -> sp.csc_matrix:
        """``tril(S diag(m_inv) Sᵀ, −1)`` in visit order with a unit diagonal in both the real
        and the imaginary part (CSC, sorted: the forward substitution's layout)."""
        n = signed.shape[0]
        lower = sp.tril(signed @ sp.diags(m_inv) @ signed.T, k=-1, format="csc")
        lower = (lower + sp.eye(n, dtype=m_inv.dtype, format="csc") * (1 + 1j)).tocsc()
        lower.sum_duplicates()
        lower.sort_indices()
        return lower

    @classmethod
    def build(
        cls,
        signed: sp.csr_matrix,
        lca: NDArray[np.int64],
        length: Array,
        z: Array,
        info: Array,
        rules: RulesKind,
    ) -> _TriangularSweep | None:
        """The sweep for the constraints of ``signed`` (rows in visit order), or ``None``
        when the coupling products exceed :data:`_TRIANGULAR_BUDGET` or SciPy's triangular
        solve is not compiled (:data:`_COMPILED_TRIANGULAR`). ``γ`` is the smallest ``M_k``
        (``rules="papers"``) or the smallest weight of a constraint (``"toro"``)."""
        per_pose = np.diff(signed.tocsc().indptr).astype(np.float64)
        if not _COMPILED_TRIANGULAR or float(per_pose @ per_pose) > _TRIANGULAR_BUDGET:
            return None
        weight = np.column_stack((info[:, 0, 0], info[:, 2, 2]))
        m = abs(signed).T @ weight
        active = m > 0
        gamma = _smallest(m if rules == "papers" else weight[length > 0])
        m_inv = np.zeros_like(m)
        np.divide(1.0, m, out=m_inv, where=active)
        return cls(signed, lca, length, z, weight, m_inv, gamma)

    def _solve(self, d: int, fs: Array, rhs: Array) -> Array:
        """``(I + L) r = rhs`` for dimension ``d`` with the columns of ``L`` scaled by ``fs``."""
        lower = self.lower[d]
        np.multiply(self.unit[d], np.repeat(fs, self.counts[d]), out=lower.data)
        return np.asarray(
            spsolve_triangular(lower, rhs, lower=True, unit_diagonal=True, overwrite_A=True)
        )

    def step(self, x: Array, p: Array, t: float) -> bool:
        """An iteration with fractions ``min(1, scale / t)``, in place on the parameters
        ``x`` (poses ``p`` at its start); ``False``, with ``x`` untouched, when the wraps
        took more than :data:`_WRAP_PASSES` solves (the caller then visits run after run)."""
        frac = np.minimum(1.0, self.scale / t)
        fs = np.zeros_like(frac)
        np.divide(frac, self.share, out=fs, where=self.share > 0)  # r → the path's step
        sx = self.signed @ x  # S x⁰, the path sums at the start
        # headings
        b = sx[:, 2] + self.z[:, 2]
        live = fs[:, 1] > 0
        if self.offset is None:  # the residuals before the visits; later, the last iteration's
            self.offset = -np.floor((b + np.pi) / _TWO_PI)
        for _ in range(_WRAP_PASSES):
            r = self._solve(1, fs[:, 1], b + _TWO_PI * self.offset)
            off = live & ((r < -np.pi) | (r >= np.pi))
            if not off.any():
                break
            self.offset[off] -= np.floor((r[off] + np.pi) / _TWO_PI)
        else:
            return False
        u_th = fs[:, 1] * r
        th = p[self.lca, 2] + self.i_side @ x[:, 2] - self.heading @ u_th
        # translations, with the headings each visit saw
        c, s_ = np.cos(th), np.sin(th)
        zx, zy = self.z[:, 0], self.z[:, 1]
        b2 = sx[:, :2]
        b2[:, 0] += c * zx - s_ * zy
        b2[:, 1] += s_ * zx + c * zy
        u_t = fs[:, :1] * self._solve(0, fs[:, 0], b2)
        x -= self.m_inv[:, [0, 0, 1]] * (self.signed_t @ np.column_stack((u_t, u_th)))
        return True


class _Runs:
    """The visits of an iteration run after run (:func:`_runs`), any weights."""

    def __init__(
        self,
        paths: _Paths,
        visit: NDArray[np.int64],
        i: NDArray[np.int64],
        z: Array,
        info: Array,
        rules: RulesKind,
        parent: NDArray[np.int64],
    ) -> None:
        self.rules = rules
        # TORO's rules read the top pose's heading as the visit finds it: its root path
        reads = _root_paths(parent, paths.lca) if rules == "toro" else None
        runs = _runs(paths.signed, visit, reads)
        # the runs laid end to end: constraint slots [c0, c1) and path entries [n0, n1) per run
        concat = np.concatenate(runs) if runs else np.empty(0, np.int64)
        sub = paths.signed[concat]
        self.lca, self.i, self.info = paths.lca[concat], i[concat], info[concat]
        self.nodes = sub.indices.astype(np.int64)
        self.sign = sub.data.astype(np.float64)
        self.starts = sub.indptr[:-1]
        self.owner = np.repeat(np.arange(concat.size), np.diff(sub.indptr))
        self.length = paths.length[concat].astype(np.float64)
        self.absolute = abs(sub).T.tocsr()  # (N, E): sums of W over the constraints on k
        # per entry: (±1 for the path difference, 1 on the i side for the heading of i)
        factor = np.stack((self.sign, (self.sign > 0).astype(np.float64)), axis=1)[:, None, :]
        bounds = np.cumsum([0] + [r.size for r in runs])
        z_run = np.asarray(z)[concat]
        # per iteration, filled in place: each path entry's step per unit residual (the
        # signed share times −f) and each constraint's top heading; the runs hold views
        self.step_all = np.zeros((self.nodes.size, 3))
        self.th_top = np.zeros(concat.size)
        self.gain = np.zeros((concat.size, 3))  # rules="toro": 2|P|/γ per dimension
        rot_a = z_run[:, :2].copy()  # R δ_t = cos θ (δx, δy) + sin θ (−δy, δx)
        rot_b = np.column_stack((-z_run[:, 1], z_run[:, 0]))
        self.blocks = []
        for k in range(len(runs)):
            c0, c1 = int(bounds[k]), int(bounds[k + 1])
            n0, n1 = int(sub.indptr[c0]), int(sub.indptr[c1])
            self.blocks.append(
                (self.nodes[n0:n1], self.owner[n0:n1] - c0,
                 (sub.indptr[c0:c1] - n0).astype(np.int64), factor[n0:n1],
                 self.step_all[n0:n1], self.th_top[c0:c1], rot_a[c0:c1], rot_b[c0:c1],
                 z_run[c0:c1, 2], self.info[c0:c1], self.gain[c0:c1])
            )  # fmt: skip
        if rules == "toro":  # fixed weights: the splits and each constraint's gain, once
            w = measurement_weights(z_run, self.info)
            gamma = _smallest(w[self.length > 0])
            self._set_split(self.absolute @ w)
            self.gain[:] = 2.0 * self.length[:, None] / gamma  # times Ω r / (t + 1)
            self.step_all[:] = self.split
            # the top pose's heading as the visit finds it (earlier visits of the iteration
            # turn its ancestors): the sum of the headings' parameters from the root to it
            assert reads is not None
            top = reads[concat]
            self.tops = [top[int(bounds[k]) : int(bounds[k + 1])] for k in range(len(runs))]

    def _set_split(self, m: Array) -> None:
        """Each path entry's signed share ``±M_k⁻¹ / Σ_P M⁻¹`` (per dimension) from ``M``."""
        m_inv = np.zeros_like(m)
        np.divide(1.0, m, out=m_inv, where=m > 0)
        mn = m_inv[self.nodes]
        share = np.add.reduceat(mn, self.starts) if self.lca.size else mn
        self.split = np.zeros_like(mn)
        own = share[self.owner]
        np.divide(mn * self.sign[:, None], own, out=self.split, where=own > 0)

    def step(self, x: Array, p: Array, t: int) -> None:
        """Iteration ``t`` in place on the parameters ``x`` (poses ``p`` at its start)."""
        if self.rules == "toro":
            self._toro_step(x, p, t)
            return
        w = _turned_diagonal(p[self.i, 2], self.info)  # the global frame's weights
        m = self.absolute @ w
        frac = np.minimum(1.0, 2.0 * self.length[:, None] * w / (_smallest(m) * t))
        # what stays fixed within an iteration: the share of each path pose
        # (M_k⁻¹ / Σ_P M⁻¹, signed), the fractions, the top poses' headings
        self._set_split(m)
        np.multiply(self.split, -frac[self.owner], out=self.step_all)
        np.take(p[:, 2], self.lca, out=self.th_top)
        for nodes, owner, starts, factor, step, top, za, zb, z_th, _, _ in self.blocks:
            xn = x[nodes]
            # (t_i − t_j, θ_i − θ_j) over the path and Σ of the i side's parameters, at once
            both = np.add.reduceat(xn[:, :, None] * factor, starts)
            th = both[:, 2, 1]
            th += top
            r = both[:, :, 0]
            r[:, :2] += np.cos(th)[:, None] * za + np.sin(th)[:, None] * zb
            a = r[:, 2]
            a += z_th
            a -= _TWO_PI * np.rint(a / _TWO_PI)  # wrapped
            x[nodes] = xn + step * r[owner]  # the poses of a run are distinct

    def _toro_step(self, x: Array, p: Array, t: int) -> None:
        """TORO's iteration ``t``: a visit moves its path by ``u = 2|P| γ⁻¹ (R_i Ω Rᵢᵀ) r_c /
        (t + 1)`` (per dimension ``γ``), where a dimension with ``|u| > |r|`` takes ``u = r``,
        split along the path by the fixed shares."""
        scale = 1.0 / (t + 1.0)
        heading = x[:, 2]
        for block, top in zip(self.blocks, self.tops, strict=True):
            nodes, owner, starts, factor, split, _, za, zb, z_th, info, gain = block
            xn = x[nodes]
            both = np.add.reduceat(xn[:, :, None] * factor, starts)
            th = both[:, 2, 1]
            th += top @ heading
            c, s_ = np.cos(th), np.sin(th)
            r = both[:, :, 0]
            r[:, :2] += c[:, None] * za + s_[:, None] * zb
            a = r[:, 2]
            a += z_th
            a -= _TWO_PI * np.rint(a / _TWO_PI)  # wrapped
            # (R Ω Rᵀ) r: into the frame of i, through Ω, back
            loc = np.column_stack((c * r[:, 0] + s_ * r[:, 1], c * r[:, 1] - s_ * r[:, 0], a))
            g = np.einsum("eab,eb->ea", info, loc)
            g[:, 0], g[:, 1] = c * g[:, 0] - s_ * g[:, 1], s_ * g[:, 0] + c * g[:, 1]
            u = g * gain * scale
            np.copyto(u, r, where=np.abs(u) > np.abs(r))
            x[nodes] = xn - split * u[owner]


def toro_optimize(
    graph: PoseGraph,
    *,
    iterations: int = 100,
    tree: TreeKind = "incremental",
    order: OrderKind = "depth",
    initial: InitialKind = "tree",
    rules: RulesKind = "toro",
) -> TreeSolution:
    """Optimise a pose graph (pose–pose constraints only) as TORO does (module docstring).

    Parameters
    ----------
    graph : PoseGraph
        Pose 0 is the root and stays fixed; landmark factors are refused.
    iterations : int
        Passes over all constraints.
    tree : {"incremental", "breadth-first"}
    order : {"depth", "input"}
    initial : {"tree", "given"}
    rules : {"toro", "papers"}
        ``"toro"``: the step, weights, ``γ`` and one constraint per pose pair of OpenSLAM's
        ``toro``, as measured on it; ``"papers"``: the update as the papers state it (module
        docstring).

    Returns
    -------
    TreeSolution
        The last iterate; its cost counts every constraint of ``graph``, also those
        ``rules="toro"`` left out (``dropped``).
    """
    if graph.pl_k.size:
        raise InputError("the TORO optimiser takes pose graphs only (no landmark factors)")
    if iterations < 0:
        raise InputError(f"need iterations >= 0, got {iterations}")
    for name, value, allowed in (
        ("tree", tree, TORO_TREES),
        ("order", order, TORO_ORDERS),
        ("initial", initial, TORO_INITIAL),
        ("rules", rules, TORO_RULES),
    ):
        if value not in allowed:
            raise InputError(f"{name} must be one of {', '.join(allowed)}; got {value!r}")
    n = graph.n_poses
    full = graph
    keep = first_per_pair(graph.pp_i, graph.pp_j) if rules == "toro" else None
    if keep is not None and not keep.all():
        graph = PoseGraph(
            graph.poses, graph.landmarks, graph.pp_i[keep], graph.pp_j[keep],
            graph.pp_z[keep], graph.pp_info[keep],
        )  # fmt: skip
    pi, pj = graph.pp_i, graph.pp_j
    parent = spanning_tree(n, pi, pj)  # first: a pose not connected to pose 0 is said as such
    if tree == "incremental":
        parent = incremental_tree(n, pi, pj)
    depth, levels = _depths(parent)
    paths = _paths(parent, depth, pi, pj)
    visit = np.argsort(depth[paths.lca], kind="stable") if order == "depth" else np.arange(pi.size)
    p0 = _tree_guess(graph, parent, levels) if initial == "tree" else np.array(graph.poses)
    x = p0.copy()
    x[1:] = p0[1:] - p0[parent[1:]]
    x[1:, 2] = se2.wrap_angle(x[1:, 2])
    z = np.asarray(graph.pp_z)
    info = np.asarray(graph.pp_info)
    length = paths.length.astype(np.float64)

    # the poses from the parameters, p_k = x_k + p_parent(k): one forward substitution in
    # breadth-first order (parents first), where it is p_k = x_k − (−1)·p_parent(k)
    tree_order = np.concatenate(levels)
    rank = np.empty(n, dtype=np.int64)
    rank[tree_order] = np.arange(n)
    below = tree_order[1:]
    compose = sp.csc_matrix(
        (np.concatenate((np.ones(n), np.full(n - 1, -1.0))),
         (np.concatenate((np.arange(n), rank[below])),
          np.concatenate((np.arange(n), rank[parent[below]])))),
        shape=(n, n),
    )  # fmt: skip
    compose.sort_indices()

    def poses_of(params: Array) -> Array:
        if _COMPILED_TRIANGULAR:
            return np.asarray(spsolve_triangular(compose, params[tree_order], lower=True))[rank]
        p = params.copy()
        for nodes in levels[1:]:
            p[nodes] += p[parent[nodes]]
        return p

    sweep = None
    if _fixed_weights(info) if rules == "papers" else _diagonal_information(info):
        sweep = _TriangularSweep.build(
            paths.signed[visit], paths.lca[visit], length[visit], z[visit], info[visit], rules
        )
    runs: _Runs | None = None  # built when first needed
    p = poses_of(x)
    costs = [graph_cost(p, full)]
    for t in range(1, iterations + 1):
        # TORO's fraction in iteration t is 2|P|W/(γ(t + 1)) (measured), the papers' /(γt)
        if sweep is None or not sweep.step(x, p, t + 1 if rules == "toro" else t):
            if runs is None:
                runs = _Runs(paths, visit, pi, z, info, rules, parent)
            runs.step(x, p, t)
        p = poses_of(x)
        costs.append(graph_cost(p, full))
    p[:, 2] = se2.wrap_angle(p[:, 2])
    return TreeSolution(
        readonly(p),
        readonly(np.asarray(costs)),
        int(iterations),
        readonly(parent, np.int64),
        float(paths.length.mean()) if paths.length.size else 0.0,
        len(runs.blocks) if runs is not None else 0,
        int(keep.size - keep.sum()) if keep is not None else 0,
    )
