"""Time-stamped SE(2) trajectories."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relation_metric import se2
from relation_metric.errors import InputError

__all__ = ["Trajectory", "readonly"]


def readonly(a: ArrayLike, dtype: type = np.float64) -> NDArray[Any]:
    """A C-contiguous copy of ``a`` (as ``dtype``) that cannot be written to."""
    out: NDArray[Any] = np.array(a, dtype=dtype, copy=True, order="C")
    out.flags.writeable = False
    return out


@dataclass(frozen=True)
class Trajectory:
    """N time-stamped poses ``w_T_k = [x, y, θ]`` in one world frame.

    Parameters
    ----------
    timestamps : array_like, shape (N,)
        Seconds; finite and never decreasing (equal neighbours are allowed).
    poses : array_like, shape (N, 3)
        ``[x, y, θ]``; finite; θ is wrapped to ``[−π, π)`` on construction.

    Both arrays are stored read-only. Construct from files with
    :func:`relation_metric.formats.read_trajectory`.
    """

    timestamps: NDArray[np.float64]
    poses: NDArray[np.float64]

    def __post_init__(self) -> None:
        t = np.asarray(self.timestamps, dtype=np.float64)
        p = np.asarray(self.poses, dtype=np.float64)
        if t.ndim != 1:
            raise InputError(f"timestamps must have shape (N,), got {t.shape}")
        if p.ndim != 2 or p.shape[1] != 3 or p.shape[0] != t.shape[0]:
            raise InputError(f"poses must have shape ({t.shape[0]}, 3), got {p.shape}")
        if not (np.isfinite(t).all() and np.isfinite(p).all()):
            bad = int(np.flatnonzero(~(np.isfinite(t) & np.isfinite(p).all(axis=1)))[0])
            raise InputError(f"pose {bad} is not finite: t={t[bad]}, pose={p[bad]}")
        if t.size > 1:
            back = np.flatnonzero(np.diff(t) < 0)
            if back.size:
                k = int(back[0])
                raise InputError(
                    f"time goes backwards at pose {k + 1}: {float(t[k + 1])} after {float(t[k])}"
                )
        object.__setattr__(self, "timestamps", readonly(t))
        object.__setattr__(self, "poses", readonly(se2.wrap_last(p)))

    def __len__(self) -> int:
        return int(self.timestamps.shape[0])

    @classmethod
    def from_poses(cls, poses: ArrayLike, *, dt: float = 1.0, t0: float = 0.0) -> Trajectory:
        """A trajectory with evenly spaced timestamps ``t0 + k dt``."""
        p = np.asarray(poses, dtype=np.float64)
        return cls(t0 + dt * np.arange(p.shape[0], dtype=np.float64), p)

    @property
    def xy(self) -> NDArray[np.float64]:
        """Positions, shape (N, 2)."""
        return self.poses[:, :2]

    def path_length(self) -> NDArray[np.float64]:
        """Cumulative travelled distance at each pose, shape (N,), starting at 0."""
        steps = np.hypot(*np.diff(self.poses[:, :2], axis=0).T) if len(self) > 1 else []
        return np.concatenate(([0.0], np.cumsum(steps)))

    def transformed(self, w_T_v: ArrayLike) -> Trajectory:
        """The whole trajectory moved rigidly: every pose becomes ``w_T_v ∘ pose``."""
        return Trajectory(self.timestamps, se2.compose(np.asarray(w_T_v), self.poses))

    def span(self) -> tuple[float, float]:
        """First and last timestamp."""
        if len(self) == 0:
            return (float("nan"), float("nan"))
        return float(self.timestamps[0]), float(self.timestamps[-1])
