"""Simulated log bundles: the seeded test/benchmark bundle and a world's bundle.

:func:`simulate_bundle` is the small seeded simulator of the tests and benchmarks (not a
world generator):

A unicycle drives with velocity controls (or odometry) through landmarks scattered around
its path; the bundle's controls are the true ones minus the control noise, so the bundle's
noise model is exactly the simulated one. Measurements are taken every ``measure_every``
control steps to every landmark within ``max_range``. The map is the ground truth (with a
tiny covariance) or, with ``map_sigma``, the ground truth plus an error drawn from the stated
joint covariance ``σ_i² I + σ_c² (11ᵀ ⊗ I₂)`` (an independent part and a common offset, as
a SLAM map's landmarks share the error of the poses that saw them). Its sensor is
:func:`slamrel.simulation.sensors.observe_all_around`.

:func:`world_bundle` turns a :class:`slamrel.simulation.worlds.World` into a bundle whose
log (odometry or controls, measurements with their true landmark ids) is the world's and
whose map is the true one (zero covariance): the input of ``slamrel slam``, and a
perfect-map test case for the recovery.
"""

from __future__ import annotations

import numpy as np

from recovery.bundle import Bundle
from recovery.models import (
    MotionModel,
    SensorModel,
    increment_covariance,
    velocity_control_covariance,
    velocity_increment,
)
from relation_metric import se2
from relation_metric.errors import InputError
from relation_metric.trajectory import Trajectory
from slamrel.simulation.sensors import AllAroundSensor, observe_all_around
from slamrel.simulation.worlds import SENSOR_FOV, SENSOR_RANGE, World

__all__ = ["simulate_bundle", "world_bundle"]


def simulate_bundle(
    seed: int,
    *,
    steps: int = 400,
    dt: float = 0.1,
    landmarks: int = 20,
    measure_every: int = 5,
    max_range: float = 8.0,
    motion: str = "velocity",
    sigma_v: float = 0.05,
    sigma_omega: float = 0.03,
    alpha: tuple[float, float, float, float] | None = None,
    sigma_odometry: tuple[float, float, float] = (0.01, 0.005, 0.004),
    sigma_range: float = 0.1,
    sigma_bearing: float = 0.02,
    map_sigma: tuple[float, float] | None = None,
    map_covariance: bool = False,
    measurement_offset: float = 0.0,
    unassociated_fraction: float = 0.0,
) -> Bundle:
    """A seeded bundle with ground truth (see module doc).

    Parameters
    ----------
    seed : int
    steps : int
        Control rows (the last one only ends the run).
    map_sigma : (σ_i, σ_c), optional
        Perturb the map with the joint covariance ``σ_i² I + σ_c² 11ᵀ ⊗ I₂``; the map's
        marginals (and with ``map_covariance`` the joint matrix) are stored in the bundle.
        Without it the map is exact with covariance ``1e-12 I``.
    measurement_offset : float
        Fraction of ``dt`` by which measurement times are shifted after their control time
        (0: measurements at control times).
    unassociated_fraction : float
        Share of measurements written without a landmark id.

    The other parameters are the drive (``dt``; ``motion`` "velocity" with ``sigma_v``,
    ``sigma_omega`` or "odometry" with ``sigma_odometry``; ``alpha`` for either instead), the
    layout (``landmarks``) and the sensor (``measure_every``, ``max_range``, ``sigma_range``,
    ``sigma_bearing``).
    """
    if motion not in ("velocity", "odometry"):
        raise InputError(f"motion must be 'velocity' or 'odometry', got {motion!r}")
    rng = np.random.default_rng(seed)
    # float64 arange: the same numbers (float × int arange is floating[Any] to the stubs)
    t = dt * np.arange(steps, dtype=np.float64)
    sigma = (sigma_v, sigma_omega) if motion == "velocity" else sigma_odometry
    model = MotionModel(motion, alpha=alpha) if alpha else MotionModel(motion, sigma=sigma)
    u_true, controls, odometry = _drive(model, rng, t, dt)
    x0 = np.array([0.0, 0.0, 0.3])
    truth = se2.cumulative_compose(u_true, start=x0)

    # landmarks scattered around poses drawn along the path (index first, then the offset)
    lm_true = truth[rng.integers(0, steps, landmarks), :2] + rng.normal(0.0, 4.0, (landmarks, 2))

    sensor = AllAroundSensor(sigma_range, sigma_bearing, max_range=max_range)
    at = np.arange(measure_every, steps - 1, measure_every)
    obs = observe_all_around(
        truth, lm_true, at, sensor, rng, increments=u_true, offset=measurement_offset
    )
    # len, not shape[0]: the stubs' Any shape[0] picks random()'s scalar overload
    assoc = rng.random(len(obs.pose)) >= unassociated_fraction
    ids = np.arange(landmarks, dtype=np.int64) + 100
    map_xy, cov = _perturbed_map(lm_true, map_sigma, rng)
    return Bundle(
        motion=model,
        sensor=SensorModel(sigma_range, sigma_bearing),
        initial_pose=x0,
        initial_covariance=1e-8 * np.eye(3),
        controls=controls,
        odometry=odometry,
        measurement_times=t[obs.pose] + measurement_offset * dt,
        measurements=np.column_stack((obs.range, obs.bearing)),
        measurement_landmarks=ids[obs.landmark],
        measurement_associated=assoc,
        map_ids=ids,
        map_xy=map_xy,
        map_marginals=_marginals(cov),
        map_covariance=cov if map_covariance else None,
        groundtruth=Trajectory(t, truth),
        landmarks_groundtruth=(ids, lm_true),
        description=f"slamrel.simulation seed={seed}",
    )


def _drive(
    model: MotionModel, rng: np.random.Generator, t: np.ndarray, dt: float
) -> tuple[np.ndarray, np.ndarray | None, Trajectory | None]:
    """True increments ``(N − 1, 3)`` and the bundle's controls or odometry.

    The commands are a smooth ``v = 1 + 0.2 sin``, ``ω = 0.25 sin``; the velocity model adds
    noise to the commands (the bundle keeps the commands), the odometry model to the
    commanded increments (the bundle keeps the commanded odometry, from ``[5, −3, 0.7]``).
    """
    steps = t.shape[0]
    v_cmd = 1.0 + 0.2 * np.sin(0.05 * np.arange(steps))
    w_cmd = 0.25 * np.sin(0.021 * np.arange(steps) + 0.3)
    if model.type == "velocity":
        m = velocity_control_covariance(v_cmd, w_cmd, sigma=model.sigma, alpha=model.alpha)
        noise = np.einsum(
            "nij,nj->ni",
            np.linalg.cholesky(m + 1e-300 * np.eye(2)),
            rng.standard_normal((steps, 2)),
        )
        u_true, _ = velocity_increment(v_cmd[:-1] + noise[:-1, 0], w_cmd[:-1] + noise[:-1, 1], dt)
        return u_true, np.column_stack((t, v_cmd, w_cmd)), None
    u_cmd, _ = velocity_increment(v_cmd[:-1], w_cmd[:-1], dt)
    sig = increment_covariance(model, u_cmd, np.ones(steps - 1))
    chol = np.linalg.cholesky(sig + 1e-300 * np.eye(3))
    u_true = u_cmd + np.einsum("nij,nj->ni", chol, rng.standard_normal((steps - 1, 3)))
    odo = se2.cumulative_compose(u_cmd, start=[5.0, -3.0, 0.7])
    return u_true, None, Trajectory(t, odo)


def _marginals(cov: np.ndarray) -> np.ndarray:
    """The 2 × 2 diagonal blocks of a ``(2L, 2L)`` covariance, shape (L, 2, 2)."""
    n = cov.shape[0] // 2
    return cov.reshape(n, 2, n, 2)[np.arange(n), :, np.arange(n), :]


def _perturbed_map(
    lm_true: np.ndarray, map_sigma: tuple[float, float] | None, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """The map ``(L, 2)`` and its joint covariance ``(2L, 2L)`` (see :func:`simulate_bundle`)."""
    n = lm_true.shape[0]
    if map_sigma is None:
        return lm_true.copy(), 1e-12 * np.eye(2 * n)
    si, sc = map_sigma
    cov = si**2 * np.eye(2 * n) + sc**2 * np.kron(np.ones((n, n)), np.eye(2))
    noise = np.linalg.cholesky(cov) @ rng.standard_normal(2 * n)
    return lm_true + noise.reshape(-1, 2), cov


def world_bundle(world: World) -> Bundle:
    """The world's log and true map as a bundle (ground truth included)."""
    nt = world.noise_params
    o = world.observations
    if world.controls is None:
        motion = MotionModel("odometry", sigma=(nt.sigma_dx, nt.sigma_dy, nt.sigma_dtheta))
        odometry: Trajectory | None = world.odometry
    else:
        rate = world.rate
        dt = (
            float(world.controls[1, 0] - world.controls[0, 0])
            if world.controls.shape[0] > 1
            else 1.0
        )
        # the per-row control noise the world drew (see slamrel.simulation.worlds.make_world)
        sv = nt.sigma_dx * np.sqrt(rate) / (dt * rate)
        sw = nt.sigma_dtheta * np.sqrt(rate) / (dt * rate)
        motion = MotionModel("velocity", sigma=(float(sv), float(sw)))
        odometry = None
    ids = np.arange(world.landmarks.shape[0], dtype=np.int64)
    return Bundle(
        motion=motion,
        # the world's sensor reach (its 0.5 m minimum range is not a reach)
        sensor=SensorModel(
            nt.sigma_range, nt.sigma_bearing, max_range=SENSOR_RANGE, fov=SENSOR_FOV
        ),
        measurement_times=o.t,
        measurements=np.column_stack((o.range, o.bearing)),
        measurement_landmarks=o.landmark,
        measurement_associated=np.ones(o.t.shape[0], dtype=bool),
        map_ids=ids,
        map_xy=world.landmarks,
        map_marginals=np.zeros((ids.size, 2, 2)),
        initial_pose=world.truth.poses[0],
        initial_covariance=1e-9 * np.eye(3),
        groundtruth=world.truth,
        landmarks_groundtruth=(ids, world.landmarks),
        description=(
            f"slamrel simulated world {world.name}, noise type {world.noise}, seed "
            f"{world.seed}, rate {world.rate}; map = true landmarks (perfect map)"
        ),
        controls=world.controls,  # None when odometry-driven
        odometry=odometry,
    )
