"""Association of relation endpoints (timestamps or indices) with estimate poses.

For a timestamp ``t`` the estimate pose is found as the Freiburg metricEvaluator does:

1. the estimate pose nearest in time, ``x_k`` with ``k = argmin |t_k − t|``; accepted when
   ``|t_k − t| ≤ max_time_diff`` (default 0.1 s);
2. otherwise, with ``interpolate=True``, the interpolation on the estimate's group (SE(2) or
   SE(3), :mod:`relation_metric.groups`) between the two estimate
   poses around ``t``, ``x_a ∘ exp(s · log(x_a⁻¹ ∘ x_b))`` with ``s = (t − t_a)/(t_b − t_a)``,
   when ``t_b − t_a ≤ max_interpolation_gap``;
3. otherwise, when an odometry log is given, the nearest estimate pose corrected by the
   odometry motion between the two odometry samples nearest to ``t_k`` and to ``t``:
   ``x_k ∘ (o(t_k)⁻¹ ∘ o(t))``;
4. otherwise the endpoint is unassociated, and so is its relation: it is counted, named
   and left out of the statistics — never silently dropped.

A relation whose two (different) times both find the *same* estimate pose (an estimate at
half the reference rate: both ends of a 0.1 s relation nearest to one pose) would be scored
as zero motion. Such relations are counted (``Association.same_pose``): with
``interpolate=True`` both ends are interpolated on the estimate's group (when the poses around
each lie within ``max_interpolation_gap``); otherwise, or when they cannot be, the relation
is unassociated with the reason ``SAME_POSE``. With ``same_pose="zero_motion"`` they are kept
as they are, zero estimated motion, as the C++ metricEvaluator scores them (the
``metricevaluator`` mode of :func:`relation_metric.evaluate.evaluate`), and still counted.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from relation_metric.errors import InputError
from relation_metric.groups import group_of
from relation_metric.relations import RelationSet
from relation_metric.trajectory import Trajectory

__all__ = [
    "Association",
    "associate",
    "nearest_index",
    "REASONS",
    "match_nearest_times",
    "synchronize",
]

# Why an endpoint could not be associated (codes of Association.reason).
OK, OUTSIDE_SPAN, TOO_FAR, BAD_INDEX, SAME_POSE = 0, 1, 2, 3, 4
# What is done with a relation whose two different times find one estimate pose.
SamePoseRule = Literal["separate", "zero_motion"]
SAME_POSE_RULES: tuple[SamePoseRule, ...] = ("separate", "zero_motion")
REASONS = {
    OK: "associated",
    OUTSIDE_SPAN: "outside the estimate's time span",
    TOO_FAR: "no estimate pose within the time tolerance",
    BAD_INDEX: "pose index out of range",
    SAME_POSE: "both ends at one estimate pose (the estimate is sparser than the relations)",
}


@dataclass(frozen=True)
class Association:
    """Estimate poses for both ends of M relations.

    Attributes
    ----------
    pose_first, pose_second : ndarray, shape (M, 3) or (M, 7)
        Estimate poses, on the estimate's group (NaN where unassociated).
    index_first, index_second : ndarray of int64, shape (M,)
        Nearest estimate pose of each end (−1 where there is none).
    valid : ndarray of bool, shape (M,)
        Both ends associated.
    via_odometry : ndarray of bool, shape (M,)
        At least one end was corrected with odometry.
    interpolated : ndarray of bool, shape (M,)
        At least one end was interpolated.
    reason : ndarray of int8, shape (M,)
        0 when valid, otherwise a key of :data:`REASONS` (the first failing end's).
    same_pose : ndarray of bool, shape (M,), optional
        Relations whose two different times found one nearest estimate pose: interpolated
        (``interpolated``), unassociated (reason ``SAME_POSE``), or, with
        ``same_pose="zero_motion"``, scored as zero motion (valid, neither interpolated nor
        corrected). ``None``: none possible (relations by index).
    """

    pose_first: NDArray[np.float64]
    pose_second: NDArray[np.float64]
    index_first: NDArray[np.int64]
    index_second: NDArray[np.int64]
    valid: NDArray[np.bool_]
    via_odometry: NDArray[np.bool_]
    interpolated: NDArray[np.bool_]
    reason: NDArray[np.int8]
    same_pose: NDArray[np.bool_] | None = None

    @property
    def estimated_delta(self) -> NDArray[np.float64]:
        """``δ_ij = x_i⁻¹ ∘ x_j`` of the estimate, shape (M, 3) or (M, 7) (NaN where invalid)."""
        return group_of(self.pose_first).between(self.pose_first, self.pose_second)


def nearest_index(times: NDArray[np.float64], query: NDArray[np.float64]) -> NDArray[np.int64]:
    """Index of the element of sorted ``times`` nearest to each ``query`` (ties: earlier)."""
    n = times.shape[0]
    k = insertion_points(times, query)
    k = np.clip(k, 1, max(n - 1, 1))
    if n == 1:
        return np.zeros(query.shape, dtype=np.int64)
    before = times[k - 1]
    after = times[k]
    pick_before = np.abs(query - before) <= np.abs(after - query)
    return np.where(pick_before, k - 1, k).astype(np.int64)


_WINDOW = 8  # indices searched on each side of a guess before a full binary search


def insertion_points(times: NDArray[np.float64], query: NDArray[np.float64]) -> NDArray[np.int64]:
    """``np.searchsorted(times, query, side="left")`` for sorted ``times``, same result.

    A binary search per query costs ~log2(N) unpredictable branches; pose times are
    usually near-uniform, so each query's index is first guessed by linear interpolation
    between the first and last time, then searched in a window of ±8 around the guess,
    and kept only where ``times[k − 1] < query ≤ times[k]`` holds (the definition of the
    left insertion point). The rest take the binary search.
    """
    q = np.asarray(query, dtype=np.float64)
    n = times.shape[0]
    if n < 4 * _WINDOW or q.size < n // 8 or not (times[-1] > times[0]):
        return np.searchsorted(times, q, side="left").astype(np.int64)
    if not np.isfinite(q).all():
        return np.searchsorted(times, q, side="left").astype(np.int64)
    guess = (q - times[0]) * ((n - 1) / (times[-1] - times[0]))
    np.clip(guess, 0, n, out=guess)
    k = np.ceil(guess).astype(np.int64)
    ok = (k == 0) | (times[np.maximum(k - 1, 0)] < q)
    ok &= (k == n) | (times[np.minimum(k, n - 1)] >= q)
    miss = np.flatnonzero(~ok)
    if miss.size:
        k[miss] = _window_search(times, q[miss], k[miss])
    return k


def _window_search(
    times: NDArray[np.float64], q: NDArray[np.float64], guess: NDArray[np.int64]
) -> NDArray[np.int64]:
    """Left insertion points of ``q`` searched among ``2W + 1`` times around ``guess``."""
    n = times.shape[0]
    width = 2 * _WINDOW + 1
    lo = np.clip(guess - _WINDOW, 0, n - width)
    k = lo.copy()
    for off in range(width):
        k += times[lo + off] < q
    # the insertion point when it falls strictly inside the window or at an end of the array
    inside = ((k > lo) | (lo == 0)) & ((k < lo + width) | (k == n))
    miss = np.flatnonzero(~inside)
    if miss.size:
        k[miss] = np.searchsorted(times, q[miss], side="left")
    return k


def _associate_times(
    query: NDArray[np.float64],
    estimate: Trajectory,
    odometry: Trajectory | None,
    max_time_diff: float,
    interpolate: bool,
    max_interpolation_gap: float,
) -> tuple[
    NDArray[np.float64], NDArray[np.int64], NDArray[np.int8], NDArray[np.bool_], NDArray[np.bool_]
]:
    t = estimate.timestamps
    p = estimate.poses
    group = estimate.group
    k = nearest_index(t, query)
    gap = np.abs(t[k] - query)
    poses = p[k]  # a new array (fancy indexing)
    reason = np.full(query.shape, OK, dtype=np.int8)
    far = gap > max_time_diff
    interp = np.zeros(query.shape, dtype=bool)
    odo = np.zeros(query.shape, dtype=bool)
    if interpolate and far.any() and t.size > 1:
        a, s = estimate.bracket(query)
        inside = (query >= t[0]) & (query <= t[-1])
        span = t[a + 1] - t[a]
        can = far & inside & (span <= max_interpolation_gap) & (span > 0)
        if can.any():
            poses[can] = group.interpolate(p[a[can]], p[a[can] + 1], s[can])
            interp[can] = True
            far = far & ~can
    if odometry is not None and far.any():
        to = odometry.timestamps
        po = odometry.poses
        q = query[far]
        inside = (q >= to[0] - max_time_diff) & (q <= to[-1] + max_time_diff)
        at_query = nearest_index(to, q)
        at_pose = nearest_index(to, t[k[far]])
        corrected = group.compose(p[k[far]], group.between(po[at_pose], po[at_query]))
        idx = np.flatnonzero(far)
        ok = idx[inside]
        poses[ok] = corrected[inside]
        odo[ok] = True
        far[ok] = False
    outside = (query < t[0] - max_time_diff) | (query > t[-1] + max_time_diff)
    reason[far] = np.where(outside[far], OUTSIDE_SPAN, TOO_FAR)
    poses[far] = np.nan
    return poses, np.where(far, -1, k), reason, odo, interp


def associate(
    relations: RelationSet,
    estimate: Trajectory,
    *,
    odometry: Trajectory | None = None,
    max_time_diff: float = 0.1,
    interpolate: bool = False,
    max_interpolation_gap: float = 1.0,
    same_pose: SamePoseRule = "separate",
) -> Association:
    """Find the estimate poses of both ends of every relation.

    Parameters
    ----------
    relations : RelationSet
        ``key="time"``: ends are timestamps; ``key="index"``: pose indices of ``estimate``.
    estimate : Trajectory
        The evaluated trajectory.
    odometry : Trajectory, optional
        Odometry log used to correct ends farther than ``max_time_diff`` from any pose; on
        the estimate's group (a planar log is lifted for an SE(3) estimate).
    max_time_diff : float
        Seconds; the nearest-pose tolerance (0.1 s as in the metricEvaluator).
    interpolate : bool
        Interpolate on the estimate's group (SE(2) or SE(3), constant twist) between the
        poses around an end beyond the tolerance.
    max_interpolation_gap : float
        Seconds; longest gap between two estimate poses that is interpolated over.
    same_pose : {"separate", "zero_motion"}
        Relations whose two different times find one estimate pose: ``"separate"``
        interpolates both ends (``interpolate=True``) or leaves the relation unassociated
        (reason ``SAME_POSE``); ``"zero_motion"`` keeps both ends at that pose, zero estimated
        motion, as the C++ metricEvaluator does. Counted in ``same_pose`` either way.

    Returns
    -------
    Association
    """
    for name, value in (
        ("max_time_diff", max_time_diff),
        ("max_interpolation_gap", max_interpolation_gap),
    ):
        if not (math.isfinite(value) and value >= 0.0):
            raise InputError(f"{name} must be a finite number of seconds >= 0, got {value}")
    if same_pose not in SAME_POSE_RULES:
        raise InputError(f"same_pose must be one of {SAME_POSE_RULES}, got {same_pose!r}")
    m = len(relations)
    width = estimate.group.width
    if odometry is not None and odometry.group is not estimate.group:
        odometry = odometry.lifted() if odometry.group.width < width else odometry.planar()
    if relations.key == "index" and _all_indices_in_range(relations, len(estimate)):
        # the common case without a mask: two gathers, no (2M, width) buffer
        first = relations.first.astype(np.int64)
        second = relations.second.astype(np.int64)
        return Association(
            pose_first=estimate.poses.take(first, axis=0),
            pose_second=estimate.poses.take(second, axis=0),
            index_first=first,
            index_second=second,
            valid=np.ones(m, dtype=bool),
            via_odometry=np.zeros(m, dtype=bool),
            interpolated=np.zeros(m, dtype=bool),
            reason=np.zeros(m, dtype=np.int8),
        )
    if relations.key == "index":
        n = len(estimate)
        ends = np.concatenate((relations.first, relations.second)).astype(np.int64)
        good = (ends >= 0) & (ends < n)
        poses = np.full((2 * m, width), np.nan)
        poses[good] = estimate.poses[ends[good]]
        idx = np.where(good, ends, -1)
        reason = np.where(good, OK, BAD_INDEX).astype(np.int8)
        odo = interp = np.zeros(2 * m, dtype=bool)
    elif len(estimate) == 0:
        poses = np.full((2 * m, width), np.nan)
        idx = np.full(2 * m, -1, dtype=np.int64)
        reason = np.full(2 * m, OUTSIDE_SPAN, dtype=np.int8)
        odo = interp = np.zeros(2 * m, dtype=bool)
    else:
        ends_t = np.concatenate((relations.first, relations.second))
        poses, idx, reason, odo, interp = _associate_times(
            ends_t, estimate, odometry, max_time_diff, interpolate, max_interpolation_gap
        )
    same = None
    if relations.key == "time" and len(estimate):
        same = _separate_same_pose(
            relations, estimate, poses, idx, reason, odo, interp,
            interpolate and same_pose == "separate", max_interpolation_gap,
            keep=same_pose == "zero_motion",
        )  # fmt: skip
    r1, r2 = reason[:m], reason[m:]
    valid = (r1 == OK) & (r2 == OK)
    return Association(
        pose_first=poses[:m],
        pose_second=poses[m:],
        index_first=idx[:m],
        index_second=idx[m:],
        valid=valid,
        via_odometry=(odo[:m] | odo[m:]) & valid,
        interpolated=(interp[:m] | interp[m:]) & valid,
        reason=np.where(r1 != OK, r1, r2).astype(np.int8),
        same_pose=same,
    )


def _separate_same_pose(
    relations: RelationSet,
    estimate: Trajectory,
    poses: NDArray[np.float64],
    idx: NDArray[np.int64],
    reason: NDArray[np.int8],
    odo: NDArray[np.bool_],
    interp: NDArray[np.bool_],
    interpolate: bool,
    max_gap: float,
    *,
    keep: bool = False,
) -> NDArray[np.bool_]:
    """Relations whose two different times took one estimate pose: interpolated or refused
    (or, with ``keep``, left at that pose: zero motion).

    Works in place on the per-end arrays (length 2M, first ends then second ends); returns
    the mask (M,) of such relations.
    """
    m = len(relations)
    own = odo | interp  # an end with a pose of its own time
    same = (
        (idx[:m] == idx[m:])
        & (idx[:m] >= 0)
        & (reason[:m] == OK)
        & (reason[m:] == OK)
        & ~own[:m]
        & ~own[m:]
        & (relations.first != relations.second)
    )
    if keep or not same.any():
        return same
    rows = np.flatnonzero(same)
    ends = np.concatenate((rows, rows + m))
    t = estimate.timestamps
    if interpolate and t.size > 1:
        query = np.concatenate((relations.first[rows], relations.second[rows]))
        a, s = estimate.bracket(query)
        span = t[a + 1] - t[a]
        ok = (query >= t[0]) & (query <= t[-1]) & (span <= max_gap) & (span > 0)
        pair = ok[: rows.size] & ok[rows.size :]
        both = np.concatenate((pair, pair))
        if both.any():
            p = estimate.poses
            poses[ends[both]] = estimate.group.interpolate(p[a[both]], p[a[both] + 1], s[both])
            interp[ends[both]] = True
        ends = ends[~both]
    poses[ends] = np.nan
    reason[ends] = SAME_POSE
    return same


def _all_indices_in_range(relations: RelationSet, n: int) -> bool:
    """Every pose index of ``relations`` (``key="index"``) names one of ``n`` poses."""
    if len(relations) == 0:
        return False
    lo = min(relations.first.min(), relations.second.min())
    hi = max(relations.first.max(), relations.second.max())
    return bool(lo >= 0 and hi < n)


def match_nearest_times(
    query: NDArray[np.float64], times: NDArray[np.float64], max_diff: float
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """evo's nearest-time matching (``evo.core.sync.matching_time_indices``), vectorised.

    For each ``query`` stamp, the ``times`` stamp nearest to it (:func:`nearest_index`; ties:
    the earlier) when ``|t_k − q| ≤ max_diff`` seconds — evo's test; ``times`` must be sorted.
    Several queries may match one time. A query equal to a time that ``times`` repeats
    takes the last of the repeats, as evo's ``searchsorted(side="right")`` does (any other
    nearest pose of a repeated time is already the one evo takes: the last of a group before
    the query, the first of a group after it).

    Returns
    -------
    index_query, index_times : ndarray of int64, shape (K,)
        The matched pairs, in query order.
    """
    q = np.asarray(query, dtype=np.float64)
    t = np.asarray(times, dtype=np.float64)
    if t.size == 0 or q.size == 0:
        return np.empty(0, np.int64), np.empty(0, np.int64)
    k = nearest_index(t, q)
    if t.size > 1 and bool((t[1:] == t[:-1]).any()):
        exact = np.flatnonzero(t[k] == q)
        k[exact] = np.searchsorted(t, q[exact], side="right") - 1
    ok = np.flatnonzero(np.abs(t[k] - q) <= max_diff)
    return ok.astype(np.int64), k[ok]


def synchronize(
    reference: Trajectory, estimate: Trajectory, *, max_diff: float = 0.01, offset: float = 0.0
) -> tuple[Trajectory, Trajectory]:
    """Pose-by-pose association of two trajectories, as ``evo`` does it (``t_max_diff``).

    Every pose of the trajectory with fewer poses (the estimate when both have as many) is
    matched to the nearest-in-time pose of the other (:func:`match_nearest_times`); poses
    without a match within ``max_diff`` seconds are dropped. Relations on the result are
    then named by index (``key="index"``): pose ``k`` of both is one matched pair. This is
    ``evo.core.sync.associate_trajectories(reference, estimate, max_diff=...)``.

    ``offset`` (seconds, evo's ``offset_2``, ``--t_offset``) is added to the estimate's
    times for the matching only, with evo's arithmetic (to the estimate's times when it is
    the longer trajectory, subtracted from the reference's otherwise); both results keep
    their own times.

    Returns
    -------
    reference_synced, estimate_synced : Trajectory
        Equally long, each with its own timestamps.

    Raises
    ------
    AssociationError
        When no pose pair lies within ``max_diff``.
    """
    from relation_metric.errors import AssociationError

    if not (math.isfinite(max_diff) and max_diff >= 0.0):
        raise InputError(f"max_diff must be a finite number of seconds >= 0, got {max_diff}")
    if not math.isfinite(offset):
        raise InputError(f"offset must be a finite number of seconds, got {offset}")
    second_longer = len(estimate) > len(reference)
    short, long_ = (reference, estimate) if second_longer else (estimate, reference)
    long_times = long_.timestamps
    if offset != 0.0:
        long_times = long_times + (offset if second_longer else -offset)
    i_short, i_long = match_nearest_times(short.timestamps, long_times, max_diff)
    if i_short.size == 0:
        raise AssociationError(
            f"no reference and estimate poses lie within {max_diff:g} s of each other (the "
            f"reference spans {reference.span()[0]:.6f} .. {reference.span()[1]:.6f} s, the "
            f"estimate {estimate.span()[0]:.6f} .. {estimate.span()[1]:.6f} s)"
        )
    s = Trajectory(short.timestamps[i_short], short.poses[i_short])
    lo = Trajectory(long_.timestamps[i_long], long_.poses[i_long])
    return (s, lo) if second_longer else (lo, s)
