"""Landmark association between an estimated and a reference map, and OSPA / GOSPA.

Association modes: by id (optionally through an id map), from a user CSV
(``estimate,reference`` id pairs, overriding everything else), or automatic: a robust rigid
alignment (seeded RANSAC over pairs of points with matching distances, refined by Umeyama on
the inliers) followed by the optimal assignment (``scipy.optimize.linear_sum_assignment``) on
the aligned distances with a cut-off.

OSPA (Schuhmacher, Vo & Vo 2008) and GOSPA with α = 2 (Rahmathullah, García-Fernández &
Svensson 2017) for sets X (m points) and Y (n points), ``m ≤ n``, cut-off ``c`` and order
``p``, over the assignment π that minimises ``Σ min(d, c)^p``:

    OSPA  = ( (1/n) [ Σ_i min(d(x_i, y_π(i)), c)^p + c^p (n − m) ] )^(1/p)
    GOSPA = ( Σ_i min(d(x_i, y_π(i)), c)^p + (c^p / 2) (n − m) )^(1/p)

The assignment is computed on ``min(d, c)^p`` — not on ``min(d, c)``, which is only the same
problem for ``p = 1``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree

from landmark_graph.maps import LandmarkMap
from relation_metric.alignment import Alignment, umeyama
from relation_metric.errors import InputError

_MAX_SMALL_HYPOTHESES = 20_000
#: OSPA and GOSPA solve the dense ``m × n`` assignment up to this many pairs (32 MB of
#: distances; the results of all earlier versions, bit for bit) and the sparse one on the
#: pairs within the cut-off beyond (20,000 landmarks a side: 3.2 GB dense per matrix).
DENSE_ASSIGNMENT_PAIRS = 4_000_000

__all__ = [
    "Association",
    "associate_by_id",
    "associate_auto",
    "ospa",
    "gospa",
]


@dataclass(frozen=True)
class Association:
    """Matched landmark rows and what is left over.

    Attributes
    ----------
    estimate_rows, reference_rows : ndarray of int, shape (K,)
        Rows of the estimated and reference maps that are matched.
    missed : ndarray of int
        Reference rows without a match.
    spurious : ndarray of int
        Estimated rows without a match.
    alignment : Alignment or None
        The rigid alignment (automatic mode).
    """

    estimate_rows: NDArray[np.int64]
    reference_rows: NDArray[np.int64]
    missed: NDArray[np.int64]
    spurious: NDArray[np.int64]
    alignment: Alignment | None = None

    def as_dict(self, est: LandmarkMap, ref: LandmarkMap) -> dict[str, object]:
        return {
            "matched": int(self.estimate_rows.size),
            "missed": int(self.missed.size),
            "spurious": int(self.spurious.size),
            "missed_ids": ref.ids[self.missed].tolist(),
            "spurious_ids": est.ids[self.spurious].tolist(),
        }


def _finish(est: LandmarkMap, ref: LandmarkMap, er, rr, alignment=None) -> Association:  # type: ignore[no-untyped-def]
    er = np.asarray(er, dtype=np.int64)
    rr = np.asarray(rr, dtype=np.int64)
    order = np.argsort(rr, kind="stable")
    er, rr = er[order], rr[order]
    missed = np.setdiff1d(np.arange(len(ref)), rr)
    spurious = np.setdiff1d(np.arange(len(est)), er)
    return Association(er, rr, missed, spurious, alignment)


def associate_by_id(
    est: LandmarkMap, ref: LandmarkMap, id_map: dict[int, int] | None = None
) -> Association:
    """Match landmarks with the same id (after mapping estimated ids through ``id_map``)."""
    e_ids = est.ids if id_map is None else np.array([id_map.get(int(i), -(2**62)) for i in est.ids])
    common, er, rr = np.intersect1d(e_ids, ref.ids, return_indices=True)
    return _finish(est, ref, er, rr)


def associate_auto(
    est: LandmarkMap,
    ref: LandmarkMap,
    *,
    cutoff: float = 1.0,
    iterations: int = 500,
    seed: int = 0,
) -> Association:
    """Robust rigid alignment (seeded RANSAC) then the optimal assignment within ``cutoff``.

    1. Candidate correspondences: for up to 400 randomly chosen estimated landmarks, the
       reference landmark with the most similar rotation-invariant descriptor (sorted
       distances to the ``k ≤ 4`` nearest neighbours), and ``iterations`` random hypotheses
       from two of them. Maps of at most 40 landmarks instead try every pair of estimated
       landmarks against every ordered pair of reference landmarks (at most 20,000 of them,
       sampled): tight clusters make descriptors ambiguous.
    2. Each hypothesis is the exact rigid transform of its two correspondences, kept when
       their separations agree within ``cutoff`` (and exceed it, so that the rotation is
       well defined); all are computed in one vectorised pass.
    3. MSAC score ``Σ_k min(d_k, c)²`` over (up to 256) estimated landmarks moved by each
       hypothesis, ``d_k`` the distance to the nearest reference landmark — unlike an inlier
       count it prefers the exact hypothesis among several with the same inliers.
    4. Refinement: the optimal assignment within ``cutoff`` and Umeyama on its pairs, repeated
       until the assignment no longer changes (at most 10 times).

    Parameters
    ----------
    est, ref : LandmarkMap
        At least 2 landmarks each.
    cutoff : float
        Largest distance [m] of a match after the alignment.
    iterations : int
        Number of RANSAC hypotheses.
    seed : int
        Seed of every random choice.

    Returns
    -------
    Association
        With ``alignment`` the rigid transform taking the estimate onto the reference.
    """
    e, r = est.xy, ref.xy
    if len(est) < 2 or len(ref) < 2:
        raise InputError("automatic association needs at least 2 landmarks in each map")
    if not (np.isfinite(cutoff) and cutoff > 0):
        raise InputError(f"the association cut-off must be a positive number, got {cutoff}")
    rng = np.random.default_rng(seed)
    tree = cKDTree(r)
    i1, j1, i2, j2 = _hypothesis_pairs(e, r, tree, cutoff, iterations, rng)
    if i1.size == 0:
        raise InputError("automatic association found no consistent pair of landmarks")
    # exact rigid transform of each hypothesis: rotation taking e2 - e1 onto r2 - r1
    ve, vr = e[i2] - e[i1], r[j2] - r[j1]
    ang = np.arctan2(ve[:, 0] * vr[:, 1] - ve[:, 1] * vr[:, 0], (ve * vr).sum(axis=1))
    cs, sn = np.cos(ang), np.sin(ang)
    me, mr = 0.5 * (e[i1] + e[i2]), 0.5 * (r[j1] + r[j2])
    tx = mr[:, 0] - (cs * me[:, 0] - sn * me[:, 1])
    ty = mr[:, 1] - (sn * me[:, 0] + cs * me[:, 1])
    sample = e if len(est) <= 256 else e[rng.choice(len(est), 256, replace=False)]
    mx = cs[:, None] * sample[None, :, 0] - sn[:, None] * sample[None, :, 1] + tx[:, None]
    my = sn[:, None] * sample[None, :, 0] + cs[:, None] * sample[None, :, 1] + ty[:, None]
    d, _ = tree.query(np.stack((mx, my), axis=-1).reshape(-1, 2), distance_upper_bound=cutoff)
    cost = (np.minimum(d, cutoff) ** 2).reshape(ang.size, -1).sum(axis=1)
    h = int(np.argmin(cost))
    al = Alignment(float(ang[h]), np.array([tx[h], ty[h]]), 1.0)
    for gate in (2.0 * cutoff, cutoff):
        er = rr = np.empty(0, np.int64)
        for _ in range(10):
            new_er, new_rr = _sparse_assignment(_apply(al, e), r, gate)
            if np.array_equal(new_er, er) and np.array_equal(new_rr, rr):
                break
            er, rr = new_er, new_rr
            if er.size >= 2:
                al = umeyama(e[er], r[rr])
    return _finish(est, ref, er, rr, al)


def _hypothesis_pairs(e, r, tree, cutoff, iterations, rng):  # type: ignore[no-untyped-def]
    """Index arrays ``(i1, j1, i2, j2)`` of two-correspondence hypotheses (see above)."""
    m, n = e.shape[0], r.shape[0]
    if m <= 40 and n <= 40:
        # every pair of estimated landmarks against every pair of reference landmarks
        a1, a2 = np.triu_indices(m, 1)
        b1, b2 = np.nonzero(~np.eye(n, dtype=bool))  # both orientations of a reference pair
        de = np.hypot(*(e[a2] - e[a1]).T)
        dr = np.hypot(*(r[b2] - r[b1]).T)
        ok = (np.abs(de[:, None] - dr[None, :]) < cutoff) & (de[:, None] > cutoff)
        pa, pb = np.nonzero(ok)
        if pa.size > _MAX_SMALL_HYPOTHESES:
            pick = np.sort(rng.choice(pa.size, _MAX_SMALL_HYPOTHESES, replace=False))
            pa, pb = pa[pick], pb[pick]
        return a1[pa], b1[pb], a2[pa], b2[pb]
    k = int(min(4, m - 1, n - 1))
    de_all, _ = cKDTree(e).query(e, k + 1)
    dr_all, _ = tree.query(r, k + 1)
    cand_i = rng.choice(m, size=min(m, 400), replace=False)
    top = int(min(3, n))  # the three most similar descriptors: clusters make them ambiguous
    _, cj = cKDTree(dr_all[:, 1:]).query(de_all[cand_i, 1:], top)
    cand_j = cj.reshape(cand_i.size, top)
    cand_i = np.repeat(cand_i, top)
    cand_j = cand_j.ravel()
    # draw 8x more pairs than needed and keep the longest baselines (a short one gives a
    # poorly defined rotation)
    a = rng.integers(0, cand_i.size, 8 * iterations)
    b = rng.integers(0, cand_i.size, 8 * iterations)
    i1, i2, j1, j2 = cand_i[a], cand_i[b], cand_j[a], cand_j[b]
    de = np.hypot(*(e[i2] - e[i1]).T)
    dr = np.hypot(*(r[j2] - r[j1]).T)
    ok = (i1 != i2) & (j1 != j2) & (np.abs(de - dr) < cutoff) & (de > cutoff)
    ok_idx = np.flatnonzero(ok)
    if ok_idx.size > iterations:
        ok_idx = np.sort(ok_idx[np.argsort(-de[ok_idx], kind="stable")[:iterations]])
    ok = np.zeros(de.shape, dtype=bool)
    ok[ok_idx] = True
    return i1[ok], j1[ok], i2[ok], j2[ok]


def _sparse_assignment(
    x: NDArray[np.float64], y: NDArray[np.float64], cutoff: float, *, power: float = 2.0
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Optimal assignment of ``x`` to ``y`` on distances below ``cutoff`` (sparse).

    Minimises ``Σ_matched d^p + c^p (#unmatched x + #unmatched y)`` over matchings whose pairs
    are closer than ``c``: the min-weight full matching of the square augmentation
    ``[[D^p, c^p I], [c^p I, (D^p)ᵀ-pattern at ~0]]`` (every candidate pair below the cut-off
    is an edge), solved by ``scipy.sparse.csgraph.min_weight_full_bipartite_matching``.
    ``p = 2`` (the default) is the least-squares objective of the Umeyama alignment, so that
    alternating the two never increases ``Σ min(d, c)²``.
    """
    er, rr, _ = _sparse_matching(
        x, y, cutoff, power=power, cost_x=cutoff**power, cost_y=cutoff**power
    )
    return er, rr


def _sparse_matching(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    cutoff: float,
    *,
    power: float,
    cost_x: float,
    cost_y: float,
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
    """Min-weight matching on the pairs closer than ``cutoff``: ``d^power`` per pair,
    ``cost_x`` per unmatched ``x``, ``cost_y`` per unmatched ``y``; the matched rows and
    their distances. The square augmentation ``[[D^p, cost_x I], [cost_y I, (D^p)ᵀ-pattern at
    ~0]]`` always has a full matching (the two identities); the pair weights get a tiny
    ``eps`` (and a zero cost is ``eps``) so that none is an implicit zero of the sparse
    matrix."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import min_weight_full_bipartite_matching

    m, n = x.shape[0], y.shape[0]
    d = cKDTree(x).sparse_distance_matrix(cKDTree(y), cutoff, output_type="coo_matrix")
    keep = d.data < cutoff
    i, j, dist = d.row[keep], d.col[keep], d.data[keep]
    w = dist**power
    eps = 1e-9 * max(cutoff**power, 1e-300)
    rows = np.concatenate((i, np.arange(m), m + np.arange(n), m + j))
    cols = np.concatenate((j, n + np.arange(m), np.arange(n), n + i))
    cx, cy = (cost if cost > 0 else eps for cost in (cost_x, cost_y))
    vals = np.concatenate((w + eps, np.full(m, cx), np.full(n, cy), np.full(i.size, eps)))
    g = sp.csr_matrix((vals, (rows, cols)), shape=(m + n, m + n))
    left, right = min_weight_full_bipartite_matching(g)
    real = (left < m) & (right < n)
    er, rr = left[real].astype(np.int64), right[real].astype(np.int64)
    return er, rr, np.hypot(*(x[er] - y[rr]).T)


def _apply(al: Alignment, xy: NDArray[np.float64]) -> NDArray[np.float64]:
    return al.apply(np.column_stack((xy, np.zeros(xy.shape[0]))))[:, :2]


def _optimal_terms(
    x: NDArray[np.float64], y: NDArray[np.float64], c: float, p: float
) -> tuple[NDArray[np.float64], int, int]:
    """``p · log(min(d, c)/c)`` of the pairs of the optimal assignment, and ``m ≤ n``.

    The distances are scaled by the cut-off, ``u = min(d, c)/c ∈ [0, 1]``: the assignment
    minimises ``Σ (u/u_max)^p`` (``u_max`` the largest ``u`` of the matrix; the order of the
    costs is that of ``Σ min(d, c)^p``, the factor ``(c u_max)^p`` is common), and the sums of
    OSPA/GOSPA are formed from the logarithms (:func:`_log_sum_exp`). So a large order ``p``
    does not underflow ``u^p`` to 0 and report two different maps as equal.
    """
    if not (np.isfinite(c) and c > 0):
        raise InputError(f"the OSPA/GOSPA cut-off c must be a positive number, got {c}")
    if not (np.isfinite(p) and p >= 1):
        raise InputError(f"the OSPA/GOSPA order p must be a number ≥ 1, got {p}")
    if x.shape[0] > y.shape[0]:
        x, y = y, x
    m, n = x.shape[0], y.shape[0]
    if m == 0:
        return np.empty(0), m, n
    if m * n > DENSE_ASSIGNMENT_PAIRS:
        # large sets: only pairs closer than c can cost less than c^p (_within_cutoff_terms)
        return _within_cutoff_terms(x, y, c, p), m, n
    d = np.hypot(x[:, None, 0] - y[None, :, 0], x[:, None, 1] - y[None, :, 1])
    u = np.minimum(d, c) / c
    top = float(u.max())
    if top == 0.0:
        return np.full(m, -np.inf), m, n
    r, s = linear_sum_assignment((u / top) ** p)
    with np.errstate(divide="ignore"):
        return p * np.log(u[r, s]), m, n


def _within_cutoff_terms(
    x: NDArray[np.float64], y: NDArray[np.float64], c: float, p: float
) -> NDArray[np.float64]:
    """The terms of :func:`_optimal_terms` (``|x| ≤ |y|``) from the pairs closer than ``c``.

    A full assignment's pairs at ``d ≥ c`` cost ``c^p`` each, as an unassigned ``x`` would;
    and a partial matching on pairs closer than ``c`` completes (``|x| ≤ |y|``) to a full
    assignment whose added pairs cost at most ``c^p`` each. So the optimum is the min-weight
    partial matching on the within-``c`` pairs with ``d^p`` per pair and ``c^p`` per
    unmatched ``x`` (an unmatched ``y`` costs nothing): a sparse problem of ``O(m + n +
    pairs)`` memory, solved as the full matching of the square augmentation of
    :func:`_sparse_assignment` by ``min_weight_full_bipartite_matching``. Each unmatched
    ``x`` gives the term 0 (``u = 1``).
    """
    # in units of c: the costs u^p ≤ 1 and 1 per unmatched x cannot overflow for any p
    er, rr, u = _sparse_matching(x / c, y / c, 1.0, power=p, cost_x=1.0, cost_y=0.0)
    with np.errstate(divide="ignore"):
        matched = p * np.log(np.minimum(u, 1.0))
    return np.concatenate((matched, np.zeros(x.shape[0] - er.size)))


def _log_sum_exp(terms: NDArray[np.float64]) -> float:
    """``log Σ exp(terms)`` without overflow or underflow (−inf for no or only −inf terms)."""
    if terms.size == 0:
        return -np.inf
    top = float(terms.max())
    if not np.isfinite(top):
        return top
    return top + float(np.log(np.exp(terms - top).sum()))


def ospa(x: ArrayLike, y: ArrayLike, *, c: float, p: float = 2.0) -> float:
    """OSPA distance of two point sets (see the module docstring).

    Computed as ``c · ((1/n) Σ u^p)^(1/p)`` with ``u = min(d, c)/c`` (1 for each unmatched
    point) in logarithms: exact for any order ``p``, no underflow to 0.
    """
    terms, m, n = _optimal_terms(
        np.asarray(x, float).reshape(-1, 2), np.asarray(y, float).reshape(-1, 2), c, p
    )
    if n == 0:
        return 0.0
    log_sum = _log_sum_exp(np.concatenate((terms, np.zeros(n - m))))
    return float(c * np.exp((log_sum - np.log(n)) / p))


def gospa(x: ArrayLike, y: ArrayLike, *, c: float, p: float = 2.0) -> float:
    """GOSPA distance with α = 2 (see the module docstring), in logarithms as :func:`ospa`."""
    terms, m, n = _optimal_terms(
        np.asarray(x, float).reshape(-1, 2), np.asarray(y, float).reshape(-1, 2), c, p
    )
    log_sum = _log_sum_exp(np.concatenate((terms, np.full(n - m, -np.log(2.0)))))
    return float(c * np.exp(log_sum / p))
