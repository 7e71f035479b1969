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
from relation_metric.textio import PathLike, read_source

__all__ = [
    "Association",
    "associate_by_id",
    "associate_auto",
    "read_association_csv",
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


def read_association_csv(path: PathLike, est: LandmarkMap, ref: LandmarkMap) -> Association:
    """``estimate,reference`` id pairs (header line required); unknown ids are errors."""
    src = read_source(path)
    rows = list(src.data_lines())
    if not rows or [h.strip().lower() for h in rows[0][1].split(",")] != ["estimate", "reference"]:
        raise InputError(
            "expected the header 'estimate,reference'",
            path=src.path,
            line=rows[0][0] if rows else None,
        )
    e_pos = {int(i): k for k, i in enumerate(est.ids.tolist())}
    r_pos = {int(i): k for k, i in enumerate(ref.ids.tolist())}
    er, rr = [], []
    for number, text in rows[1:]:
        f = [v.strip() for v in text.split(",")]
        if len(f) != 2:
            raise InputError(f"expected 2 fields, got {len(f)}", path=src.path, line=number)
        try:
            a, b = int(f[0]), int(f[1])
        except ValueError:
            raise InputError(
                f"expected two integer ids, got {text!r}", path=src.path, line=number
            ) from None
        if a not in e_pos:
            raise InputError(f"unknown estimated landmark id {a}", path=src.path, line=number)
        if b not in r_pos:
            raise InputError(f"unknown reference landmark id {b}", path=src.path, line=number)
        if e_pos[a] in er or r_pos[b] in rr:
            raise InputError(f"landmark {a} or {b} is associated twice", path=src.path, line=number)
        er.append(e_pos[a])
        rr.append(r_pos[b])
    return _finish(est, ref, er, rr)


def associate_auto(
    est: LandmarkMap, ref: LandmarkMap, *, cutoff: float = 1.0, iterations: int = 500, seed: int = 0
) -> Association:
    """Robust rigid alignment (seeded RANSAC) then the optimal assignment within ``cutoff``."""
    e, r = est.xy, ref.xy
    if len(est) < 2 or len(ref) < 2:
        raise InputError("automatic association needs at least 2 landmarks in each map")
    rng = np.random.default_rng(seed)
    tree = cKDTree(r)
    best, best_al = -1, None
    i = rng.integers(0, len(est), (iterations, 2))
    j = rng.integers(0, len(ref), (iterations, 2))
    de = np.hypot(*(e[i[:, 1]] - e[i[:, 0]]).T)
    dr = np.hypot(*(r[j[:, 1]] - r[j[:, 0]]).T)
    ok = (i[:, 0] != i[:, 1]) & (j[:, 0] != j[:, 1]) & (np.abs(de - dr) < cutoff)
    for k in np.flatnonzero(ok):
        al = umeyama(e[i[k]], r[j[k]])
        moved = _apply(al, e)
        score = int(np.sum(tree.query(moved, distance_upper_bound=cutoff)[0] < cutoff))
        if score > best:
            best, best_al = score, al
    if best_al is None:
        best_al = (
            umeyama(e[: min(len(e), len(r))], r[: min(len(e), len(r))])
            if len(e) == len(r)
            else None
        )
        if best_al is None:
            raise InputError("automatic association found no consistent pair of landmarks")
    # refine on the inliers, then assign optimally
    for _ in range(3):
        moved = _apply(best_al, e)
        dist, nn = tree.query(moved, distance_upper_bound=cutoff)
        inl = dist < cutoff
        if inl.sum() >= 2:
            best_al = umeyama(e[inl], r[nn[inl]])
    moved = _apply(best_al, e)
    d = np.hypot(moved[:, None, 0] - r[None, :, 0], moved[:, None, 1] - r[None, :, 1])
    cost = np.where(d < cutoff, d, 1e6)
    er, rr = linear_sum_assignment(cost)
    good = cost[er, rr] < cutoff
    return _finish(est, ref, er[good], rr[good], best_al)


def _apply(al: Alignment, xy: NDArray[np.float64]) -> NDArray[np.float64]:
    return al.apply(np.column_stack((xy, np.zeros(xy.shape[0]))))[:, :2]


def _optimal_cost(
    x: NDArray[np.float64], y: NDArray[np.float64], c: float, p: float
) -> tuple[float, int, int]:
    """``min_π Σ min(d, c)^p`` with ``|x| = m ≤ n = |y|``, and ``m``, ``n``."""
    if x.shape[0] > y.shape[0]:
        x, y = y, x
    m, n = x.shape[0], y.shape[0]
    if m == 0:
        return 0.0, m, n
    d = np.hypot(x[:, None, 0] - y[None, :, 0], x[:, None, 1] - y[None, :, 1])
    w = np.minimum(d, c) ** p
    r, s = linear_sum_assignment(w)
    return float(w[r, s].sum()), m, n


def ospa(x: ArrayLike, y: ArrayLike, *, c: float, p: float = 2.0) -> float:
    """OSPA distance of two point sets (see the module docstring)."""
    total, m, n = _optimal_cost(
        np.asarray(x, float).reshape(-1, 2), np.asarray(y, float).reshape(-1, 2), c, p
    )
    if n == 0:
        return 0.0
    return float(((total + c**p * (n - m)) / n) ** (1.0 / p))


def gospa(x: ArrayLike, y: ArrayLike, *, c: float, p: float = 2.0) -> float:
    """GOSPA distance with α = 2 (see the module docstring)."""
    total, m, n = _optimal_cost(
        np.asarray(x, float).reshape(-1, 2), np.asarray(y, float).reshape(-1, 2), c, p
    )
    return float((total + c**p / 2.0 * (n - m)) ** (1.0 / p))
