"""A world in which the posterior of SLAM is exact: slamrel's models in their linear limit.

The question this world answers is what a recovery's stated covariance *should* be when the
map was made from the very log the recovery reads again (an EKF-SLAM's final map). Its answer
needs a world where the joint posterior of all poses and landmarks given the log is known
exactly and the EKF-SLAM is a Kalman filter. A world with linear models (``x_{k+1} = x_k + u_k
+ w``, ``z = l − x + v``) is one, but slamrel's filters, smoother and SLAM speak only the
SE(2) odometry model and the range-bearing sensor. So this world keeps those models and makes
them linear instead: with every noise ``σ`` tiny against the ranges ``r`` (metres against
tenths of a millimetre), each model equals its first-order expansion about the truth to a
relative ``O(σ / r)`` (here about 1e-5), the EKF-SLAM is the Kalman filter of that linear model
to the same order, and the posterior is the Gaussian of the information matrix ``Jᵀ W J`` at
the truth (:func:`exact_posterior`), the prior on the first pose included and landmarks without
a prior (EKF-SLAM initialises a landmark from its first sighting). Every ratio of covariances
is independent of the noise's scale, so the small noise loses nothing but the nonlinearity.

The path is a circle through a field of landmarks, each seen within :data:`SENSOR_RANGE` by
every pose, with known associations; the bundle is a log bundle (map = the true landmarks with
zero covariance) for :func:`slamrel.backends.ekf_slam.ekf_slam_bundle`.

:func:`exact_posterior` builds the oracle with its own Jacobians, dense, from the log and the
truth alone: nothing of :mod:`recovery` enters it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from recovery.bundle import Bundle
from recovery.models import MotionModel, SensorModel
from relation_metric import se2
from relation_metric.arrays import Array
from relation_metric.trajectory import Trajectory

__all__ = [
    "SENSOR_RANGE",
    "ExactPosterior",
    "exact_posterior",
    "linear_world",
]

#: The sensor's reach [m]: each landmark is seen from part of the circle only.
SENSOR_RANGE = 7.0
#: Radius of the circle the robot drives [m].
RADIUS = 6.0
#: Standard deviations at ``scale = 1``: odometry per step ``[x, y, θ]`` [m, m, rad] and the
#: sensor's range [m] and bearing [rad] — the proportions of slamrel's simulated worlds.
ODOMETRY_SIGMA = (0.02, 0.02, 0.005)
SENSOR_SIGMA = (0.1, 0.04)
#: The default scale of every noise: ``σ / r`` about 1e-5, the models linear to that order.
SCALE = 1e-3


def linear_world(
    seed: int, *, poses: int = 50, landmarks: int = 10, scale: float = SCALE
) -> Bundle:
    """A log bundle of the linear-limit world (module doc), ground truth included.

    Parameters
    ----------
    seed : int
        Seeds the landmark field and every noise draw.
    poses : int
        Poses on the circle (one odometry step and one scan each).
    landmarks : int
        Landmarks, uniform in the square around the circle.
    scale : float
        Every standard deviation is :data:`ODOMETRY_SIGMA` / :data:`SENSOR_SIGMA` times it.

    Returns
    -------
    Bundle
        Odometry model with ``σ = scale · ODOMETRY_SIGMA``, range-bearing sensor with
        ``σ = scale · SENSOR_SIGMA``, start pose exact (covariance ``(1e-6 scale)² I``),
        measurements at every pose of every landmark within :data:`SENSOR_RANGE`, true
        associations; map = the true landmarks (a log bundle).
    """
    rng = np.random.default_rng(seed)
    lm = rng.uniform(-RADIUS - 3.0, RADIUS + 3.0, size=(landmarks, 2))
    phi = np.linspace(0.0, 2.0 * np.pi, poses, endpoint=False)
    nominal = np.column_stack(
        (RADIUS * np.cos(phi), RADIUS * np.sin(phi), se2.wrap_angle(phi + np.pi / 2))
    )
    step = se2.between(nominal[:-1], nominal[1:])  # the commanded body-frame increments
    sig_o = scale * np.asarray(ODOMETRY_SIGMA)
    sig_z = scale * np.asarray(SENSOR_SIGMA)
    noise = rng.normal(size=(poses - 1, 3)) * sig_o
    truth = se2.cumulative_compose(step + noise, nominal[0])  # x_{k+1} = x_k ∘ (u_k + n_k)
    odo = se2.cumulative_compose(step, nominal[0])
    times = np.arange(poses, dtype=np.float64)
    d = lm[None, :, :] - truth[:, None, :2]  # (N, M, 2)
    rng_true = np.hypot(d[..., 0], d[..., 1])
    k_idx, l_idx = np.nonzero(rng_true <= SENSOR_RANGE)
    z = np.column_stack(
        (
            rng_true[k_idx, l_idx],
            np.arctan2(d[k_idx, l_idx, 1], d[k_idx, l_idx, 0]) - truth[k_idx, 2],
        )
    )
    z += rng.normal(size=z.shape) * sig_z
    z[:, 1] = se2.wrap_angle(z[:, 1])
    ids = np.arange(landmarks, dtype=np.int64)
    return Bundle(
        motion=MotionModel("odometry", sigma=tuple(float(s) for s in sig_o)),
        sensor=SensorModel(float(sig_z[0]), float(sig_z[1]), max_range=SENSOR_RANGE),
        measurement_times=times[k_idx],
        measurements=z,
        measurement_landmarks=l_idx.astype(np.int64),
        measurement_associated=np.ones(k_idx.shape[0], dtype=bool),
        map_ids=ids,
        map_xy=lm,
        map_marginals=np.zeros((landmarks, 2, 2)),
        initial_pose=truth[0],
        initial_covariance=(1e-6 * scale) ** 2 * np.eye(3),
        groundtruth=Trajectory(times, truth),
        landmarks_groundtruth=(ids, lm),
        odometry=Trajectory(times, odo),
        description=f"slamrel linear-limit world, seed {seed}, noise scale {scale:g}",
    )


@dataclass(frozen=True)
class ExactPosterior:
    """The Gaussian posterior of all poses and landmarks given the log (module doc).

    Attributes
    ----------
    information : ndarray, shape (3N + 2M, 3N + 2M)
        ``Jᵀ W J`` at the truth: poses ``[x, y, θ]`` first (grid order), then the landmarks
        ``[x, y]`` in ``landmark_ids`` order.
    mean : ndarray, shape (3N + 2M,)
        The posterior mean: one Gauss–Newton step from the truth, ``truth + (Jᵀ W J)⁻¹ Jᵀ W r``
        (exact for the linear model; headings not wrapped).
    covariance : ndarray, shape (3N + 2M, 3N + 2M)
        Its inverse.
    landmark_ids : ndarray of int, shape (M,)
    poses : int
        ``N``.
    """

    information: Array
    mean: Array
    covariance: Array
    landmark_ids: Array
    poses: int

    def pose_means(self) -> Array:
        """The poses' posterior means, (N, 3) (headings not wrapped)."""
        return np.asarray(self.mean[: 3 * self.poses].reshape(-1, 3))

    def pose_covariances(self) -> Array:
        """Each pose's marginal covariance given the log, (N, 3, 3): the oracle."""
        n = self.poses
        blocks = self.covariance[: 3 * n, : 3 * n].reshape(n, 3, n, 3)
        return np.asarray(blocks[np.arange(n), :, np.arange(n), :])

    def map_covariance(self) -> Array:
        """The landmarks' joint covariance given the log, (2M, 2M)."""
        return np.asarray(self.covariance[3 * self.poses :, 3 * self.poses :])

    def blocks(self) -> tuple[Array, Array, Array]:
        """``A`` (3N, 3N), ``B`` (3N, 2M), ``D`` (2M, 2M): the poses', cross and map blocks of
        the information."""
        n3 = 3 * self.poses
        h = self.information
        return h[:n3, :n3], h[:n3, n3:], h[n3:, n3:]


def exact_posterior(bundle: Bundle, landmark_ids: Array | None = None) -> ExactPosterior:
    """The oracle of a :func:`linear_world` log: ``Jᵀ W J`` of its factors at the truth.

    Factors: the prior ``x_0 ~ N(x̄_0, P_0)``; one per odometry step,
    ``between(x_k, x_{k+1}) − u_k ~ N(0, diag σ²)`` with ``between(a, b) = R(θ_a)ᵀ (p_b − p_a),
    θ_b − θ_a``; one per measurement, ``z − [‖l − p‖, atan2(l − p) − θ] ~ N(0, diag σ²)``.
    Jacobians written out here (not :mod:`recovery.models`'), dense.

    Parameters
    ----------
    bundle : Bundle
        A :func:`linear_world` bundle (odometry and measurements at the same times, ground
        truth and true landmarks given).
    landmark_ids : array of int, optional
        The landmarks' order in the state (default the bundle's ``map_ids``): a SLAM result's
        map order, to compare with its covariance.
    """
    assert bundle.groundtruth is not None and bundle.landmarks_groundtruth is not None
    assert bundle.odometry is not None and bundle.motion.sigma is not None
    x = bundle.groundtruth.poses
    n = x.shape[0]
    ids = bundle.map_ids if landmark_ids is None else np.asarray(landmark_ids)
    true_ids, true_xy = bundle.landmarks_groundtruth
    row = {int(i): r for r, i in enumerate(true_ids.tolist())}
    lm = true_xy[[row[int(i)] for i in ids.tolist()]]
    m = ids.shape[0]
    size = 3 * n + 2 * m
    info = np.zeros((size, size))
    info[:3, :3] += np.linalg.inv(bundle.initial_covariance)
    grad = np.zeros(size)  # Jᵀ W r, r = observed − predicted at the truth
    r0 = bundle.initial_pose - x[0]
    r0[2] = se2.wrap_angle(r0[2])
    grad[:3] += info[:3, :3] @ r0
    r_odo = se2.between(bundle.odometry.poses[:-1], bundle.odometry.poses[1:])
    r_odo = r_odo - se2.between(x[:-1], x[1:])
    r_odo[:, 2] = se2.wrap_angle(r_odo[:, 2])
    w_odo = np.diag(1.0 / np.square(bundle.motion.sigma))
    c, s = np.cos(x[:-1, 2]), np.sin(x[:-1, 2])
    dp = x[1:, :2] - x[:-1, :2]
    for k in range(n - 1):  # ~50 dense 6 × 6 blocks: a loop is clearer than the scatter
        rt = np.array([[c[k], s[k]], [-s[k], c[k]]])  # R(θ_k)ᵀ
        d_rt = np.array([[-s[k], c[k]], [-c[k], -s[k]]])  # ∂R(θ_k)ᵀ/∂θ_k
        j = np.zeros((3, 6))
        j[:2, :2] = -rt
        j[:2, 2] = d_rt @ dp[k]
        j[2, 2] = -1.0
        j[:2, 3:5] = rt
        j[2, 5] = 1.0
        rows = np.r_[3 * k : 3 * k + 6]
        info[np.ix_(rows, rows)] += j.T @ w_odo @ j
        grad[rows] += j.T @ w_odo @ r_odo[k]
    w_z = np.diag(1.0 / np.square([bundle.sensor.sigma_range, bundle.sensor.sigma_bearing]))
    k_of = np.searchsorted(bundle.groundtruth.timestamps, bundle.measurement_times)
    col = {int(i): r for r, i in enumerate(ids.tolist())}
    l_of = [col[int(i)] for i in bundle.measurement_landmarks.tolist()]
    for k, li, z in zip(k_of.tolist(), l_of, bundle.measurements):
        d = lm[li] - x[k, :2]
        q = float(d @ d)
        r = np.sqrt(q)
        h_l = np.array([[d[0] / r, d[1] / r], [-d[1] / q, d[0] / q]])
        j = np.zeros((2, 5))
        j[:, :2] = -h_l
        j[1, 2] = -1.0
        j[:, 3:] = h_l
        rows = np.r_[3 * k : 3 * k + 3, 3 * n + 2 * li : 3 * n + 2 * li + 2]
        info[np.ix_(rows, rows)] += j.T @ w_z @ j
        rz = z - np.array([r, np.arctan2(d[1], d[0]) - x[k, 2]])
        rz[1] = se2.wrap_angle(rz[1])
        grad[rows] += j.T @ w_z @ rz
    info = 0.5 * (info + info.T)
    cov = np.asarray(np.linalg.inv(info), dtype=np.float64)
    return ExactPosterior(
        information=info,
        mean=np.concatenate((x.ravel(), lm.ravel())) + cov @ grad,
        covariance=cov,
        landmark_ids=np.asarray(ids),
        poses=n,
    )
