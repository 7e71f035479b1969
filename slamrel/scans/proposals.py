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
from relation_metric.se2 import between, wrap_angle_float
from slamrel.formats.laser import nearest_times

if TYPE_CHECKING:
    from slamrel.scans.relations import ScanRelations

__all__ = [
    "Proposals",
    "SPACINGS",
    "LOOP_GROWTH_ANGLE",
    "keyframes",
    "consecutive_pairs",
    "loop_pairs",
    "pairs_at_times",
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
    travel = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(poses[:, :2], axis=0).T))))
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
    prop = result.proposals
    sub = Proposals(*(getattr(prop, f.name)[keep] for f in fields(prop)))
    arrays = {
        f.name: getattr(result, f.name)[keep]
        for f in fields(result)
        if f.name != "proposals" and getattr(result, f.name) is not None
    }
    return replace(result, proposals=sub, **arrays)
