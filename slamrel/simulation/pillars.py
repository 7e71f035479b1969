"""A world with walls and point landmarks: EKF-SLAM on the pillars while the laser is logged.

The ``"loop"`` laser world (:func:`slamrel.simulation.laser.laser_world`: a 30 × 20 m
corridor around a block, doorways, twelve 0.3 m pillars on its outer walls) with eight more
pillars on the block's walls (:data:`EXTRA_PILLARS`). Every pillar's centre is a **point
landmark**, 20 in all. One drive (:func:`pillar_log`) gives both sensors of a robot:

* the **laser** (:func:`~slamrel.simulation.laser.simulate_laser_log`: 361 beams, 1 cm range
  noise) and the drifting **odometry** (per step ``N(0, σ²)`` on ``dx, dy, dθ``, σ =
  ``odometry_sigma``), and
* a **pillar detector**: range and bearing to every pillar centre within ``max_range`` and
  the ±90° field of view whose line of sight is clear (the segment from the robot to a point
  :data:`PILLAR_CLEARANCE` short of the centre crosses no wall), with ``N(0, σ_r²)`` and
  ``N(0, σ_b²)`` noise (its own random stream, apart from the laser's).

:func:`pillar_log` returns the laser log and the **log bundle** (odometry motion model with
the odometry's σ, the detector's range–bearing model, known associations, the true map with
zero covariance as a placeholder, the ground truth): ``slamrel slam``'s input
(:func:`slamrel.backends.ekf_slam.ekf_slam_bundle`). The laser is at the robot's origin, so
the bundle's poses and the scans' poses are the same poses at the same times (``k · dt``).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from recovery.bundle import Bundle
from recovery.models import MotionModel, SensorModel
from relation_metric import se2
from relation_metric.trajectory import Trajectory
from slamrel.simulation.laser import SimulatedLog, laser_world, loop_path, simulate_laser_log

__all__ = ["EXTRA_PILLARS", "PillarLog", "pillar_world", "pillar_log", "line_of_sight"]

#: Lower-left corners of the eight pillars (0.3 × 0.3 m) added on the block's walls [m].
EXTRA_PILLARS = (
    (10.5, 2.7),
    (15.0, 2.7),
    (19.5, 2.7),
    (5.0, 17.0),
    (11.0, 17.0),
    (16.0, 17.0),
    (2.7, 9.0),
    (27.0, 6.0),
)
#: The drive's corners (the corridor's centre line) [m].
CORNERS = ((1.5, 1.5), (28.5, 1.5), (28.5, 18.5), (1.5, 18.5))
#: A pillar is seen when its line of sight is clear up to this far short of its centre [m]
#: (its own faces lie 0.15–0.21 m from the centre).
PILLAR_CLEARANCE = 0.25
_SIDE = 0.3


class PillarLog(NamedTuple):
    """One drive: the laser log and the pillar detector's log bundle.

    Attributes
    ----------
    laser : SimulatedLog
        Scans with the odometry as their poses, and the true laser poses.
    bundle : Bundle
        The log bundle (odometry, measurements, true map, ground truth).
    landmarks : (L, 2) float
        The pillars' centres [m].
    """

    laser: SimulatedLog
    bundle: Bundle
    landmarks: NDArray[np.float64]


def pillar_world() -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Walls ``(S, 4)`` and pillar centres ``(20, 2)`` of the world (module docstring)."""
    walls = laser_world("loop")
    extra = np.asarray(EXTRA_PILLARS, dtype=np.float64)
    x, y, s = extra[:, 0], extra[:, 1], _SIDE
    corners = np.stack(
        [np.column_stack(c) for c in ((x, y), (x + s, y), (x + s, y + s), (x, y + s))], axis=1
    )  # (P, 4, 2)
    boxes = np.concatenate((corners, np.roll(corners, -1, axis=1)), axis=2).reshape(-1, 4)
    walls = np.vstack((walls, boxes))
    return walls, _pillar_centres(walls)


def _pillar_centres(walls: NDArray[np.float64]) -> NDArray[np.float64]:
    """Centres of the closed 0.3 m squares among ``walls``: four segments of length 0.3 whose
    lower-left corner is shared (each square is drawn as four such segments)."""
    length = np.hypot(walls[:, 2] - walls[:, 0], walls[:, 3] - walls[:, 1])
    side = walls[np.isclose(length, _SIDE)]
    lower_left = np.minimum(side[:, :2], side[:, 2:])
    corner, count = np.unique(np.round(lower_left, 6), axis=0, return_counts=True)
    return corner[count == 2] + _SIDE / 2  # two of a square's sides start at its lower left


def line_of_sight(
    origins: NDArray[np.float64], targets: NDArray[np.float64], walls: NDArray[np.float64]
) -> NDArray[np.bool_]:
    """``(K,)``: the segment ``origins[k]`` → ``targets[k]`` (``(K, 2)`` each) crosses no wall.

    Segments ``p + t (q − p)`` and ``a + s (b − a)`` cross when ``0 ≤ t ≤ 1`` and
    ``0 ≤ s ≤ 1``, with ``t = ((a − p) × (b − a)) / d``, ``s = ((a − p) × (q − p)) / d``,
    ``d = (q − p) × (b − a)`` (parallel segments, ``d = 0``, never cross).
    """
    p, r = origins[:, None, :], (targets - origins)[:, None, :]  # (K, 1, 2)
    a, e = walls[None, :, :2], (walls[:, 2:] - walls[:, :2])[None]  # (1, S, 2)
    ap = a - p
    d = r[..., 0] * e[..., 1] - r[..., 1] * e[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (ap[..., 0] * e[..., 1] - ap[..., 1] * e[..., 0]) / d
        s = (ap[..., 0] * r[..., 1] - ap[..., 1] * r[..., 0]) / d
    cross = (np.abs(d) > 1e-12) & (t >= 0) & (t <= 1) & (s >= 0) & (s <= 1)
    return np.asarray(~cross.any(axis=1), dtype=bool)


def _detect(
    truth: NDArray[np.float64],
    landmarks: NDArray[np.float64],
    walls: NDArray[np.float64],
    max_range: float,
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
    """Pose and landmark rows of every clear sighting, with its true range and bearing."""
    rel = se2.inverse_transform_points(truth[:, None, :], landmarks[None, :, :])  # (N, L, 2)
    rng_, brg = np.hypot(rel[..., 0], rel[..., 1]), np.arctan2(rel[..., 1], rel[..., 0])
    k, lm = np.nonzero((rng_ <= max_range) & (np.abs(brg) <= np.pi / 2))
    r, b = rng_[k, lm], brg[k, lm]
    origin = truth[k, :2]
    short = landmarks[lm] - (PILLAR_CLEARANCE / r)[:, None] * (landmarks[lm] - origin)
    ok = line_of_sight(origin, short, walls)
    return k[ok].astype(np.int64), lm[ok].astype(np.int64), r[ok], b[ok]


def pillar_log(
    seed: int,
    *,
    extra_scans: int = 60,
    step: float = 0.3,
    max_range: float = 10.0,
    sigma_range: float = 0.05,
    sigma_bearing: float = 0.01,
    odometry_sigma: tuple[float, float, float] = (0.01, 0.005, 0.005),
    dt: float = 0.2,
) -> PillarLog:
    """One drive around the block and ``extra_scans`` on past the start (module docstring);
    everything drawn from ``seed``."""
    walls, landmarks = pillar_world()
    lap = loop_path(np.asarray(CORNERS), step)
    truth = np.vstack((lap, lap[:extra_scans]))
    laser = simulate_laser_log(walls, truth, odometry_sigma=odometry_sigma, dt=dt, seed=seed)
    k, lm, r, b = _detect(truth, landmarks, walls, max_range)
    noise = np.random.default_rng([seed, 38]).normal(0.0, 1.0, (k.size, 2))
    z = np.column_stack(
        (np.abs(r + sigma_range * noise[:, 0]), se2.wrap_angle(b + sigma_bearing * noise[:, 1]))
    )
    times = laser.scans.timestamps
    ids = np.arange(landmarks.shape[0], dtype=np.int64)
    bundle = Bundle(
        motion=MotionModel("odometry", sigma=odometry_sigma),
        sensor=SensorModel(sigma_range, sigma_bearing, max_range=max_range, fov=np.pi),
        measurement_times=times[k],
        measurements=z,
        measurement_landmarks=lm,
        measurement_associated=np.ones(k.size, dtype=bool),
        map_ids=ids,
        map_xy=landmarks,
        map_marginals=np.zeros((ids.size, 2, 2)),
        initial_pose=truth[0],
        initial_covariance=np.zeros((3, 3)),
        groundtruth=Trajectory(times, truth),
        landmarks_groundtruth=(ids, landmarks),
        description=f"slamrel pillar world (loop + {len(EXTRA_PILLARS)} pillars), seed {seed}",
        odometry=Trajectory(times, laser.scans.odometry_pose),
    )
    return PillarLog(laser, bundle, landmarks)
