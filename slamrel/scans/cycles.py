"""The set-level check of reference relations: each relation against the short cycles it
closes with the others (pure numpy; no I/O).

A relation set is a graph: scans (or poses) are nodes, each relation ``δ_k = x_a⁻¹ ∘ x_b``
an edge ``a → b`` with covariance ``Σ_k`` (the aligner's Gauss–Newton covariance, never
below a floor, :class:`CycleOptions`), optionally joined by a *chain* (the sequential
odometry or scan-matched motion, edges of the same kind). A cycle through the relation
``a → b`` returns to ``a`` by other edges; the relations along it compose to the identity
when all are right:

    C = δ_1 ∘ δ_2^{±1} ∘ … ∘ δ_L^{±1}  (L = 2, 3 or 4 edges: a parallel relation, a triangle,
    a quadrilateral such as relation – chain – relation – chain),

    χ² = cᵀ Σ_C⁻¹ c,  c = [x, y, wrap(θ)] of C,  Σ_C = Σ_l J_l Σ_l J_lᵀ

with the first-order Jacobians of composition and inversion (:func:`compose_cycles`). A
cycle *fails* when χ² exceeds the ``1 − alpha`` quantile of χ²(3).

Who is to blame (:func:`blame`): a relation is **contradicted** when at least
``min_failed`` of its cycles fail *because of it* and they are more than ``fail_share`` of
its cycles — a failed cycle is laid on it when every other edge of that cycle passes
elsewhere (fails in at most ``fail_share`` of its cycles without this relation). A relation
in no other cycle cannot clear itself (two bad relations at one scan must not put the blame
on the good one they share); a step of the chain in no other cycle counts as passing (the
chain is short, sequential motion). The
decision is greedy: the worst candidate first; its cycles are then set aside (they are
explained), so a second bad relation nearby is judged by the cycles left. A relation whose
failed cycles cannot be laid on it alone (two bad neighbours, or only one cycle) is not
flagged; ``cycles == 0`` says it could not be checked at all.

Work is bounded: at most ``max_branch`` edges are followed from each end of a relation, and
at most ``max_cycles`` cycles (the shortest first) are kept per relation.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.stats import chi2 as chi2_dist

from relation_metric.se2 import compose, compose_jacobian, inverse

if TYPE_CHECKING:
    from slamrel.scans.relations import ScanRelations

__all__ = [
    "CycleOptions",
    "CycleCheck",
    "check_cycles",
    "check_scan_relations",
    "find_cycles",
    "compose_cycles",
    "blame",
    "mark_contradicted",
]


@dataclass(frozen=True)
class CycleOptions:
    """How relations are tested against their cycles.

    Attributes
    ----------
    max_length : int
        Longest cycle, in edges (2–4; default 4).
    max_cycles : int
        Cycles kept per relation, the shortest first (default 20).
    max_branch : int
        Edges followed from each end of a relation (default 16).
    alpha : float
        False-alarm rate of one cycle's χ²(3) test (default 0.01).
    min_sd_xy, min_sd_theta : float
        Floor of each edge's standard deviations [m], [rad] (0.01 m, 0.005 rad): the aligner's
        covariance is optimistic (correlated laser residuals), and a chain of them would fail
        right relations.
    min_failed : int
        Least number of failed cycles laid on a relation to flag it (default 2).
    fail_share : float
        Share of a relation's cycles that must fail because of it (default 0.5).
    """

    max_length: int = 4
    max_cycles: int = 20
    max_branch: int = 16
    alpha: float = 0.01
    min_sd_xy: float = 0.01
    min_sd_theta: float = 0.005
    min_failed: int = 2
    fail_share: float = 0.5


@dataclass(frozen=True)
class CycleCheck:
    """The verdict on ``M`` relations.

    Attributes
    ----------
    contradicted : (M,) bool
        Flagged: its neighbours contradict it.
    cycles, failed : (M,) int
        Cycles through the relation that were tested, and how many failed.
    blamed : (M,) int
        Failed cycles laid on the relation (0 unless contradicted).
    n_cycles : int
        Distinct cycles tested.
    """

    contradicted: NDArray[np.bool_]
    cycles: NDArray[np.int64]
    failed: NDArray[np.int64]
    blamed: NDArray[np.int64]
    n_cycles: int

    @property
    def count(self) -> int:
        """Number of contradicted relations."""
        return int(np.count_nonzero(self.contradicted))

    def confirmed(self, min_cycles: int = 2) -> NDArray[np.bool_]:
        """Relations in at least ``min_cycles`` cycles, none of which failed. (Relations
        wrong by the same amount, e.g. neighbouring loop pairs slid alike along a corridor,
        close their short cycles with each other: confirmation is evidence, not proof.)"""
        return (self.cycles >= min_cycles) & (self.failed == 0)

    @property
    def unchecked(self) -> int:
        """Relations in no cycle (nothing to test them against)."""
        return int(np.count_nonzero(self.cycles == 0))


def _expand(
    nodes: NDArray[np.int64], offsets: NDArray[np.int64], order: NDArray[np.int64], cap: int
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """For each query ``nodes[q]``, its first ``cap`` half-edges: ``(q (K,), half-edge (K,))``."""
    start = offsets[nodes]
    count = np.minimum(offsets[nodes + 1] - start, cap)
    rep = np.repeat(np.arange(nodes.size), count)
    first = np.repeat(np.cumsum(count) - count, count)
    pos = np.arange(rep.size) - first + np.repeat(start, count)
    return rep, order[pos]


def _join(
    left: NDArray[np.int64], right: NDArray[np.int64]
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """All index pairs ``(i, j)`` with ``left[i] == right[j]``."""
    order = np.argsort(right, kind="stable")
    srt = right[order]
    lo = np.searchsorted(srt, left, "left")
    n = np.searchsorted(srt, left, "right") - lo
    i = np.repeat(np.arange(left.size), n)
    j = np.arange(i.size) - np.repeat(np.cumsum(n) - n, n) + np.repeat(lo, n)
    return i, order[j]


def find_cycles(
    first: ArrayLike, second: ArrayLike, tested: ArrayLike, options: CycleOptions | None = None
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """Short cycles through each tested edge ``first[k] → second[k]`` (vectorised).

    Parameters
    ----------
    first, second : (E,) int
        Node ids of each edge's two ends (any integers).
    tested : (E,) bool
        Edges whose cycles are sought (others only join them).

    Returns
    -------
    owner : (C,) int
        The tested edge each cycle was found for (its first step, taken forwards).
    edges : (C, 4) int
        The edges along the cycle, ``-1`` after its end.
    signs : (C, 4) int
        ``+1`` an edge taken forwards, ``-1`` inverted, 0 after the end.
    """
    opt = options or CycleOptions()
    ids, ends = np.unique(np.concatenate((first, second)).astype(np.int64), return_inverse=True)
    e = ends.size // 2
    a, b = ends[:e], ends[e:]
    v = max(ids.size, 1)
    hu, hv = np.concatenate((a, b)), np.concatenate((b, a))
    he = np.concatenate((np.arange(e), np.arange(e)))
    hs = np.concatenate((np.ones(e, np.int64), -np.ones(e, np.int64)))
    order = np.argsort(hu, kind="stable")
    offsets = np.searchsorted(hu[order], np.arange(v + 1))
    t = np.flatnonzero(np.asarray(tested, dtype=bool))
    qa, ha = _expand(a[t], offsets, order, opt.max_branch)
    keep = he[ha] != t[qa]
    qa, ha = qa[keep], ha[keep]
    qb, hb = _expand(b[t], offsets, order, opt.max_branch)
    keep = he[hb] != t[qb]
    qb, hb = qb[keep], hb[keep]
    found = []
    # length 2: another edge between a and b
    two = hv[ha] == b[t[qa]]
    found.append((qa[two], [he[ha[two]]], [-hs[ha[two]]]))
    if opt.max_length >= 3:
        far_a = hv[ha] != b[t[qa]]
        far_b = hv[hb] != a[t[qb]]
        la, lb = np.flatnonzero(far_a), np.flatnonzero(far_b)
        i, j = _join(qa[la] * v + hv[ha[la]], qb[lb] * v + hv[hb[lb]])
        h1, h2 = ha[la[i]], hb[lb[j]]
        ok = he[h1] != he[h2]
        found.append((qa[la[i]][ok], [he[h2[ok]], he[h1[ok]]], [hs[h2[ok]], -hs[h1[ok]]]))
    if opt.max_length >= 4:
        found.append(_four_cycles(t, a, b, (qa, ha, qb, hb), (hv, he, hs), offsets, order, v, opt))
    return _capped(t, found, opt.max_cycles)


def _four_cycles(
    t: NDArray[np.int64],
    a: NDArray[np.int64],
    b: NDArray[np.int64],
    branches: tuple[NDArray[np.int64], ...],
    half: tuple[NDArray[np.int64], ...],
    offsets: NDArray[np.int64],
    order: NDArray[np.int64],
    v: int,
    opt: CycleOptions,
) -> tuple[NDArray[np.int64], list[NDArray[np.int64]], list[NDArray[np.int64]]]:
    """Cycles ``a → b → d → c → a``: a step from ``a`` to ``c``, one from ``c`` to ``d``, one
    from ``b`` to ``d``, four distinct nodes and edges."""
    qa, ha, qb, hb = branches
    hv, he, hs = half
    ta, tb = t[qa], t[qb]
    sa = (hv[ha] != b[ta]) & (hv[ha] != a[ta])
    sb = (hv[hb] != a[tb]) & (hv[hb] != b[tb])
    qa, ha, qb, hb = qa[sa], ha[sa], qb[sb], hb[sb]
    r, h3 = _expand(hv[ha], offsets, order, opt.max_branch)
    q, h1 = qa[r], ha[r]
    ends = hv[h3]
    ok = (he[h3] != he[h1]) & (he[h3] != t[q]) & (ends != a[t[q]]) & (ends != b[t[q]])
    q, h1, h3 = q[ok], h1[ok], h3[ok]
    i, j = _join(q * v + hv[h3], qb * v + hv[hb])
    h2 = hb[j]
    q, h1, h3 = q[i], h1[i], h3[i]
    ok = (he[h2] != he[h1]) & (he[h2] != he[h3])
    q, h1, h2, h3 = q[ok], h1[ok], h2[ok], h3[ok]
    return q, [he[h2], he[h3], he[h1]], [hs[h2], -hs[h3], -hs[h1]]


def _capped(
    t: NDArray[np.int64],
    found: list[tuple[NDArray[np.int64], list[NDArray[np.int64]], list[NDArray[np.int64]]]],
    cap: int,
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """The cycles of every length as padded arrays, at most ``cap`` per tested edge (the
    shortest first)."""
    owners, edges, signs = [], [], []
    for q, es, ss in found:
        n = q.size
        row_e = np.full((n, 4), -1, np.int64)
        row_s = np.zeros((n, 4), np.int64)
        row_e[:, 0], row_s[:, 0] = t[q], 1
        for k, (ek, sk) in enumerate(zip(es, ss, strict=True)):
            row_e[:, k + 1], row_s[:, k + 1] = ek, sk
        owners.append(t[q])
        edges.append(row_e)
        signs.append(row_s)
    owner = np.concatenate(owners)
    edge = np.concatenate(edges)
    sign = np.concatenate(signs)
    order = np.argsort(owner, kind="stable")  # within an owner: by length, then found order
    owner, edge, sign = owner[order], edge[order], sign[order]
    start = np.searchsorted(owner, owner, "left")
    keep = np.arange(owner.size) - start < cap
    return owner[keep], edge[keep], sign[keep]


def _inverse_jacobian(d: NDArray[np.float64]) -> NDArray[np.float64]:
    """``∂(d⁻¹)/∂d = [[−c, −s, s x − c y], [s, −c, c x + s y], [0, 0, −1]]`` ``(..., 3, 3)``."""
    c, s = np.cos(d[..., 2]), np.sin(d[..., 2])
    x, y = d[..., 0], d[..., 1]
    j = np.zeros(d.shape[:-1] + (3, 3))
    j[..., 0, 0], j[..., 0, 1], j[..., 0, 2] = -c, -s, s * x - c * y
    j[..., 1, 0], j[..., 1, 1], j[..., 1, 2] = s, -c, c * x + s * y
    j[..., 2, 2] = -1.0
    return j


def compose_cycles(
    delta: NDArray[np.float64],
    covariance: NDArray[np.float64],
    edges: NDArray[np.int64],
    signs: NDArray[np.int64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The composition ``C`` (C, 3) of each cycle and its first-order covariance (C, 3, 3).

    ``P ← P ∘ T`` with ``T = δ`` or ``δ⁻¹``: ``Σ_P ← J_P Σ_P J_Pᵀ + J_T Σ_T J_Tᵀ``,
    ``J_P = ∂(P ∘ T)/∂P``, ``J_T = blockdiag(R(θ_P), 1)``; an inverted edge's covariance is
    ``J_inv Σ J_invᵀ``.
    """
    n = edges.shape[0]
    pose = np.zeros((n, 3))
    cov = np.zeros((n, 3, 3))
    for k in range(edges.shape[1]):
        on = edges[:, k] >= 0
        d = delta[edges[on, k]]
        sd = covariance[edges[on, k]]
        inv = signs[on, k] < 0
        j_inv = _inverse_jacobian(d[inv])
        sd[inv] = j_inv @ sd[inv] @ np.swapaxes(j_inv, 1, 2)
        d[inv] = inverse(d[inv])
        p = pose[on]
        j_p = compose_jacobian(p, d)
        j_t = np.zeros((p.shape[0], 3, 3))
        c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
        j_t[:, 0, 0], j_t[:, 0, 1], j_t[:, 1, 0], j_t[:, 1, 1], j_t[:, 2, 2] = c, -s, s, c, 1
        cov[on] = j_p @ cov[on] @ np.swapaxes(j_p, 1, 2) + j_t @ sd @ np.swapaxes(j_t, 1, 2)
        pose[on] = compose(p, d)
    return pose, cov


def blame(
    members: NDArray[np.int64],
    failed: NDArray[np.bool_],
    n_edges: int,
    options: CycleOptions,
    trusted: NDArray[np.bool_] | None = None,
) -> tuple[NDArray[np.bool_], NDArray[np.int64]]:
    """Which edges their cycles contradict (module docstring), greedily.

    Parameters
    ----------
    members : (C, 4) int
        Edges of each distinct cycle (``-1`` padding).
    failed : (C,) bool
    n_edges : int
    trusted : (n_edges,) bool, optional
        Edges (the chain's) that count as passing when they are in no other cycle; any
        other edge must pass in cycles of its own to clear a cycle it shares.

    Returns
    -------
    contradicted : (n_edges,) bool
    blamed : (n_edges,) int
        Failed cycles laid on each contradicted edge.
    """
    trust = np.zeros(n_edges, bool) if trusted is None else trusted
    cyc, edge = np.nonzero(members >= 0)
    edge = members[cyc, edge]
    order = np.argsort(edge, kind="stable")
    cycles_of = cyc[order]
    offsets = np.searchsorted(edge[order], np.arange(n_edges + 1))
    tot = np.bincount(edge, minlength=n_edges)
    bad = np.bincount(edge[failed[cyc]], minlength=n_edges)
    alive = np.ones(members.shape[0], bool)
    flagged = np.zeros(n_edges, bool)
    blamed = np.zeros(n_edges, np.int64)
    settled = np.zeros(n_edges, bool)  # examined since the last flag, not to blame
    while True:
        share = bad / np.maximum(tot, 1)
        cand = (bad >= options.min_failed) & (share > options.fail_share) & ~flagged & ~settled
        if not cand.any():
            return flagged, blamed
        e = int(np.flatnonzero(cand)[np.lexsort((-bad[cand], -share[cand]))[0]])
        mine = cycles_of[offsets[e] : offsets[e + 1]]
        mine = mine[alive[mine]]
        laid = _laid_on(members[mine], failed[mine], e, (tot, bad, trust), options)
        if laid >= options.min_failed and laid > options.fail_share * tot[e]:
            flagged[e], blamed[e] = True, laid
            alive[mine] = False
            gone = members[mine]
            on = gone >= 0
            tot -= np.bincount(gone[on], minlength=n_edges)
            f = np.broadcast_to(failed[mine][:, None], gone.shape)
            bad -= np.bincount(gone[on & f], minlength=n_edges)
            settled[:] = False
        else:
            settled[e] = True


def _laid_on(
    its: NDArray[np.int64],
    its_failed: NDArray[np.bool_],
    e: int,
    counts: tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.bool_]],
    options: CycleOptions,
) -> int:
    """How many of ``e``'s failed cycles (``its``: the members of its alive cycles) are laid
    on it: every other edge of the cycle passes elsewhere (fails at most ``fail_share`` of
    its cycles without ``e``; a relation in no other cycle does not pass, a trusted step of
    the chain does)."""
    tot, bad, trusted = counts
    on = its >= 0
    ids, where = np.unique(its[on], return_inverse=True)
    shared_tot = np.bincount(where, minlength=ids.size)
    f = np.broadcast_to(its_failed[:, None], its.shape)[on]
    shared_bad = np.bincount(where[f], minlength=ids.size)
    else_tot = tot[ids] - shared_tot
    else_bad = bad[ids] - shared_bad
    passes = (else_bad <= options.fail_share * else_tot) & ((else_tot > 0) | trusted[ids])
    passes[ids == e] = True
    ok = np.ones(its.shape, bool)
    ok[on] = passes[where]
    return int(np.count_nonzero(ok.all(axis=1) & its_failed))


def check_cycles(
    first: ArrayLike,
    second: ArrayLike,
    delta: ArrayLike,
    covariance: ArrayLike,
    *,
    chain: tuple[ArrayLike, ArrayLike, ArrayLike, ArrayLike] | None = None,
    options: CycleOptions | None = None,
) -> CycleCheck:
    """Test ``M`` relations ``first[k] → second[k]`` (``δ`` (M, 3), ``Σ`` (M, 3, 3)) against
    the cycles they close with each other and with ``chain`` (``first, second, δ, Σ`` of the
    sequential edges, which join cycles and may take the blame but are not reported).

    Node ids are any integers (scan indices, pose ids); the chain uses the same ids.
    """
    opt = options or CycleOptions()
    f = np.asarray(first, dtype=np.int64).reshape(-1)
    s = np.asarray(second, dtype=np.int64).reshape(-1)
    d = np.asarray(delta, dtype=np.float64).reshape(-1, 3)
    cov = np.asarray(covariance, dtype=np.float64).reshape(-1, 3, 3)
    m = f.size
    if chain is not None:
        cf, cs, cd, cc = chain
        f = np.concatenate((f, np.asarray(cf, dtype=np.int64).reshape(-1)))
        s = np.concatenate((s, np.asarray(cs, dtype=np.int64).reshape(-1)))
        d = np.concatenate((d, np.asarray(cd, dtype=np.float64).reshape(-1, 3)))
        cov = np.concatenate((cov, np.asarray(cc, dtype=np.float64).reshape(-1, 3, 3)))
    floor = np.array([opt.min_sd_xy, opt.min_sd_xy, opt.min_sd_theta]) ** 2
    cov = cov + np.diag(floor)
    tested = np.arange(f.size) < m
    owner, edges, signs = find_cycles(f, s, tested, opt)
    canon = np.sort(edges, axis=1)
    _, first_of, which = np.unique(canon, axis=0, return_index=True, return_inverse=True)
    which = which.reshape(-1)
    c, sc = compose_cycles(d, cov, edges[first_of], signs[first_of])
    chi2 = np.einsum("ci,ci->c", c, np.linalg.solve(sc, c[..., None])[..., 0])
    failed = chi2 > chi2_dist.ppf(1.0 - opt.alpha, 3)
    flagged, blamed = blame(np.sort(edges[first_of], axis=1), failed, f.size, opt, ~tested)
    return CycleCheck(
        contradicted=flagged[:m],
        cycles=np.bincount(owner, minlength=f.size)[:m],
        failed=np.bincount(owner[failed[which]], minlength=f.size)[:m],
        blamed=blamed[:m],
        n_cycles=int(first_of.size),
    )


def check_scan_relations(
    result: ScanRelations,
    *,
    use: ArrayLike | None = None,
    chain: tuple[ArrayLike, ArrayLike, ArrayLike, ArrayLike] | None = None,
    options: CycleOptions | None = None,
) -> CycleCheck:
    """:func:`check_cycles` on the relations of :func:`~slamrel.scans.relations.align_scans`.

    Nodes are scan indices (``result.proposals.pairs``). ``use`` (P,) bool picks the relations
    that take part (default: those not flagged — a flagged relation is already for review and
    would only blur its neighbours' cycles); the others get ``cycles == 0`` and are never
    contradicted. ``chain`` (scan indices, motions, covariances) is passed on.
    """
    p = len(result)
    take = ~result.flagged if use is None else np.asarray(use, dtype=bool).reshape(p)
    take &= np.isfinite(result.covariance).all(axis=(1, 2)) & np.isfinite(result.delta).all(1)
    idx = np.flatnonzero(take)
    pairs = result.proposals.pairs[idx]
    got = check_cycles(
        pairs[:, 0],
        pairs[:, 1],
        result.delta[idx],
        result.covariance[idx],
        chain=chain,
        options=options,
    )

    contradicted = np.zeros(p, bool)
    contradicted[idx] = got.contradicted
    counts = np.zeros((3, p), np.int64)
    counts[:, idx] = (got.cycles, got.failed, got.blamed)
    return CycleCheck(
        contradicted=contradicted,
        cycles=counts[0],
        failed=counts[1],
        blamed=counts[2],
        n_cycles=got.n_cycles,
    )


def mark_contradicted(result: ScanRelations, check: CycleCheck) -> ScanRelations:
    """``result`` with the flag ``contradicted`` added to the relations ``check`` contradicts;
    their suspicion is raised to at least ``1 + blamed / cycles`` (1.5–2), so the review
    visits them."""
    from dataclasses import replace

    c = check.contradicted
    flags = result.flags.astype(object)
    flags[c] = [f"{f}, contradicted" if f else "contradicted" for f in flags[c]]
    share = check.blamed / np.maximum(check.cycles, 1)
    suspicion = np.where(c, np.maximum(result.suspicion, 1.0 + share), result.suspicion)
    return replace(result, flags=flags.astype(str), suspicion=suspicion)
