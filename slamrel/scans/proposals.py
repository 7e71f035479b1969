"""Which scan pairs to align: consecutive by travel, loops by proximity, or given timestamps.

All three return :class:`Proposals`: scan index pairs ``(P, 2)`` (reference first), plus the
timestamps the relations will carry. Poses are ``(N, 3)`` laser poses ``[x, y, θ]`` of an
estimate (or the log's odometry) at the scans' times.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from relation_metric.errors import InputError
from relation_metric.se2 import between, inverse, wrap_angle_float
from slamrel.formats.laser import nearest_times

if TYPE_CHECKING:
    from slamrel.formats.laser import LaserScans
    from slamrel.scans.relations import ScanRelations

__all__ = [
    "Proposals",
    "SPACINGS",
    "LOOP_GROWTH_ANGLE",
    "keyframes",
    "consecutive_pairs",
    "loop_pairs",
    "pairs_at_times",
    "expected_overlap",
    "can_overlap",
    "drop_unseen_loops",
    "keep_overlapping",
    "OVERLAP_SPREAD_XY",
    "OVERLAP_SPREAD_THETA",
    "OVERLAP_TOLERANCE",
]


@dataclass(frozen=True)
class Proposals:
    """Scan pairs to align.

    Attributes
    ----------
    pairs : (P, 2) int
        ``[i, j]``: scan ``j`` is aligned to reference scan ``i``.
    t1, t2 : (P,) float
        The timestamps the relations carry (the scans' own, or the ones of a relation file).
    kind : (P,) str
        ``"consecutive"``, ``"loop"`` or ``"given"``.
    time_offset : (P,) float
        ``max(|t1 − t(scan i)|, |t2 − t(scan j)|)`` [s]: 0 unless times were given.
    """

    pairs: NDArray[np.int64]
    t1: NDArray[np.float64]
    t2: NDArray[np.float64]
    kind: NDArray[np.str_]
    time_offset: NDArray[np.float64]

    def __len__(self) -> int:
        return int(self.pairs.shape[0])

    def __add__(self, other: Proposals) -> Proposals:
        return Proposals(
            np.concatenate((self.pairs, other.pairs)).astype(np.int64),
            np.concatenate((self.t1, other.t1)),
            np.concatenate((self.t2, other.t2)),
            np.concatenate((self.kind, other.kind)),
            np.concatenate((self.time_offset, other.time_offset)),
        )


#: The rules :func:`keyframes` keeps scans by.
SPACINGS = ("motion", "travel")
#: Heading growth of loop candidates per unit of radius growth [rad/m per m/m]: the
#: global aligner's ratio of its windows' growth (0.0005 rad/m to 0.01 m/m).
LOOP_GROWTH_ANGLE = 0.05


def _proposals(pairs: NDArray[np.int64], times: NDArray[np.float64], kind: str) -> Proposals:
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    return Proposals(
        pairs,
        times[pairs[:, 0]],
        times[pairs[:, 1]],
        np.full(pairs.shape[0], kind),
        np.zeros(pairs.shape[0]),
    )


def keyframes(
    poses: NDArray[np.float64], distance: float, angle: float, *, spacing: str = "motion"
) -> NDArray[np.int64]:
    """Indices of scans a robot keeps when it moved ``distance`` [m] or turned ``angle`` [rad].

    The first scan is a keyframe. ``spacing``:

    * ``"motion"`` (default): scan ``k`` is the next one when the motion since the last
      keyframe, ``between(x_last, x_k)``, has a translation ``≥ distance`` or a rotation
      ``≥ angle``. Each keyframe overshoots ``distance`` by part of a step, and the overshoot
      adds up: on a drive of 0.1 m steps the keyframes of noisy odometry lie 5 or 6 steps
      apart, those of exact 0.1 m steps 5 apart — 7 % fewer keyframes and 15 % fewer loop
      pairs from the same drive (corridor world 107, 418 against 449).
    * ``"travel"``: scan ``k`` is the next one when the path length of ``poses`` (the sum
      of their steps' translations) passed a multiple of ``distance`` since the last
      keyframe, or the rotation since it reached ``angle``. The overshoot does not add up:
      the keyframes lie ``distance`` apart on average along the path whatever the poses'
      noise, so poses that drift propose as many pairs as the true ones (455 and 455).

    (Sequential by nature: each choice depends on the previous one.)
    """
    if spacing not in SPACINGS:
        raise ValueError(f"spacing must be one of {SPACINGS}, not {spacing!r}")
    n = poses.shape[0]
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    if spacing == "travel":
        return _keyframes_by_travel(poses, distance, angle)
    keep = [0]
    last = poses[0]
    rel = between(poses[0], poses)
    for k in range(1, n):
        d = rel[k]
        if np.hypot(d[0], d[1]) >= distance or abs(d[2]) >= angle:
            keep.append(k)
            last = poses[k]
            rel = between(last, poses)
    return np.asarray(keep, dtype=np.int64)


def _keyframes_by_travel(
    poses: NDArray[np.float64], distance: float, angle: float
) -> NDArray[np.int64]:
    """:func:`keyframes` with ``spacing="travel"``."""
    step = between(poses[:-1], poses[1:])
    travel = np.concatenate(([0.0], np.cumsum(np.hypot(step[:, 0], step[:, 1]))))
    mark = np.floor(travel / distance) if distance > 0 else np.arange(poses.shape[0])
    theta = poses[:, 2]
    keep = [0]
    last = 0
    for k in range(1, poses.shape[0]):
        turn = abs(wrap_angle_float(float(theta[k] - theta[last])))
        if mark[k] > mark[last] or turn >= angle:
            keep.append(k)
            last = k
    return np.asarray(keep, dtype=np.int64)


def consecutive_pairs(
    poses: NDArray[np.float64],
    times: NDArray[np.float64],
    *,
    distance: float,
    angle: float,
    spacing: str = "motion",
) -> Proposals:
    """Pairs of consecutive keyframes (:func:`keyframes`)."""
    key = keyframes(poses, distance, angle, spacing=spacing)
    return _proposals(np.column_stack((key[:-1], key[1:])), times, "consecutive")


def loop_pairs(
    poses: NDArray[np.float64],
    times: NDArray[np.float64],
    *,
    radius: float,
    min_travel: float,
    distance: float,
    angle: float,
    max_angle: float = np.pi,
    spacing: str = "motion",
    growth: float = 0.0,
    growth_angle: float = 0.0,
) -> Proposals:
    """Keyframe pairs that are near in space but far apart along the path.

    Keyframes (:func:`keyframes` by ``spacing``) whose positions lie within ``radius`` [m] of
    each other, whose headings differ by at most ``max_angle`` [rad] (a laser with a limited
    field of view sees little of the same scene from opposite directions), and between which
    the estimate travelled at least ``min_travel`` [m].

    ``growth`` [m/m] and ``growth_angle`` [rad/m] widen both limits by the travel ``D``
    between the two keyframes — ``radius + growth·D``, ``max_angle + growth_angle·D`` — the
    poses' accumulated uncertainty: a drifting odometry places a place it revisits the
    farther off the longer it drove in between. Such pairs are *candidates*: once aligned,
    :func:`within_reach` keeps those whose aligned motion meets ``radius`` and
    ``max_angle``, so the pairs kept are the ones the true poses would propose. (The search
    first gathers every keyframe pair within the widest reach, ``radius + growth`` × the
    whole travel: its work grows with the drive's length; keep ``growth`` small on long
    drives.)
    """
    from scipy.spatial import cKDTree  # here: ``relations align --at`` never needs it

    key = keyframes(poses, distance, angle, spacing=spacing)
    p = poses[key]
    travel = _travel(poses)
    reach = radius + growth * float(travel[key[-1]] - travel[key[0]]) if key.size else radius
    pairs = np.array(sorted(cKDTree(p[:, :2]).query_pairs(reach)), dtype=np.int64).reshape(-1, 2)
    if pairs.shape[0]:
        i, j = key[pairs[:, 0]], key[pairs[:, 1]]
        rel = between(poses[i], poses[j])
        apart = np.abs(travel[j] - travel[i])
        ok = (apart >= min_travel) & (np.abs(rel[:, 2]) <= max_angle + growth_angle * apart)
        if growth > 0:  # the tree's query holds the widest reach
            ok &= np.hypot(rel[:, 0], rel[:, 1]) <= radius + growth * apart
        pairs = np.column_stack((i[ok], j[ok]))
    return _proposals(pairs, times, "loop")


def within_reach(
    proposals: Proposals,
    delta: NDArray[np.float64],
    *,
    radius: float,
    max_angle: float = np.pi,
) -> NDArray[np.bool_]:
    """Which aligned pairs ``(P,)`` to keep: every pair that is not a loop pair, and the
    loop pairs whose aligned motion ``delta`` ``(P, 3)`` (scan ``j`` in scan ``i``'s frame)
    lies within ``radius`` [m] and ``max_angle`` [rad] — the loop rule of
    :func:`loop_pairs` applied to what the scans say rather than to the guesses."""
    delta = np.asarray(delta, dtype=np.float64).reshape(-1, 3)
    near = (np.hypot(delta[:, 0], delta[:, 1]) <= radius) & (np.abs(delta[:, 2]) <= max_angle)
    return (proposals.kind != "loop") | near


def pairs_at_times(
    scan_times: NDArray[np.float64],
    t1: NDArray[np.float64],
    t2: NDArray[np.float64],
    *,
    tolerance: float,
    path: str | None = None,
) -> Proposals:
    """The scans nearest to each timestamp pair of a relation file.

    A timestamp farther than ``tolerance`` [s] from every scan is an error (naming the first
    such relation): a relation between scans the log does not hold cannot be re-derived.
    """
    i, di = nearest_times(scan_times, t1)
    j, dj = nearest_times(scan_times, t2)
    off = np.maximum(di, dj)
    far = np.flatnonzero(off > tolerance)
    if far.size:
        k = int(far[0])
        raise InputError(
            f"{far.size} relation(s) name times with no scan within {tolerance} s; the first, "
            f"relation {k + 1} ({float(t1[k])!r} {float(t2[k])!r}), is {off[k]:.3g} s from "
            "the nearest scan",
            path=path,
        )
    return Proposals(
        np.column_stack((i, j)).astype(np.int64),
        np.asarray(t1, dtype=np.float64),
        np.asarray(t2, dtype=np.float64),
        np.full(i.shape[0], "given"),
        off,
    )


def keep_within_reach(
    result: ScanRelations, *, radius: float, max_angle: float = np.pi
) -> ScanRelations:
    """``result`` without the loop relations whose aligned motion lies beyond ``radius`` [m]
    or ``max_angle`` [rad] (:func:`within_reach`): what is left of candidates proposed with
    :func:`loop_pairs`' ``growth``."""
    keep = within_reach(result.proposals, result.delta, radius=radius, max_angle=max_angle)
    return _select(result, keep)


#: The guesses' uncertainty at zero travel for :func:`drop_unseen_loops` [m, rad]: the global
#: aligner's window at ``D = 0`` (``0.3 m``, ``0.05 rad``); it grows by the loop growth.
OVERLAP_SPREAD_XY = 0.3
OVERLAP_SPREAD_THETA = 0.05
#: A return counts as seen by the other scan unless that scan's reading along its bearing
#: ends more than this [m] in front of it (a wall between them).
OVERLAP_TOLERANCE = 0.1
#: Pairs per block in :func:`expected_overlap` (bounds its temporary arrays).
_OVERLAP_BLOCK = 1024
#: Cells of :func:`can_overlap`'s search over the uncertainty: 0.5 m, 0.1 rad.
_OVERLAP_CELL = 0.5
_OVERLAP_CELL_THETA = 0.1


@dataclass(frozen=True)
class _Returns:
    """The scans of some pairs as arrays ``(U, B)`` (``U`` distinct scans): returns in the
    laser frame, their ranges, the readings that can hide a point (no return: ``+inf``), a
    max-table of those readings for ranges of beams, and each scan's field of view."""

    points: NDArray[np.float64]  # (U, B, 2), NaN where no return
    norm: NDArray[np.float64]  # (U, B)
    valid: NDArray[np.bool_]  # (U, B)
    table: NDArray[np.float32]  # (L, U, B): max of readings over 2**l beams from each
    centre: NDArray[np.float64]  # (U,) bearing of the middle of the field of view
    half: NDArray[np.float64]  # (U,) half the field of view, half a beam included
    start: NDArray[np.float64]  # (U,)
    resolution: NDArray[np.float64]  # (U,)
    beams: NDArray[np.int64]  # (U,)
    top: NDArray[np.float64]  # (U,) largest range read


def _returns(
    scans: LaserScans, which: NDArray[np.int64], max_range: float | None, min_range: float
) -> _Returns:
    """:class:`_Returns` of scans ``which`` (the rule of :meth:`LaserScans.points`)."""
    r = scans.ranges[which]
    n = scans.beams[which]
    k = np.arange(r.shape[1])
    res = scans.angular_resolution[which]
    start = scans.start_angle[which]
    top = (
        scans.max_range[which]
        if max_range is None
        else np.minimum(max_range, scans.max_range[which])
    )
    low = np.full(which.shape, min_range)
    if scans.min_range is not None:
        low = np.maximum(low, scans.min_range[which])
    a = start[:, None] + k * res[:, None]
    with np.errstate(invalid="ignore"):
        valid = (k < n[:, None]) & (r > low[:, None]) & (r < top[:, None])
    rr = np.where(valid, r, np.nan)
    pts = np.stack((rr * np.cos(a), rr * np.sin(a)), axis=-1)
    seen = np.where(valid, r, np.inf).astype(np.float32)  # no return: hides nothing
    levels = [seen]
    width = 1
    while 2 * width <= r.shape[1]:
        prev = levels[-1]
        nxt = np.full_like(prev, np.inf)
        nxt[:, : r.shape[1] - width] = np.maximum(prev[:, : r.shape[1] - width], prev[:, width:])
        levels.append(nxt)
        width *= 2
    half_span = (n - 1) * res / 2
    return _Returns(
        pts,
        np.where(valid, rr, 0.0),
        valid,
        np.stack(levels),
        start + half_span,
        half_span + res / 2,
        start,
        res,
        n.astype(np.int64),
        top,
    )


def _seen_share(
    ret: _Returns,
    a: NDArray[np.int64],
    b: NDArray[np.int64],
    delta: NDArray[np.float64],
    spread_xy: NDArray[np.float64],
    spread_theta: NDArray[np.float64],
    tolerance: float,
) -> NDArray[np.float64]:
    """Share of scan ``b``'s returns (rows of ``ret``) that scan ``a`` could see, ``(P,)``.

    ``delta`` ``(P, 3)``: ``b``'s pose in ``a``'s frame, known within ``spread_xy`` [m] in
    translation and ``spread_theta`` [rad] in rotation. A return ``p`` of ``b`` lies at
    ``q = t + R(θ) p`` in ``a``'s frame by the guess and, for any pose within the spread,
    within ``e = spread_xy + |p|·spread_theta`` of ``q``. It counts when some point of that
    disc is inside ``a``'s range, inside its field of view, and not hidden: some reading
    of ``a`` on the beams bracketing the bearings the disc covers ends no more than
    ``tolerance`` in front of it.
    """
    pts = ret.points[b]  # (P, B, 2)
    c, s = np.cos(delta[:, 2])[:, None], np.sin(delta[:, 2])[:, None]
    qx = delta[:, 0, None] + c * pts[..., 0] - s * pts[..., 1]
    qy = delta[:, 1, None] + s * pts[..., 0] + c * pts[..., 1]
    valid = ret.valid[b]
    r = np.where(valid, np.hypot(qx, qy), 0.0)
    e = spread_xy[:, None] + ret.norm[b] * spread_theta[:, None]
    near = r <= e
    w = np.arcsin(np.minimum(1.0, e / np.where(near, 1.0, r)))
    w[near] = np.pi
    centre, half = ret.centre[a][:, None], ret.half[a][:, None]
    phi = np.where(valid, np.arctan2(qy, qx), 0.0) - centre
    phi = (phi + np.pi) % (2 * np.pi) - np.pi
    wraps = half + w >= np.pi  # the disc's bearings may reach round the back
    inside = wraps | (np.abs(phi) - w <= half)
    res, start = ret.resolution[a][:, None], ret.start[a][:, None]
    n = ret.beams[a][:, None]
    # the beams from the one before the bearings phi ± w to the one after: a surface seen
    # at grazing incidence between two beams is not called hidden by the nearer one
    lo = np.clip(np.floor((centre + phi - w - start) / res), 0, n - 1).astype(np.int64)
    hi = np.clip(np.ceil((centre + phi + w - start) / res), 0, n - 1).astype(np.int64)
    hi = np.maximum(hi, lo)
    lev = np.floor(np.log2(hi - lo + 1)).astype(np.int64)
    rows = a[:, None]
    far = np.maximum(ret.table[lev, rows, lo], ret.table[lev, rows, hi - (1 << lev) + 1])
    open_ = wraps | (far >= r - e - tolerance)
    seen = valid & (r - e < ret.top[a][:, None]) & (near | (inside & open_))
    count = valid.sum(axis=1)
    return np.where(count > 0, seen.sum(axis=1) / np.maximum(count, 1), 0.0)


def expected_overlap(
    scans: LaserScans,
    pairs: NDArray[np.int64],
    delta: NDArray[np.float64],
    *,
    spread_xy: NDArray[np.float64] | float,
    spread_theta: NDArray[np.float64] | float,
    max_range: float | None = None,
    min_range: float = 0.05,
    tolerance: float = OVERLAP_TOLERANCE,
) -> NDArray[np.float64]:
    """The most two scans can overlap, ``(P,)`` in [0, 1], given their relative pose within
    an uncertainty.

    ``pairs`` ``(P, 2)`` ``[i, j]``, ``delta`` ``(P, 3)`` the guessed pose of scan ``j`` in
    scan ``i``'s frame, true within ``spread_xy`` [m] (any translation error of at most that
    length) and ``spread_theta`` [rad] (scalars or ``(P,)``). For each direction, the share
    of one scan's returns (readings in ``(min_range, max_range)``, as
    :meth:`LaserScans.points`) that the other scan could see: inside its range, its field
    of view, and not behind one of its own returns by more than ``tolerance`` [m] (a wall
    in between), where each return may lie anywhere the uncertainty can move it (see
    :func:`_seen_share`). The larger of the two shares.

    Each return is allowed its own pose within the uncertainty, so this is an upper bound
    of the overlap at any one pose within it: a pair is never judged by a guess that is
    off by less than the uncertainty. Returns a scan does not hold count for nothing; a scan
    with no return overlaps nothing (0).
    """
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    delta = np.asarray(delta, dtype=np.float64).reshape(-1, 3)
    n = pairs.shape[0]
    sxy = np.broadcast_to(np.asarray(spread_xy, dtype=np.float64), (n,))
    sth = np.broadcast_to(np.asarray(spread_theta, dtype=np.float64), (n,))
    out = np.zeros(n)
    if n == 0:
        return out
    which, local = np.unique(pairs, return_inverse=True)
    ret = _returns(scans, which, max_range, min_range)
    return _overlap(ret, local.reshape(-1, 2), delta, sxy, sth, tolerance)


def _overlap(
    ret: _Returns,
    local: NDArray[np.int64],
    delta: NDArray[np.float64],
    sxy: NDArray[np.float64],
    sth: NDArray[np.float64],
    tolerance: float,
) -> NDArray[np.float64]:
    """:func:`expected_overlap` of pairs ``local`` ``(P, 2)`` (rows of ``ret``)."""
    n = local.shape[0]
    out = np.zeros(n)
    back = inverse(delta)  # scan i's pose in j's frame: its translation's error also
    sxy_back = sxy + np.hypot(delta[:, 0], delta[:, 1]) * sth  # turns with the rotation's
    for s0 in range(0, n, _OVERLAP_BLOCK):  # blocks bound the (P, B) temporaries
        sl = slice(s0, s0 + _OVERLAP_BLOCK)
        i, j = local[sl, 0], local[sl, 1]
        with np.errstate(invalid="ignore", divide="ignore"):
            ij = _seen_share(ret, i, j, delta[sl], sxy[sl], sth[sl], tolerance)
            ji = _seen_share(ret, j, i, back[sl], sxy_back[sl], sth[sl], tolerance)
        out[sl] = np.maximum(ij, ji)
    return out


def _travel(poses: NDArray[np.float64]) -> NDArray[np.float64]:
    """Path length of ``poses`` ``(N, 3)`` up to each pose ``(N,)`` [m]."""
    return np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(poses[:, :2], axis=0).T))))


def can_overlap(
    scans: LaserScans,
    pairs: NDArray[np.int64],
    delta: NDArray[np.float64],
    *,
    spread_xy: NDArray[np.float64] | float,
    spread_theta: NDArray[np.float64] | float,
    min_overlap: float,
    radius: float | None = None,
    max_range: float | None = None,
    min_range: float = 0.05,
    tolerance: float = OVERLAP_TOLERANCE,
) -> NDArray[np.bool_]:
    """Whether the two scans of each pair can overlap by ``min_overlap`` at some relative
    pose within the guess's uncertainty, ``(P,)``.

    The poses ``(t + d, θ + dθ)`` with ``|d| ≤ spread_xy`` and ``|dθ| ≤ spread_theta``
    around the guess ``delta = (t, θ)`` (and, with ``radius``, ``|t + d| ≤ radius``: a
    loop pair kept only where its aligned motion lies within the loop radius) are cut into
    cells of 0.5 m × 0.5 m × 0.1 rad (larger when it is wider than 4 m or 0.4 rad: at most
    17 × 17 × 9 cells); each cell's :func:`expected_overlap` (its centre,
    spread by the cell's half size) bounds the overlap anywhere in it, so a pair is judged
    ``False`` only when no pose within the uncertainty gives ``min_overlap``. Cells are
    tried nearest to the guess first and a pair stops at the first that reaches it.
    """
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    delta = np.asarray(delta, dtype=np.float64).reshape(-1, 3)
    n = pairs.shape[0]
    sxy = np.broadcast_to(np.asarray(spread_xy, dtype=np.float64), (n,))
    sth = np.broadcast_to(np.asarray(spread_theta, dtype=np.float64), (n,))
    if n == 0:
        return np.zeros(0, dtype=bool)
    which, local = np.unique(pairs, return_inverse=True)
    local = local.reshape(-1, 2)
    ret = _returns(scans, which, max_range, min_range)
    # translation cells: around the guess, or around 0 when the radius is the tighter bound
    capped = np.zeros(n, dtype=bool) if radius is None else radius < sxy
    centre = np.where(capped[:, None], 0.0, delta[:, :2])
    reach = np.where(capped, 0.0 if radius is None else radius, sxy)
    # cells of 0.5 m × 0.1 rad, larger where the uncertainty is wide (at most 17 × 17 × 9
    # cells: each still bounds the overlap within it, only more loosely)
    cell = max(_OVERLAP_CELL, float(reach.max()) / 8)
    cell_t = max(_OVERLAP_CELL_THETA, float(sth.max()) / 4)
    half, half_t = cell / np.sqrt(2.0), cell_t / 2
    spread, spread_t = np.full(n, half), np.full(n, half_t)
    k = int(np.ceil(float(reach.max()) / cell))
    g = np.arange(-k, k + 1) * cell
    grid = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    xy = centre[:, None, :] + grid[None]  # (P, S, 2)
    ok = np.hypot(grid[:, 0], grid[:, 1])[None] <= reach[:, None] + half
    if radius is not None:
        ok &= np.hypot(xy[..., 0], xy[..., 1]) <= radius + half
    ok &= np.hypot(*(xy - delta[:, None, :2]).transpose(2, 0, 1)) <= sxy[:, None] + half
    m = int(np.ceil(float(sth.max()) / cell_t))
    turns = np.arange(-m, m + 1) * cell_t
    ok_t = np.abs(turns)[None] - half_t <= sth[:, None]  # the cells that meet ±spread_theta
    # every (translation, rotation) cell, nearest to the guess first
    dist = np.hypot(*(xy - delta[:, None, :2]).transpose(2, 0, 1))  # (P, S)
    order_t = np.argsort(np.abs(turns), kind="stable")
    found = np.zeros(n, dtype=bool)
    tried = np.zeros(n, dtype=bool)
    order_xy = np.argsort(dist, axis=1, kind="stable")
    rows = np.arange(n)
    for c in range(grid.shape[0]):
        s_idx = order_xy[:, c]
        for tt in order_t:
            use = ~found & ok[rows, s_idx] & ok_t[:, tt]
            if not use.any():
                continue
            idx = np.flatnonzero(use)
            pose = np.column_stack(
                (xy[idx, s_idx[idx], 0], xy[idx, s_idx[idx], 1], delta[idx, 2] + turns[tt])
            )
            ov = _overlap(ret, local[idx], pose, spread[idx], spread_t[idx], tolerance)
            tried[idx] = True
            found[idx[ov >= min_overlap]] = True
        if found.all():
            break
    if not tried.all():  # no cell within the bounds (a guess far outside the radius)
        idx = np.flatnonzero(~tried)
        ov = _overlap(ret, local[idx], delta[idx], sxy[idx], sth[idx], tolerance)
        found[idx] = ov >= min_overlap
    return found


def drop_unseen_loops(
    proposals: Proposals,
    scans: LaserScans,
    poses: NDArray[np.float64],
    *,
    min_overlap: float,
    growth: float = 0.0,
    growth_angle: float = 0.0,
    radius: float | None = None,
    max_range: float | None = None,
) -> tuple[Proposals, int]:
    """``proposals`` without the loop pairs whose scans cannot overlap by ``min_overlap``
    (:func:`can_overlap`), and how many were left out.

    The guess of a pair is ``between(poses[i], poses[j])``, known within
    ``OVERLAP_SPREAD_XY + growth·D`` [m] and ``OVERLAP_SPREAD_THETA + growth_angle·D``
    [rad], ``D`` the travel between the two scans by ``poses`` (the drift
    :func:`loop_pairs`' candidates allow); ``radius`` (give it when the loop relations are
    kept by their aligned motion, :func:`keep_within_reach`) bounds the translation.
    Consecutive and given pairs are never left out (the chain stays connected).
    """
    loop = np.flatnonzero(proposals.kind == "loop")
    if min_overlap <= 0 or loop.size == 0:
        return proposals, 0
    p = proposals.pairs[loop]
    travel = _travel(poses)
    d = np.abs(travel[p[:, 1]] - travel[p[:, 0]])
    ok = can_overlap(
        scans,
        p,
        between(poses[p[:, 0]], poses[p[:, 1]]),
        spread_xy=OVERLAP_SPREAD_XY + growth * d,
        spread_theta=OVERLAP_SPREAD_THETA + growth_angle * d,
        min_overlap=min_overlap,
        radius=radius,
        max_range=max_range,
    )
    keep = np.ones(len(proposals), dtype=bool)
    keep[loop[~ok]] = False
    return _subset(proposals, keep), int((~ok).sum())


def _subset(proposals: Proposals, keep: NDArray[np.bool_]) -> Proposals:
    return Proposals(*(getattr(proposals, f.name)[keep] for f in fields(proposals)))


def keep_overlapping(
    result: ScanRelations,
    scans: LaserScans,
    *,
    min_overlap: float,
    max_range: float | None = None,
) -> tuple[ScanRelations, int]:
    """``result`` without the loop relations whose two scans, placed by the aligned motion,
    overlap by less than ``min_overlap`` (:func:`expected_overlap` at ``result.delta``, no
    uncertainty), and how many were left out: the rule of :func:`drop_unseen_loops`
    applied to what the scans say. Other relations are kept."""
    loop = np.flatnonzero(result.proposals.kind == "loop")
    if min_overlap <= 0 or loop.size == 0:
        return result, 0
    ov = expected_overlap(
        scans,
        result.proposals.pairs[loop],
        result.delta[loop],
        spread_xy=0.0,
        spread_theta=0.0,
        max_range=max_range,
    )
    keep = np.ones(len(result), dtype=bool)
    keep[loop[~(ov >= min_overlap)]] = False
    return _select(result, keep), int(loop.size - (ov >= min_overlap).sum())


def _select(result: ScanRelations, keep: NDArray[np.bool_]) -> ScanRelations:
    """The relations ``keep`` of ``result``."""
    arrays = {
        f.name: getattr(result, f.name)[keep]
        for f in fields(result)
        if f.name != "proposals" and getattr(result, f.name) is not None
    }
    return replace(result, proposals=_subset(result.proposals, keep), **arrays)
