"""Landmark association between an estimated and a reference map.

Association modes: by id (optionally through an id map), from a user CSV
(``estimate,reference`` id pairs, overriding everything else), or automatic: a robust rigid
alignment (seeded RANSAC over pairs of points with matching distances, refined by Umeyama on
the inliers) followed by the optimal assignment on the aligned distances with a cut-off
(:func:`landmark_graph.matching.sparse_matching`, on the pairs within the cut-off).

OSPA and GOSPA, the distances of two maps over their own optimal assignment, are in
:mod:`landmark_graph.set_distances`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from landmark_graph.maps import LandmarkMap
from landmark_graph.matching import sparse_matching
from relation_metric.alignment import Alignment, umeyama
from relation_metric.errors import InputError

_MAX_SMALL_HYPOTHESES = 20_000

__all__ = [
    "Association",
    "associate_by_id",
    "associate_auto",
    "NoPairsFound",
]


class NoPairsFound(InputError):
    """An association that found no pair of landmarks (valid maps: a person can still pair
    them by hand, e.g. on the page of ``slamrel review``)."""


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
        raise NoPairsFound("automatic association needs at least 2 landmarks in each map")
    if not (np.isfinite(cutoff) and cutoff > 0):
        raise InputError(f"the association cut-off must be a positive number, got {cutoff}")
    rng = np.random.default_rng(seed)
    tree = cKDTree(r)
    i1, j1, i2, j2 = _hypothesis_pairs(e, r, tree, cutoff, iterations, rng)
    if i1.size == 0:
        raise NoPairsFound("automatic association found no consistent pair of landmarks")
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
    er, rr, _ = sparse_matching(
        x, y, cutoff, power=power, cost_x=cutoff**power, cost_y=cutoff**power
    )
    return er, rr


def _apply(al: Alignment, xy: NDArray[np.float64]) -> NDArray[np.float64]:
    return al.apply(np.column_stack((xy, np.zeros(xy.shape[0]))))[:, :2]
