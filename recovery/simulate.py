"""A small seeded simulator of bundles for tests and benchmarks (not a world generator).

A unicycle drives with velocity controls (or odometry) through landmarks scattered around
its path; the bundle's controls are the true ones minus the control noise, so the bundle's
noise model is exactly the simulated one. Measurements are taken every ``measure_every``
control steps to every landmark within ``max_range``. The map is the ground truth (with a
tiny covariance) or, with ``map_sigma``, the ground truth plus an error drawn from the stated
joint covariance ``σ_i² I + σ_c² (11ᵀ ⊗ I₂)`` (an independent part and a common offset, as
a SLAM map's landmarks share the error of the poses that saw them).
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
from relation_metric.trajectory import Trajectory

__all__ = ["simulate_bundle"]


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
    """
    rng = np.random.default_rng(seed)
    t = dt * np.arange(steps)
    v_cmd = 1.0 + 0.2 * np.sin(0.05 * np.arange(steps))
    w_cmd = 0.25 * np.sin(0.021 * np.arange(steps) + 0.3)
    if motion == "velocity":
        model = (
            MotionModel("velocity", alpha=alpha)
            if alpha
            else MotionModel("velocity", sigma=(sigma_v, sigma_omega))
        )
        m = velocity_control_covariance(v_cmd, w_cmd, sigma=model.sigma, alpha=model.alpha)
        noise = np.einsum(
            "nij,nj->ni",
            np.linalg.cholesky(m + 1e-300 * np.eye(2)),
            rng.standard_normal((steps, 2)),
        )
        u_true, _ = velocity_increment(v_cmd[:-1] + noise[:-1, 0], w_cmd[:-1] + noise[:-1, 1], dt)
        controls = np.column_stack((t, v_cmd, w_cmd))
        odometry = None
    else:
        model = (
            MotionModel("odometry", alpha=alpha)
            if alpha
            else MotionModel("odometry", sigma=sigma_odometry)
        )
        u_cmd, _ = velocity_increment(v_cmd[:-1], w_cmd[:-1], dt)
        sig = increment_covariance(model, u_cmd, np.ones(steps - 1))
        chol = np.linalg.cholesky(sig + 1e-300 * np.eye(3))
        u_true = u_cmd + np.einsum("nij,nj->ni", chol, rng.standard_normal((steps - 1, 3)))
        odo = se2.cumulative_compose(u_cmd, start=[5.0, -3.0, 0.7])
        odometry = Trajectory(t, odo)
        controls = None
    x0 = np.array([0.0, 0.0, 0.3])
    truth = se2.cumulative_compose(u_true, start=x0)

    idx = rng.integers(0, steps, landmarks)
    side = rng.normal(0.0, 4.0, (landmarks, 2))
    lm_true = truth[idx, :2] + side

    meas_k = np.arange(measure_every, steps - 1, measure_every)
    pose_k, lm_k = _visible(truth, lm_true, meas_k, max_range)
    frac = measurement_offset
    if frac:
        pose_m = se2.compose(truth[pose_k], _partial(u_true[pose_k], frac, motion))
    else:
        pose_m = truth[pose_k]
    rel = lm_true[lm_k] - pose_m[:, :2]
    dist = np.hypot(rel[:, 0], rel[:, 1])
    keep = (dist < max_range) & (dist > 0.5)
    pose_k, lm_k, pose_m, dist = pose_k[keep], lm_k[keep], pose_m[keep], dist[keep]
    bearing = np.arctan2(rel[keep, 1], rel[keep, 0]) - pose_m[:, 2]
    z = np.column_stack(
        (
            dist + sigma_range * rng.standard_normal(dist.shape[0]),
            se2.wrap_angle(bearing + sigma_bearing * rng.standard_normal(dist.shape[0])),
        ),
    )
    assoc = rng.random(dist.shape[0]) >= unassociated_fraction

    ids = np.arange(landmarks, dtype=np.int64) + 100
    if map_sigma is None:
        cov = 1e-12 * np.eye(2 * landmarks)
        map_xy = lm_true.copy()
    else:
        si, sc = map_sigma
        cov = si**2 * np.eye(2 * landmarks) + sc**2 * np.kron(
            np.ones((landmarks, landmarks)), np.eye(2)
        )
        map_xy = lm_true + (np.linalg.cholesky(cov) @ rng.standard_normal(2 * landmarks)).reshape(
            -1, 2
        )
    marg = np.stack([cov[2 * i : 2 * i + 2, 2 * i : 2 * i + 2] for i in range(landmarks)])
    return Bundle(
        motion=model,
        sensor=SensorModel(sigma_range, sigma_bearing),
        initial_pose=x0,
        initial_covariance=1e-8 * np.eye(3),
        controls=controls,
        odometry=odometry,
        measurement_times=t[pose_k] + frac * dt,
        measurements=z,
        measurement_landmarks=ids[lm_k],
        measurement_associated=assoc,
        map_ids=ids,
        map_xy=map_xy,
        map_marginals=marg,
        map_covariance=cov if map_covariance else None,
        groundtruth=Trajectory(t, truth),
        landmarks_groundtruth=(ids, lm_true),
        description=f"recovery.simulate seed={seed}",
    )


def _visible(truth: np.ndarray, lm: np.ndarray, meas_k: np.ndarray, max_range: float):  # type: ignore[no-untyped-def]
    """(pose, landmark) pairs within ``max_range`` (+1 m margin), in chunks of poses."""
    ks, ls = [], []
    chunk = max(1, 2_000_000 // max(lm.shape[0], 1))
    for start in range(0, meas_k.shape[0], chunk):
        k = meas_k[start : start + chunk]
        d = np.hypot(lm[None, :, 0] - truth[k, None, 0], lm[None, :, 1] - truth[k, None, 1])
        i, j = np.nonzero(d < max_range + 1.0)
        ks.append(k[i])
        ls.append(j)
    return np.concatenate(ks), np.concatenate(ls)


def _partial(u: np.ndarray, frac: float, motion: str) -> np.ndarray:
    """The first ``frac`` of each increment (constant twist)."""
    return se2.exp(frac * se2.log(u))
