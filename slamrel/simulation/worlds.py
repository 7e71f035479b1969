"""Simulated worlds after Hu, Huang & Dissanayake, "Evaluation of Pose Only SLAM".

A robot moves 0.5 m a step and turns by predefined angles; a range-bearing sensor sees point
features between 0.5 m and 5 m and within a 180° field of view; 225 features are normally
distributed around the path. Four trajectories: two simple ones (about 82 poses, one loop,
a single return to the start) and two complex ones (about 420 poses, several loop
closures). Noise types follow their Table I (standard deviations):

====  ===============================  ===========================
type  odometry dx, dy, dθ per step      observation
====  ===============================  ===========================
a     0.1 m, 0.1 m, 0.05 rad            0.1 m
b     0.2 m, 0.2 m, 0.2 rad             0.1 m
c     0.1 m, 0.1 m, 0.05 rad            0.3 m
====  ===============================  ===========================

The paper's observations are relative positions with ``σ`` on dx and dy; slamrel's sensor is
range-bearing (the SLAM result bundle's sensor model), so the observation noise is mapped to
``σ_range = σ`` and ``σ_bearing = σ / r₀`` with ``r₀ = 2.5 m`` (the middle of the sensing
range), which gives the same cross-range standard deviation at ``r₀``.

The worlds ``hu-simple1``, ``hu-simple2``, ``hu-complex1``, ``hu-complex2``
(:data:`PAPER_WORLDS`) follow the paper's *stated* set-up: exactly 82 poses (simple) and 420
poses (complex), the same drives trimmed or extended to that length, no minimum sensing range,
and the paper's Cartesian observation noise (``σ`` on the relative position's x and y,
``observation="cartesian"``; the observations are still stored as range and bearing, the
exact polar form of the noisy relative position). The older worlds keep their numbers
(other results depend on them); either sensor model can be chosen for any world.

They do **not** reproduce the paper's observation counts, which its stated set-up does not
determine: these worlds give many times the paper's data dof ``2 (K − L)`` and far larger
Method 2 graphs (the counts over seeds: benchmarks/README.md). The paper's Table II implies
a data dof near 330 for the simple worlds (full LS's NEES3 sits at its data dof) and Method 2
graphs far smaller (NEES2 of 18–34): 225 features within 5 m of an 82-pose drive, seen over
180°, cannot give so few observations, so the paper's features must be farther from the path
(or its sensor narrower) than it says. Absolute NEES2/NEES3 values are therefore not
comparable with the paper's; the orderings between methods and NEES against its own dof are.

A world and its noise realisation are fully determined by ``(trajectory, noise type, seed)``:
the landmark layout draws from ``seed`` and the noise from an independent child stream, so
changing the noise type keeps the same features.

The sensor is :func:`slamrel.simulation.sensors.observe_field_of_view` (:func:`sensor_of`);
:func:`slamrel.simulation.bundles.world_bundle` turns a world into a log bundle.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from recovery.models import velocity_increment
from relation_metric import se2
from relation_metric.errors import InputError
from relation_metric.trajectory import Trajectory, readonly
from slamrel.constants import NOISE_NAMES, PAPER_WORLDS, WORLDS
from slamrel.simulation.sensors import FieldOfViewSensor, observe_field_of_view

__all__ = [
    "WORLDS",
    "PAPER_WORLDS",
    "PAPER_POSES",
    "OBSERVATION_MODELS",
    "NOISE_TYPES",
    "NoiseType",
    "Observations",
    "World",
    "make_world",
    "path_of",
    "sensor_of",
]

STEP = 0.5  # metres a step
SENSOR_RANGE = 5.0
SENSOR_MIN_RANGE = 0.5  # m; closer features are not detected
SENSOR_FOV = np.pi  # 180°
N_FEATURES = 225
FEATURE_SPREAD = 2.0  # m, standard deviation of the features around the path
NOMINAL_RANGE = 2.5  # m, maps Cartesian observation noise to bearing noise


class NoiseType(NamedTuple):
    """Standard deviations of one noise type (Hu et al., Table I)."""

    sigma_dx: float
    sigma_dy: float
    sigma_dtheta: float
    sigma_observation: float

    @property
    def sigma_range(self) -> float:
        return self.sigma_observation

    @property
    def sigma_bearing(self) -> float:
        return self.sigma_observation / NOMINAL_RANGE


#: The noise type of each of :data:`~slamrel.constants.NOISE_NAMES`, in its order (a, b, c).
NOISE_TYPES: dict[str, NoiseType] = dict(
    zip(
        NOISE_NAMES,
        (
            NoiseType(0.1, 0.1, 0.05, 0.1),  # a
            NoiseType(0.2, 0.2, 0.2, 0.1),  # b
            NoiseType(0.1, 0.1, 0.05, 0.3),  # c
        ),
        strict=True,
    )
)

_Q = np.pi / 2  # quarter turn


def _segments(name: str) -> list[tuple[int, float]]:
    """The drive as ``(steps, total turn over those steps)`` segments."""
    if name == "simple1":  # a 10 m × 10 m square: 4 × 20 steps, 90° corners
        return [(20, 0.0), (1, _Q)] * 4
    if name == "simple2":  # a circle of 40 m circumference (one full turn in 80 steps)
        return [(80, 2 * np.pi), (2, 0.0)]
    if name == "complex1":  # a 3 × 3 block grid driven as a lawn-mower and back: many revisits
        legs: list[tuple[int, float]] = []
        for k in range(3):
            turn = _Q if k % 2 == 0 else -_Q
            legs += [(30, 0.0), (1, turn), (10, 0.0), (1, turn)]
        legs += [(30, 0.0), (1, _Q), (30, 0.0), (1, _Q)]  # back along the outer edge
        legs += [(30, 0.0), (1, _Q), (30, 0.0), (1, _Q)]  # and once more round the block
        legs += [(15, 0.0), (1, _Q), (30, 0.0), (1, -_Q), (15, 0.0), (1, -_Q), (30, 0.0)]
        legs += [(1, _Q), (15, 0.0), (1, _Q), (30, 0.0)]
        return legs
    if name == "complex2":  # a figure eight driven twice, then a loop round both lobes
        lobe = 2 * np.pi
        return (
            [(50, lobe), (50, -lobe)] * 2
            + [(40, 0.0), (1, _Q), (20, 0.0), (1, _Q)]
            + [
                (40, 0.0),
                (1, _Q),
                (20, 0.0),
                (1, _Q),
            ]
            * 2
            + [(55, 0.0)]
        )
    raise InputError(f"unknown world {name!r}; expected one of {', '.join(WORLDS)}")


PAPER_POSES = {"simple": 82, "complex": 420}  # Hu et al.: poses of the simple / complex runs
OBSERVATION_MODELS = ("range-bearing", "cartesian")


def _paper_segments(name: str) -> list[tuple[int, float]]:
    """A paper world's drive: its base world's, cut or extended to the paper's pose count."""
    base = name.removeprefix("hu-")
    if base == "simple1":  # the 10 m square with the turn in each side's last step, then
        return [(19, 0.0), (1, _Q)] * 4 + [(1, 0.0)]  # one step past the start: 82 poses
    if base == "simple2":  # the 40 m circle and one step past the start
        return [(80, 2 * np.pi), (1, 0.0)]
    steps = PAPER_POSES["complex"] - 1
    legs: list[tuple[int, float]] = []
    for n, turn in _segments(base) * 2:  # cut (or re-drive) to exactly `steps` steps
        take = min(n, steps - sum(k for k, _ in legs))
        if take <= 0:
            break
        legs.append((take, turn * take / n))
    return legs


def path_of(name: str) -> NDArray[np.float64]:
    """The noise-free poses of a world's drive, shape (N, 3), starting at the origin."""
    inc = []
    if name not in WORLDS and name not in PAPER_WORLDS:
        raise InputError(
            f"unknown world {name!r}; expected one of {', '.join(WORLDS + PAPER_WORLDS)}"
        )
    for steps, turn in _paper_segments(name) if name in PAPER_WORLDS else _segments(name):
        per = turn / steps
        for _ in range(steps):
            # each step: rotate half the turn, move, rotate the other half (an arc chord)
            inc.append(se2.compose(se2.compose([0, 0, per / 2], [STEP, 0, 0]), [0, 0, per / 2]))
    return se2.cumulative_compose(np.asarray(inc))


class Observations(NamedTuple):
    """Range-bearing observations, one row each, in time order.

    Attributes
    ----------
    pose : ndarray of int, shape (K,)
        Index of the observing pose (or control step for velocity-driven worlds).
    t : ndarray, shape (K,)
    range, bearing : ndarray, shape (K,)
        Noisy measurements; bearing wrapped to ``[−π, π)``.
    landmark : ndarray of int, shape (K,)
        True landmark id (the known data association).
    """

    pose: NDArray[np.int64]
    t: NDArray[np.float64]
    range: NDArray[np.float64]
    bearing: NDArray[np.float64]
    landmark: NDArray[np.int64]


@dataclass(frozen=True)
class World:
    """A simulated world with one noise realisation.

    Attributes
    ----------
    name, noise, seed :
        What determines it.
    truth : Trajectory
        True poses ``w_T_k`` at the measurement times, shape (N, 3).
    landmarks : ndarray, shape (L, 2)
        True feature positions ``w_p_l``; landmark id = row index.
    odometry : Trajectory
        Noisy wheel odometry poses in the odometry frame (same times as ``truth``); the
        motion between consecutive rows is the odometry-model input.
    controls : ndarray, shape (K, 3) or None
        ``[t, v, ω]`` rows for velocity-driven worlds (``rate > 0``); each held until the next.
    observations : Observations
    rate : int
        Control steps per measurement step (0: odometry-driven).
    """

    name: str
    noise: str
    seed: int
    truth: Trajectory
    landmarks: NDArray[np.float64]
    odometry: Trajectory
    controls: NDArray[np.float64] | None
    observations: Observations
    rate: int
    observation_model: str = "range-bearing"

    @property
    def noise_params(self) -> NoiseType:
        return NOISE_TYPES[self.noise]

    @property
    def observation_covariance(self) -> NDArray[np.float64] | None:
        """``σ² I`` (2 × 2) for Cartesian observations, None for range-bearing ones."""
        if self.observation_model != "cartesian":
            return None
        return self.noise_params.sigma_observation**2 * np.eye(2)


def _landmarks(path: NDArray[np.float64], rng: np.random.Generator) -> NDArray[np.float64]:
    # Features scattered around points drawn uniformly along the path.
    anchor = path[rng.integers(0, path.shape[0], N_FEATURES), :2]
    return anchor + rng.normal(0.0, FEATURE_SPREAD, (N_FEATURES, 2))


def make_world(
    name: str = "simple1",
    *,
    noise: str = "a",
    seed: int = 0,
    rate: int = 0,
    dt: float = 1.0,
    observation: str | None = None,
) -> World:
    """Build a world and its noise realisation.

    Parameters
    ----------
    name : {"simple1", "simple2", "complex1", "complex2", "hu-simple1", …, "hu-complex2"}
        :data:`WORLDS` or :data:`PAPER_WORLDS`.
    noise : {"a", "b", "c"}
        Noise type of Hu et al., Table I.
    seed : int
        Determines the features and the noise.
    rate : int
        0: odometry-driven (one odometry increment per measurement step, noise on dx, dy, dθ).
        k ≥ 1: velocity-driven with k control steps per measurement step (each step's v and ω
        held for ``dt / k``), noise on v and ω chosen so that over one measurement step the
        drift matches the odometry noise type (σ_v = σ_dx √k / dt, σ_ω = σ_dθ √k / dt).
    dt : float
        Seconds between measurement steps.
    observation : {"range-bearing", "cartesian"}, optional
        Sensor noise model: ``σ_range = σ``, ``σ_bearing = σ / 2.5 m`` (default for
        :data:`WORLDS`) or the paper's ``N(0, σ² I)`` on the relative position (default for
        :data:`PAPER_WORLDS`, which also have no minimum range).
    """
    model = _check(name, noise, rate, observation)
    nt = NOISE_TYPES[noise]
    layout_rng, noise_rng = (
        np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(2)
    )
    path = path_of(name)
    landmarks = _landmarks(path, layout_rng)
    t = dt * np.arange(path.shape[0], dtype=np.float64)
    if rate == 0:
        controls, odo = None, _odometry_drive(path, nt, noise_rng)
    else:
        controls, odo = _velocity_drive(path, nt, noise_rng, rate=rate, dt=dt)
    obs = observe_field_of_view(path, landmarks, sensor_of(nt, name, model), noise_rng)
    return World(
        name=name,
        noise=noise,
        seed=seed,
        truth=Trajectory(t, path),
        landmarks=readonly(landmarks),
        odometry=Trajectory(t, odo),
        controls=None if controls is None else readonly(controls),
        observations=Observations(obs.pose, t[obs.pose], obs.range, obs.bearing, obs.landmark),
        rate=rate,
        observation_model=model,
    )


def sensor_of(noise: NoiseType, name: str, observation: str) -> FieldOfViewSensor:
    """The world's sensor: 180°, 5 m, and 0.5 m minimum range except in :data:`PAPER_WORLDS`."""
    return FieldOfViewSensor(
        noise.sigma_range,
        noise.sigma_bearing,
        max_range=SENSOR_RANGE,
        min_range=0.0 if name in PAPER_WORLDS else SENSOR_MIN_RANGE,
        fov=SENSOR_FOV,
        cartesian_sigma=noise.sigma_observation if observation == "cartesian" else None,
    )


#: The most control rows a velocity-driven world is built with: ``rate × (steps − 1)``. A row
#: costs about 0.3 kB of memory while the world, its bundle and the filter's arrays are built
#: and ~60 bytes in ``controls.csv``: ``--rate 1000000`` on simple1 (84 million rows) wrote a
#: 4.4 GB bundle with more than 7 GB of memory. At the limit (complex2, rate 2262): 0.33 GB
#: peak memory for `slamrel simulate`, a 56 MB bundle; refused, 32 MB in 0.6 s.
MAX_CONTROL_ROWS = 1_000_000


def max_rate(name: str) -> int | None:
    """The largest control rate (control steps per measurement step) world ``name`` is built
    with: :data:`MAX_CONTROL_ROWS` ``//`` its measurement steps (``None``: not a named world)."""
    if name not in WORLDS + PAPER_WORLDS:
        return None
    return MAX_CONTROL_ROWS // max(path_of(name).shape[0] - 1, 1)


def _check(name: str, noise: str, rate: int, observation: str | None) -> str:
    """The observation model to use; InputError on an unknown noise type, model or rate."""
    if noise not in NOISE_TYPES:
        raise InputError(f"unknown noise type {noise!r}; expected one of a, b, c")
    if rate < 0:
        raise InputError(f"rate must be >= 0, got {rate}")
    steps = path_of(name).shape[0] - 1 if name in WORLDS + PAPER_WORLDS else 0
    if rate * steps > MAX_CONTROL_ROWS:
        raise InputError(
            f"rate {rate}: {rate} control steps per measurement step × {steps} measurement "
            f"steps of {name} = {rate * steps} control rows, above the limit of "
            f"{MAX_CONTROL_ROWS} (the world, its bundle and the filter grow with them); "
            f"expected a rate of at most {MAX_CONTROL_ROWS // steps}"
        )
    default = "cartesian" if name in PAPER_WORLDS else "range-bearing"
    model = observation if observation is not None else default
    if model not in OBSERVATION_MODELS:
        raise InputError(
            f"unknown observation model {model!r}; expected one of {', '.join(OBSERVATION_MODELS)}"
        )
    return model


def _odometry_drive(
    path: NDArray[np.float64], nt: NoiseType, rng: np.random.Generator
) -> NDArray[np.float64]:
    """Wheel odometry: each true increment plus ``N(0, diag(σ_dx², σ_dy², σ_dθ²))``."""
    true_inc = se2.between(path[:-1], path[1:])
    sigma = [nt.sigma_dx, nt.sigma_dy, nt.sigma_dtheta]
    noisy_inc = true_inc + rng.normal(0.0, sigma, true_inc.shape)
    return se2.cumulative_compose(noisy_inc)


def _velocity_drive(
    path: NDArray[np.float64], nt: NoiseType, rng: np.random.Generator, *, rate: int, dt: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Noisy ``[t, v, ω]`` controls, ``rate`` per measurement step, and their odometry poses.

    Per measurement step, v and ω take pose k to pose k+1 along an arc (exactly, for the
    chord-arc steps of :func:`path_of`), held over ``rate`` control steps.
    """
    inc = se2.between(path[:-1], path[1:])
    omega = inc[:, 2] / dt
    # arc length of a chord of length c subtending angle φ: c φ / (2 sin(φ/2))
    chord = np.hypot(inc[:, 0], inc[:, 1])
    half = inc[:, 2] / 2
    turning = np.abs(half) > 1e-12
    arc = np.where(turning, chord * half / np.where(turning, np.sin(half), 1.0), chord)
    v = arc / dt
    h = dt / rate
    v_k = np.repeat(v, rate)
    w_k = np.repeat(omega, rate)
    sv = nt.sigma_dx * np.sqrt(rate) / dt
    sw = nt.sigma_dtheta * np.sqrt(rate) / dt
    v_meas = v_k + rng.normal(0.0, sv, v_k.size)
    w_meas = w_k + rng.normal(0.0, sw, w_k.size)
    controls = np.column_stack((h * np.arange(v_k.size), v_meas, w_meas))
    odo = se2.cumulative_compose(velocity_increment(v_meas, w_meas, h)[0])[::rate]
    return controls, odo
