"""Result bundles that are healthy *by construction*: the runs on which the recovery must be
consistent, and the healthy half of the verdict's calibration (:mod:`slamrel.studies.calibration`).

A healthy bundle is what a correct SLAM run with exact models could have left behind, built
so that every number in it is true to its stated statistics:

* the log (odometry, range-bearing measurements) and ground truth of a simulated world
  (:func:`slamrel.simulation.worlds.make_world`, odometry-driven, noise type ``a``), whose
  noise the bundle's models state exactly (:func:`slamrel.simulation.bundles.world_bundle`);
* the true data associations (every measurement, its true landmark);
* a map of the landmarks the log sees: the true positions plus an error drawn from exactly
  the map covariance the bundle states, from a random stream independent of the log's noise.

The truth frame is the map frame: ground truth and true landmarks stay where the world put
them and the map's anchoring error (its common-mode translation and rotation) is part of its
drawn error; the initial pose is the true start with the world's ``1e-9 I`` covariance.

Two forms of stated map covariance (:data:`FORMS`):

``joint``
    A correlated SPD ``(2M, 2M)`` matrix such as an EKF-SLAM map has (:func:`joint_covariance`):
    a common-mode rigid part (translation, and a small rotation about the map's centroid),
    a smooth spatially correlated part (squared-exponential kernel over landmark distance)
    and a small independent part; stored as ``map_covariance``, its 2 × 2 diagonal blocks as
    ``map_marginals``.
``marginal``
    Independent landmarks: a block-diagonal covariance with a random anisotropic 2 × 2 block
    per landmark (:func:`marginal_covariance`), given only as ``map_marginals``
    (``map_covariance`` is None). The error is drawn block by block from exactly those.

``error_scale`` multiplies the drawn error (not the stated covariance): 1 is healthy, 3 is
the control of the tests (a map three times worse than it says).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from recovery.bundle import Bundle
from recovery.models import MotionModel
from relation_metric import se2
from relation_metric.trajectory import Trajectory
from slamrel.simulation.bundles import world_bundle
from slamrel.simulation.worlds import make_world

__all__ = [
    "FORMS",
    "JOINT_PARAMS",
    "ODOMETRY_SIGMA",
    "MARGINAL_STD",
    "healthy_bundle",
    "healthy_bundles",
    "joint_covariance",
    "marginal_covariance",
]

#: The forms of stated map covariance (see the module doc).
FORMS = ("joint", "marginal")

#: The joint covariance's parts: common-mode translation std [m] and rotation std [rad]
#: about the centroid, the smooth part's std [m] and length scale [m], the independent std [m].
#: Per-coordinate landmark std ≈ 0.15–0.2 m: above the sensor's footprint (σ_range 0.1 m,
#: σ_bearing 0.04 rad, i.e. ~0.1 m cross-range at 2.5 m).
JOINT_PARAMS = {
    "translation": 0.10,
    "rotation": 0.01,
    "smooth": 0.10,
    "length": 5.0,
    "independent": 0.05,
}
#: Range of the per-landmark principal standard deviations of the marginal form [m].
MARGINAL_STD = (0.05, 0.25)

#: Wheel odometry noise per 0.5 m step [m, m, rad] of the healthy bundles: a good odometry
#: (4 % of the step, 0.3° a step), so that the map, not the odometry, bounds the pose error
#: and a recovery that mistakes the map's persistent error for fresh noise shows it.
ODOMETRY_SIGMA = (0.02, 0.02, 0.005)

#: Seed offset of the map's random stream (independent of the world's seed streams).
_MAP_STREAM = 0x5EED_0023
_ODO_STREAM = 0x0D0_0023


def joint_covariance(xy: np.ndarray, **params: float) -> np.ndarray:
    """A realistic correlated map covariance ``(2M, 2M)`` over landmark positions ``xy``.

    ``G diag(σ_t², σ_t², σ_r²) Gᵀ`` (rigid: ``δp_i = t + φ J (p_i − c)``, ``J`` the quarter
    turn, ``c`` the centroid) ``+ K ⊗ I₂`` (``K_ij = σ_s² exp(−d_ij² / 2ℓ²)``) ``+ σ_i² I``.
    Parameters default to :data:`JOINT_PARAMS`.
    """
    p = {**JOINT_PARAMS, **params}
    xy = np.asarray(xy, dtype=np.float64)
    m = xy.shape[0]
    rel = xy - xy.mean(axis=0)
    g = np.zeros((m, 2, 3))
    g[:, 0, 0] = g[:, 1, 1] = 1.0
    g[:, 0, 2] = -rel[:, 1]
    g[:, 1, 2] = rel[:, 0]
    g2 = g.reshape(2 * m, 3)
    rigid = g2 @ np.diag([p["translation"] ** 2, p["translation"] ** 2, p["rotation"] ** 2]) @ g2.T
    d2 = np.sum((xy[:, None, :] - xy[None, :, :]) ** 2, axis=-1)
    smooth = np.kron(p["smooth"] ** 2 * np.exp(-d2 / (2.0 * p["length"] ** 2)), np.eye(2))
    cov = rigid + smooth + p["independent"] ** 2 * np.eye(2 * m)
    return 0.5 * (cov + cov.T)


def marginal_covariance(m: int, rng: np.random.Generator) -> np.ndarray:
    """``(M, 2, 2)`` random anisotropic SPD blocks, principal stds in :data:`MARGINAL_STD`."""
    std = rng.uniform(*MARGINAL_STD, (m, 2))
    ang = rng.uniform(0.0, np.pi, m)
    c, s = np.cos(ang), np.sin(ang)
    rot = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)
    return np.einsum("mij,mj,mkj->mik", rot, std**2, rot)


def _redraw_odometry(
    log: Bundle, sigma: tuple[float, float, float], rng: np.random.Generator
) -> Bundle:
    """``log`` with odometry ``true increment + N(0, diag σ²)`` a step, its model stating σ."""
    assert log.groundtruth is not None and log.odometry is not None
    truth = log.groundtruth.poses
    inc = se2.between(truth[:-1], truth[1:])
    noisy = inc + rng.normal(0.0, sigma, inc.shape)
    return replace(
        log,
        motion=MotionModel("odometry", sigma=tuple(float(v) for v in sigma)),
        odometry=Trajectory(log.odometry.timestamps, se2.cumulative_compose(noisy)),
    )


def _blocks(cov: np.ndarray) -> np.ndarray:
    """The 2 × 2 diagonal blocks of a ``(2M, 2M)`` matrix, shape (M, 2, 2)."""
    m = cov.shape[0] // 2
    return cov.reshape(m, 2, m, 2)[np.arange(m), :, np.arange(m), :].copy()


def healthy_bundle(
    world: str,
    seed: int,
    form: str,
    *,
    error_scale: float = 1.0,
    noise: str = "a",
    odometry: tuple[float, float, float] | None = ODOMETRY_SIGMA,
) -> Bundle:
    """One healthy-by-construction result bundle (module doc), in memory.

    Parameters
    ----------
    world : str
        One of :data:`slamrel.constants.WORLDS`.
    seed : int
        The world's seed (layout and log noise) and, through an independent stream, the map's.
    form : {"joint", "marginal"}
    error_scale : float
        The drawn map error is ``error_scale`` times a draw from the stated covariance.
    noise : str
        The world's noise type (its sensor noise; its odometry noise unless ``odometry``).
    odometry : (σ_x, σ_y, σ_θ), optional
        Re-draw the wheel odometry with this noise per step (from the true increments, an
        independent stream; the bundle states it): default :data:`ODOMETRY_SIGMA`. ``None``
        keeps the world's odometry (noise type ``a``: 0.1 m, 0.1 m, 0.05 rad a 0.5 m step).
    """
    if form not in FORMS:
        raise ValueError(f"form must be one of {FORMS}, got {form!r}")
    log = world_bundle(make_world(world, noise=noise, seed=seed))
    if odometry is not None:
        log = _redraw_odometry(log, odometry, np.random.default_rng([_ODO_STREAM, seed]))
    # the map holds the landmarks the log sees (as an EKF-SLAM map does), in id order
    ids = np.unique(log.measurement_landmarks[log.measurement_associated])
    gt_ids, gt_xy = log.landmarks_groundtruth  # type: ignore[misc]
    true_xy = gt_xy[np.searchsorted(gt_ids, ids)]
    m = ids.size
    rng = np.random.default_rng([_MAP_STREAM, seed, FORMS.index(form)])
    if form == "joint":
        cov = joint_covariance(true_xy)
        err = (np.linalg.cholesky(cov) @ rng.standard_normal(2 * m)).reshape(m, 2)
        marg, joint = _blocks(cov), cov
    else:
        marg = marginal_covariance(m, rng)
        err = np.einsum("mij,mj->mi", np.linalg.cholesky(marg), rng.standard_normal((m, 2)))
        joint = None
    return replace(
        log,
        map_ids=ids,
        map_xy=true_xy + error_scale * err,
        map_marginals=marg,
        map_covariance=joint,
        map_source="independent",  # its error drawn apart from the log's noise
        landmarks_groundtruth=(ids, true_xy),
        description=(
            f"healthy by construction: world {world}, noise {noise}, seed {seed}, map form "
            f"{form}, map error drawn {error_scale:g} x the stated covariance"
        ),
    )


def healthy_bundles(
    worlds: tuple[str, ...], seeds: tuple[int, ...], forms: tuple[str, ...] = FORMS, **kw: float
) -> dict[tuple[str, int, str], Bundle]:
    """:func:`healthy_bundle` for every ``(world, seed, form)``."""
    return {
        (w, s, f): healthy_bundle(w, s, f, **kw)  # type: ignore[arg-type]
        for w in worlds
        for s in seeds
        for f in forms
    }
