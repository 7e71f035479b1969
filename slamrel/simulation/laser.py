"""A ray-casting 2-D laser simulator: walls as segments, exact truth, range noise, odometry drift.

Worlds are sets of wall segments ``(S, 4)`` rows ``[x1, y1, x2, y2]`` [m]. A scan from laser
pose ``[x, y, θ]`` casts beam ``k`` at angle ``θ + start + k · resolution``; its reading is
the distance to the nearest wall hit, plus ``N(0, σ²)`` noise, or ``no_return`` (beyond the
maximum range, as a SICK reports 81.91 m) when no wall lies within ``max_range``.

Ray–segment intersection, vectorised over beams × segments: with ray ``o + r u`` and segment
``a + s (b − a)``, ``r = ((a − o) × (b − a)) / (u × (b − a))`` and
``s = ((a − o) × u) / (u × (b − a))`` (2-D cross product); a hit needs ``r > 0``,
``0 ≤ s ≤ 1``.

Named worlds (:func:`laser_world`): ``"room"`` (a 12 × 8 m room with boxes and pillars),
``"corridor"`` (two parallel walls 2 m apart, 200 m long, nothing else: only the direction
across the corridor is observable), ``"loop"`` (a rectangular corridor loop around a block,
with doorways and pillars, 30 × 20 m). Pure functions of their seed.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from relation_metric import se2
from slamrel.formats.laser import LaserScans

__all__ = [
    "LaserSensor",
    "SimulatedLog",
    "laser_world",
    "ray_cast",
    "simulate_laser_log",
    "loop_path",
]


class LaserSensor(NamedTuple):
    """A planar laser: ``beams`` over ``fov`` from ``start``, ranges ``(0, max_range)``.

    Defaults: a SICK LMS in 0.5° mode (361 beams, −90°…+90°, 80 m, σ = 1 cm, 81.91 m for
    no return).
    """

    beams: int = 361
    start: float = -np.pi / 2
    resolution: float = np.pi / 360
    max_range: float = 80.0
    sigma: float = 0.01
    no_return: float = 81.91


class SimulatedLog(NamedTuple):
    """A simulated log: the scans (with odometry poses) and the true laser poses.

    Attributes
    ----------
    scans : LaserScans
        ``laser_pose`` and ``odometry_pose`` hold the drifting odometry (the laser is at the
        robot's origin).
    truth : (N, 3) float
        True laser poses; ``se2.between(truth[i], truth[j])`` is the exact relation.
    """

    scans: LaserScans
    truth: NDArray[np.float64]


def _box(x: float, y: float, w: float, h: float) -> list[list[float]]:
    c = [(x, y), (x + w, y), (x + w, y + h), (x, y + h)]
    return [[*c[k], *c[(k + 1) % 4]] for k in range(4)]


def laser_world(name: str) -> NDArray[np.float64]:
    """Wall segments ``(S, 4)`` of a named world: ``"room"``, ``"corridor"`` or ``"loop"``."""
    if name == "room":
        walls = _box(0.0, 0.0, 12.0, 8.0)
        walls += _box(2.0, 5.5, 1.5, 1.0) + _box(7.0, 2.2, 1.0, 1.2) + _box(6.0, 6.0, 0.4, 0.4)
        walls += [[4.0, 0.0, 4.0, 1.0], [10.0, 8.0, 10.0, 6.0]]
    elif name == "corridor":
        walls = [[-100.0, -1.0, 100.0, -1.0], [-100.0, 1.0, 100.0, 1.0]]
    elif name == "loop":
        walls = _box(0.0, 0.0, 30.0, 20.0) + _box(3.0, 3.0, 24.0, 14.0)
        for x in (6.0, 12.0, 18.0, 24.0):
            walls += _box(x, 0.3, 0.3, 0.3) + _box(x + 1.5, 19.4, 0.3, 0.3)
        for y in (6.0, 12.0):
            walls += _box(0.3, y, 0.3, 0.3) + _box(29.4, y + 1.0, 0.3, 0.3)
        walls += [[9.0, 3.0, 9.0, 2.0], [21.0, 17.0, 21.0, 18.0], [27.0, 9.0, 28.0, 9.0]]
    else:
        raise ValueError(f"unknown laser world {name!r}; expected room, corridor or loop")
    return np.asarray(walls, dtype=np.float64)


def ray_cast(
    walls: NDArray[np.float64], pose: NDArray[np.float64], sensor: LaserSensor
) -> NDArray[np.float64]:
    """Noise-free ranges ``(beams,)`` from ``pose``; ``inf`` where no wall is hit."""
    ang = pose[2] + sensor.start + sensor.resolution * np.arange(sensor.beams)
    u = np.column_stack((np.cos(ang), np.sin(ang)))  # (B, 2)
    a, b = walls[:, :2], walls[:, 2:]
    seg = b - a  # (S, 2)
    ao = a - pose[:2]  # (S, 2)
    denom = u[:, None, 0] * seg[None, :, 1] - u[:, None, 1] * seg[None, :, 0]  # (B, S)
    cross_ao_seg = ao[:, 0] * seg[:, 1] - ao[:, 1] * seg[:, 0]  # (S,)
    cross_ao_u = ao[None, :, 0] * u[:, None, 1] - ao[None, :, 1] * u[:, None, 0]  # (B, S)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = cross_ao_seg[None, :] / denom
        s = cross_ao_u / denom
    hit = (np.abs(denom) > 1e-12) & (r > 1e-9) & (s >= 0.0) & (s <= 1.0)
    return np.where(hit, r, np.inf).min(axis=1)


def loop_path(
    corners: NDArray[np.float64], step: float, *, turn_steps: int = 6
) -> NDArray[np.float64]:
    """Poses ``(N, 3)`` along a closed polygon ``corners`` ``(K, 2)``, ``step`` apart.

    The heading follows each side; at a corner the robot turns on the spot in
    ``turn_steps`` equal steps (so consecutive scans differ by a rotation only there).
    """
    poses = []
    k = corners.shape[0]
    for c in range(k):
        p, q = corners[c], corners[(c + 1) % k]
        heading = float(np.arctan2(q[1] - p[1], q[0] - p[0]))
        n = max(int(np.floor(np.hypot(*(q - p)) / step)), 1)
        for s in range(n):
            poses.append([*(p + (q - p) * s / n), heading])
        nxt = corners[(c + 2) % k] - q
        turn = se2.wrap_angle_float(float(np.arctan2(nxt[1], nxt[0])) - heading)
        for s in range(turn_steps):
            poses.append([*q, heading + turn * s / turn_steps])
    out = np.asarray(poses, dtype=np.float64)
    out[:, 2] = se2.wrap_angle(out[:, 2])
    return out


def simulate_laser_log(
    walls: NDArray[np.float64],
    truth: NDArray[np.float64],
    *,
    sensor: LaserSensor | None = None,
    odometry_sigma: tuple[float, float, float] = (0.01, 0.005, 0.005),
    dt: float = 0.2,
    seed: int = 0,
) -> SimulatedLog:
    """Scans from the true laser poses ``truth`` ``(N, 3)`` and a drifting odometry.

    Odometry: the true increments ``between(truth[k−1], truth[k])`` with independent
    ``N(0, σ²)`` noise on ``dx, dy, dθ`` (``odometry_sigma``, per step), chained from
    ``truth[0]``. Times ``k · dt``. Range noise ``N(0, sensor.sigma²)``; readings beyond the
    maximum range become ``sensor.no_return``.
    """
    sensor = sensor or LaserSensor()
    rng = np.random.default_rng(seed)
    truth = np.asarray(truth, dtype=np.float64)
    n = truth.shape[0]
    ranges = np.stack([ray_cast(walls, p, sensor) for p in truth])
    ranges = ranges + rng.normal(0.0, sensor.sigma, ranges.shape)
    ranges = np.where(ranges < sensor.max_range, ranges, sensor.no_return)
    inc = se2.between(truth[:-1], truth[1:])
    inc = inc + rng.normal(0.0, 1.0, inc.shape) * np.asarray(odometry_sigma)
    odom = se2.cumulative_compose(inc, truth[0])
    ones = np.ones(n)
    scans = LaserScans(
        path="<simulated>",
        record="FLASER",
        timestamps=np.arange(n, dtype=np.float64) * dt,
        ranges=ranges,
        beams=np.full(n, sensor.beams, dtype=np.int64),
        start_angle=ones * sensor.start,
        angular_resolution=ones * sensor.resolution,
        max_range=ones * sensor.max_range,
        laser_pose=odom.copy(),
        odometry_pose=odom.copy(),
        lines=np.arange(1, n + 1, dtype=np.int64),
        guessed_config=False,
    )
    return SimulatedLog(scans, truth)
