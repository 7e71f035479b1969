"""Estimate poses at scan times, and the per-relation quality report (CSV text).

:func:`estimate_at_scans` follows the Freiburg evaluator's rule: the estimate pose nearest
in time, and when it is more than ``tolerance`` away the odometry motion between the scan
nearest to that pose and the scan itself is composed onto it,
``x̂_k = x_n ∘ (o_{s(n)}⁻¹ ∘ o_k)`` (``o`` the log's laser poses, ``s(n)`` the scan nearest to
pose ``n``).

:func:`laser_poses_at_stamps` is the rule for scans without poses of their own (a ROS bag's
``sensor_msgs/LaserScan``): the estimate of the robot's base frame interpolated at each
scan's stamp (:meth:`Trajectory.poses_at <relation_metric.trajectory.Trajectory.poses_at>`,
constant twist between the two poses around it), composed with the laser's offset on the
robot, ``x̂_k = b(t_k) ∘ o``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from relation_metric.se2 import between, compose
from relation_metric.trajectory import Trajectory
from slamrel.formats.laser import LaserScans, nearest_times
from slamrel.scans.relations import ScanRelations

__all__ = [
    "estimate_at_scans",
    "laser_poses_at_stamps",
    "interpolation_gaps",
    "GUESS_GAP",
    "format_report",
    "REPORT_COLUMNS",
]

REPORT_COLUMNS = (
    "t1,t2,x,y,theta,guess_x,guess_y,guess_theta,sd_x,sd_y,sd_theta,matched_fraction,"
    "residual,condition,weak_x,weak_y,initialiser,suspicion,flags,score,second_x,second_y,"
    "second_theta,second_score_ratio"
)


def estimate_at_scans(
    scans: LaserScans,
    times: NDArray[np.float64],
    poses: NDArray[np.float64],
    *,
    tolerance: float = 0.1,
) -> tuple[NDArray[np.float64], int]:
    """Estimate poses ``(N, 3)`` at the scans' times, and how many were odometry-corrected."""
    n, gap = nearest_times(times, scans.timestamps)
    out = poses[n].copy()
    far = gap > tolerance
    if far.any():
        s = nearest_times(scans.timestamps, times[n[far]])[0]
        motion = between(scans.laser_pose[s], scans.laser_pose[far])
        out[far] = compose(out[far], motion)
    return out, int(far.sum())


def within_span(
    stamps: NDArray[np.float64], times: NDArray[np.float64], *, tolerance: float = 0.1
) -> NDArray[np.bool_]:
    """Which ``stamps`` lie within the span of the sorted ``times``, widened by ``tolerance``
    [s] at both ends: the scans an estimate at ``times`` can give a pose without
    extrapolating."""
    if times.size == 0:
        return np.zeros(np.shape(stamps), dtype=bool)
    return (stamps >= times[0] - tolerance) & (stamps <= times[-1] + tolerance)


def laser_poses_at_stamps(
    stamps: NDArray[np.float64],
    base: Trajectory,
    offset: NDArray[np.float64],
    *,
    tolerance: float = 0.1,
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Laser poses ``(N, 3)`` at ``stamps`` from a planar estimate ``base`` of the robot and
    the laser's pose ``offset`` ``[x, y, θ]`` on it, and which stamps have one.

    A stamp more than ``tolerance`` [s] before the first or after the last pose of ``base``
    has none (NaN row, False): an estimate is not extrapolated. Within ``tolerance`` of an
    end the end pose is used.
    """
    stamps = np.asarray(stamps, dtype=np.float64)
    inside = within_span(stamps, base.timestamps, tolerance=tolerance)
    out = np.full((stamps.size, 3), np.nan)
    if inside.any():
        out[inside] = compose(base.poses_at(stamps[inside]), np.asarray(offset, dtype=np.float64))
    return out, inside


#: A scan whose two bracketing estimate poses are farther apart than this [s] gets a guess
#: interpolated across a gap (``relations align`` counts them in a warning).
GUESS_GAP = 1.0


def interpolation_gaps(
    times: NDArray[np.float64], stamps: NDArray[np.float64]
) -> NDArray[np.float64]:
    """The time [s] between the two poses (at ``times``, sorted) that an interpolation at
    each of ``stamps`` spans: 0 at a pose's own time (nothing is interpolated) and at or
    beyond an end (the end pose is used)."""
    t = np.asarray(times, dtype=np.float64)
    stamps = np.asarray(stamps, dtype=np.float64)
    if t.size < 2:
        return np.zeros(stamps.size)
    k = np.clip(np.searchsorted(t, stamps), 1, t.size - 1)
    gap = t[k] - t[k - 1]
    at_pose = (t[k] == stamps) | (t[k - 1] == stamps)
    return np.where(at_pose | (stamps <= t[0]) | (stamps >= t[-1]), 0.0, gap)


def format_report(result: ScanRelations) -> str:
    """The quality report: a header :data:`REPORT_COLUMNS`, one row a relation, in order."""
    p = result.proposals
    sd = np.sqrt(np.maximum(np.diagonal(result.covariance, axis1=1, axis2=2), 0.0))
    lines = [REPORT_COLUMNS]
    rows = np.column_stack(
        (
            p.t1,
            p.t2,
            result.delta,
            result.guess,
            sd,
            result.matched_fraction,
            result.residual,
            result.condition,
            result.weak_direction,
        )
    )
    n = len(result)
    score = result.score if result.score is not None else np.full(n, np.nan)
    second = result.second if result.second is not None else np.full((n, 3), np.nan)
    ratio = result.second_ratio if result.second_ratio is not None else np.full(n, np.nan)
    search = np.column_stack((score, second, ratio)).tolist()
    for k, row in enumerate(rows.tolist()):
        nums = ",".join(f"{v:.17g}" for v in row)
        more = ",".join(f"{v:.9g}" for v in search[k])
        flags = result.flags[k]
        lines.append(f'{nums},{result.initialiser[k]},{result.suspicion[k]:.6g},"{flags}",{more}')
    return "\n".join(lines) + "\n"
