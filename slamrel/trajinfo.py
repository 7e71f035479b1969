"""What ``slamrel traj info`` says about a trajectory: counts, times, length, rate.

Pure functions of a :class:`~relation_metric.trajectory.Trajectory` (no I/O).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from relation_metric.trajectory import Trajectory

__all__ = ["TrajectoryInfo", "trajectory_info"]


@dataclass(frozen=True)
class TrajectoryInfo:
    """A trajectory's vital numbers.

    Attributes
    ----------
    poses : int
    dimension : str
        ``"2-D"`` (SE(2)) or ``"3-D"`` (SE(3)).
    start, end, duration : float
        First and last timestamp and their difference [s].
    length : float
        Path length ``Σ ‖p_{k+1} − p_k‖`` over the positions [m].
    rate : float
        ``(N − 1) / duration`` [Hz]; NaN for fewer than 2 poses or a zero duration.
    median_step, max_gap : float
        Median and largest time between consecutive poses [s]; NaN below 2 poses.
    extent : tuple of float
        The range ``max − min`` of each position coordinate [m] (2 or 3 values).
    """

    poses: int
    dimension: str
    start: float
    end: float
    duration: float
    length: float
    rate: float
    median_step: float
    max_gap: float
    extent: tuple[float, ...]

    def as_dict(self) -> dict[str, object]:
        return {
            "poses": self.poses,
            "dimension": self.dimension,
            "start_s": self.start,
            "end_s": self.end,
            "duration_s": self.duration,
            "length_m": self.length,
            "rate_hz": None if np.isnan(self.rate) else self.rate,
            "median_step_s": None if np.isnan(self.median_step) else self.median_step,
            "max_gap_s": None if np.isnan(self.max_gap) else self.max_gap,
            "extent_m": list(self.extent),
        }


def trajectory_info(trajectory: Trajectory) -> TrajectoryInfo:
    """The :class:`TrajectoryInfo` of a trajectory with at least one pose (vectorised)."""
    t = trajectory.timestamps
    xyz = trajectory.group.positions(trajectory.poses)
    n = int(t.size)
    duration = float(t[-1] - t[0])
    steps = np.diff(t)
    nan = float("nan")
    length = float(np.linalg.norm(np.diff(xyz, axis=0), axis=1).sum()) if n > 1 else 0.0
    return TrajectoryInfo(
        poses=n,
        dimension="3-D" if trajectory.group.name == "SE3" else "2-D",
        start=float(t[0]),
        end=float(t[-1]),
        duration=duration,
        length=length,
        rate=(n - 1) / duration if n > 1 and duration > 0 else nan,
        median_step=float(np.median(steps)) if n > 1 else nan,
        max_gap=float(steps.max()) if n > 1 else nan,
        extent=tuple(float(v) for v in np.ptp(xyz, axis=0)),
    )
