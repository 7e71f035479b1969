"""Time-stamped trajectories on SE(2) (``(N, 3)`` poses) or SE(3) (``(N, 7)`` poses)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relation_metric import se3
from relation_metric.errors import InputError
from relation_metric.groups import SE2, SE3, PoseGroup, group_of
from relation_metric.timeorder import check_in_order

__all__ = [
    "Trajectory",
    "OutOfPlane",
    "readonly",
    "readonly_fresh",
    "MAX_COORDINATE",
    "check_coordinates",
]

MAX_COORDINATE = 1e30
"""Largest position magnitude accepted [m] (10³ × the observable universe).

Beyond it, squared distances and their sums leave float64 (1e300 squared is ``inf``), so a
score would be ``inf``/``nan``; such a file is an input error, not a score."""


def readonly(a: ArrayLike, dtype: type = np.float64) -> NDArray[Any]:
    """A C-contiguous copy of ``a`` (as ``dtype``) that cannot be written to."""
    out: NDArray[Any] = np.array(a, dtype=dtype, copy=True, order="C")
    out.flags.writeable = False
    return out


def readonly_fresh(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """:func:`readonly` without the copy for an array nobody else holds (just computed).

    ``a`` itself is made read-only when it is C-contiguous float64, otherwise copied.
    """
    if a.dtype != np.float64 or not a.flags.c_contiguous or not a.flags.owndata:
        return readonly(a)
    a.flags.writeable = False
    return a


def check_coordinates(
    xy: NDArray[np.float64],
    *,
    what: str,
    path: str | None = None,
    line_of: Callable[[int], int] | None = None,
) -> None:
    """Refuse positions (shape (N, 2) or (N, 3)) with a coordinate beyond :data:`MAX_COORDINATE`.

    ``path`` and ``line_of`` (row → 1-based file line) name where the row came from.
    """
    big = np.flatnonzero((np.abs(xy) > MAX_COORDINATE).any(axis=-1))
    if big.size:
        k = int(big[0])
        line = int(line_of(k)) if line_of is not None else None
        name = f"{what} {k}: " if line is None else f"{what}: "
        raise InputError(
            f"{name}position ({', '.join(f'{float(v):.6g}' for v in xy[k])}) is beyond "
            f"{MAX_COORDINATE:.0e} m; expected coordinates in metres",
            path=path,
            line=line,
        )


class OutOfPlane(NamedTuple):
    """Out-of-plane motion: ``z`` range [m], largest ``|roll|`` and ``|pitch|`` [rad]."""

    z_range: float
    max_abs_roll: float
    max_abs_pitch: float

    def is_planar(self, *, tol_m: float = 1e-9, tol_rad: float = 1e-9) -> bool:
        """Whether the motion stays in one horizontal plane (within the tolerances)."""
        return (
            self.z_range <= tol_m and self.max_abs_roll <= tol_rad and self.max_abs_pitch <= tol_rad
        )

    def describe(self) -> str:
        """``z range 0.123 m, |roll| up to 4.5 deg, |pitch| up to 6.7 deg``."""
        return (
            f"z range {self.z_range:.3g} m, |roll| up to {np.degrees(self.max_abs_roll):.3g} deg, "
            f"|pitch| up to {np.degrees(self.max_abs_pitch):.3g} deg"
        )


@dataclass(frozen=True)
class Trajectory:
    """N time-stamped poses ``w_T_k`` in one world frame, on SE(2) or SE(3).

    Parameters
    ----------
    timestamps : array_like, shape (N,)
        Seconds; finite and never decreasing (equal neighbours are allowed).
    poses : array_like, shape (N, 3) or (N, 7)
        SE(2): ``[x, y, θ]``, θ wrapped to ``[−π, π)`` on construction.
        SE(3): ``[x, y, z, qx, qy, qz, qw]`` (the TUM column order), the quaternion
        normalised to unit length with ``qw ≥ 0`` on construction.
        The column count decides the group (:attr:`group`); finite.

    Both arrays are stored read-only. Construct from files with
    :func:`slamrel.formats.trajectories.read_trajectory`.
    """

    timestamps: NDArray[np.float64]
    poses: NDArray[np.float64]

    def __post_init__(self) -> None:
        t = np.asarray(self.timestamps, dtype=np.float64)
        p = np.asarray(self.poses, dtype=np.float64)
        if t.ndim != 1:
            raise InputError(f"timestamps must have shape (N,), got {t.shape}")
        if p.ndim != 2 or p.shape[1] not in (3, 7) or p.shape[0] != t.shape[0]:
            raise InputError(
                f"poses must have shape ({t.shape[0]}, 3) or ({t.shape[0]}, 7), got {p.shape}"
            )
        if not (np.isfinite(t).all() and np.isfinite(p).all()):
            bad = int(np.flatnonzero(~(np.isfinite(t) & np.isfinite(p).all(axis=1)))[0])
            raise InputError(f"pose {bad} is not finite: t={float(t[bad])}, pose={p[bad].tolist()}")
        group = group_of(p)
        check_coordinates(group.positions(p), what="pose")
        if group is SE3 and p.shape[0]:
            norms = np.linalg.norm(p[:, 3:7], axis=1)
            if not (norms > 1e-12).all():
                bad = int(np.flatnonzero(~(norms > 1e-12))[0])
                raise InputError(f"pose {bad}: the quaternion is zero; expected a unit quaternion")
        check_in_order(t)
        object.__setattr__(self, "timestamps", readonly(t))
        object.__setattr__(self, "poses", readonly_fresh(group.normalize(p)))

    @property
    def group(self) -> PoseGroup:
        """:data:`~relation_metric.groups.SE2` or :data:`~relation_metric.groups.SE3`."""
        return group_of(self.poses)

    @property
    def positions(self) -> NDArray[np.float64]:
        """Positions, shape (N, 2) on SE(2), (N, 3) on SE(3)."""
        return self.group.positions(self.poses)

    def lifted(self) -> Trajectory:
        """The same trajectory on SE(3) (``z = roll = pitch = 0`` for planar poses)."""
        if self.group is SE3:
            return self
        return Trajectory(self.timestamps, se3.from_planar(self.poses))

    def planar(self) -> Trajectory:
        """The trajectory projected onto SE(2): ``[x, y, yaw]`` (z, roll, pitch dropped)."""
        if self.group is SE2:
            return self
        return Trajectory(self.timestamps, se3.to_planar(self.poses))

    def out_of_plane(self) -> OutOfPlane:
        """How far the trajectory leaves the plane (what :meth:`planar` discards)."""
        if self.group is SE2 or len(self) == 0:
            return OutOfPlane(0.0, 0.0, 0.0)
        z = self.poses[:, 2]
        rpy = se3.euler_zyx(self.poses[:, 3:7])
        return OutOfPlane(
            z_range=float(z.max() - z.min()),
            max_abs_roll=float(np.abs(rpy[:, 0]).max()),
            max_abs_pitch=float(np.abs(rpy[:, 1]).max()),
        )

    def __len__(self) -> int:
        return int(self.timestamps.shape[0])

    @classmethod
    def from_poses(cls, poses: ArrayLike, *, dt: float = 1.0, t0: float = 0.0) -> Trajectory:
        """A trajectory with evenly spaced timestamps ``t0 + k dt``."""
        p = np.asarray(poses, dtype=np.float64)
        return cls(t0 + dt * np.arange(p.shape[0], dtype=np.float64), p)

    @property
    def xy(self) -> NDArray[np.float64]:
        """Horizontal positions ``[x, y]``, shape (N, 2)."""
        return self.poses[:, :2]

    def path_length(self) -> NDArray[np.float64]:
        """Cumulative travelled distance at each pose, shape (N,), starting at 0."""
        if len(self) < 2:
            return np.zeros(len(self))
        diff = np.diff(self.positions, axis=0)
        steps = (
            np.hypot(diff[:, 0], diff[:, 1]) if diff.shape[1] == 2 else np.linalg.norm(diff, axis=1)
        )
        return np.concatenate(([0.0], np.cumsum(steps)))

    def transformed(self, w_T_v: ArrayLike) -> Trajectory:
        """The whole trajectory moved rigidly: every pose becomes ``w_T_v ∘ pose``."""
        g = self.group
        return Trajectory(self.timestamps, g.compose(np.asarray(w_T_v), self.poses))

    def bracket(self, t: ArrayLike) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """The stored poses around times ``t`` (shape (M,)): index ``a`` of the last stored
        time ≤ t (clipped to ``0 … N−2``) and the fraction ``s = (t − t_a) / (t_{a+1} − t_a)``
        (NaN where the two times are equal). Needs N ≥ 2."""
        t = np.asarray(t, dtype=np.float64)
        times = self.timestamps
        a = np.clip(np.searchsorted(times, t, side="right") - 1, 0, times.size - 2)
        span = times[a + 1] - times[a]
        with np.errstate(invalid="ignore", divide="ignore"):
            s = (t - times[a]) / span
        return a, np.where(span > 0, s, np.nan)

    def poses_at(self, t: ArrayLike) -> NDArray[np.float64]:
        """Poses at times ``t`` (shape (M,)) → (M, width): the one pose interpolation.

        Constant-twist motion between the two stored poses around each time,
        ``w_T_a ∘ exp(s · log(w_T_a⁻¹ ∘ w_T_b))`` (:meth:`PoseGroup.interpolate`); times
        before the first or after the last pose get that pose, and a time between two equal
        time stamps the earlier pose. Needs N ≥ 1.
        """
        t = np.asarray(t, dtype=np.float64)
        if len(self) == 1:
            return np.repeat(self.poses, t.size, axis=0)
        a, s = self.bracket(t)
        s = np.clip(np.nan_to_num(s, nan=0.0), 0.0, 1.0)
        return self.group.interpolate(self.poses[a], self.poses[a + 1], s)

    def span(self) -> tuple[float, float]:
        """First and last timestamp."""
        if len(self) == 0:
            return (float("nan"), float("nan"))
        return float(self.timestamps[0]), float(self.timestamps[-1])
