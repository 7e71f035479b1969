"""A textbook EKF-SLAM client, independent of slamrel: simulator, filter, bundle exporters.

Written from the equations of Thrun, Burgard & Fox, *Probabilistic Robotics*, Tables 10.1 and
10.2 (EKF-SLAM with unknown correspondence), in the structure popular example code uses
(PythonRobotics' ``ekf_slam.py``): forward-Euler velocity motion, a 3 × 3 pose noise ``Cx``
added in the world frame each step, sequential range-bearing updates, Mahalanobis
nearest-neighbour association that opens a new landmark when no existing one is close enough.
Nothing here imports slamrel's EKF-SLAM (``slamrel/backends/ekf_slam.py``) or its recovery;
only the exporters use slamrel's bundle record and writer, to produce the files slamrel reads.

The switches reproduce the habits of such code:

* ``reuse_cx_as_r``: the measurement noise is ``Cx[0:2, 0:2]`` — a metre variance used as
  the bearing variance (PythonRobotics' ``calc_innovation``);
* ``init="improper"``: a new landmark enters with covariance ``init_variance · I``,
  uncorrelated with the pose, and is then updated with the measurement that created it
  (PythonRobotics); ``init="proper"``: Jacobian augmentation ``P_ll = G_x P_xx G_xᵀ +
  G_z R G_zᵀ``, ``P_lx = G_x P_x·`` and no second use of that measurement.

Time line: step ``k = 1..K`` moves the robot over ``(t_{k-1}, t_k]``, ``t_k = k Δt``, with
control ``u_k``; the landmarks in range are measured at ``t_k`` after the motion.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

DT = 0.1
STEPS = 500


def wrap(a: float) -> float:
    """An angle to [-π, π)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def wrap_array(a: np.ndarray) -> np.ndarray:
    """Angles to [-π, π)."""
    return (a + np.pi) % (2.0 * np.pi) - np.pi


def loop_world(inner: int = 4, outer: int = 8, radius: float = 8.0, seed: int = 0) -> np.ndarray:
    """RFID-like point landmarks around a circular loop of ``radius`` centred at (0, radius):
    ``inner`` on a ring of radius 3 m inside it, ``outer`` on a ring of 15 m outside, radii
    jittered by ±1 m with a fixed generator, (inner + outer, 2). (Rings closer to the path
    give this textbook client more ambiguous first measurements per step: loop_world was
    chosen so that seeds 0-2 are healthy runs, see benchmarks/client_recovery.py.)"""
    rng = np.random.default_rng(1000 + seed)
    ang = np.concatenate(
        (
            np.linspace(0.0, 2.0 * np.pi, inner, endpoint=False) + 0.3,
            np.linspace(0.0, 2.0 * np.pi, outer, endpoint=False) + 0.1,
        )
    )
    rad = np.concatenate((np.full(inner, 3.0), np.full(outer, 15.0)))
    rad = rad + rng.uniform(-1.0, 1.0, rad.size)
    return np.column_stack((rad * np.cos(ang), radius + rad * np.sin(ang)))


@dataclass(frozen=True)
class Config:
    """The world, the true noise and the filter's settings (PythonRobotics' defaults)."""

    dt: float = DT
    steps: int = STEPS
    v: float = 1.0  # commanded speed [m/s]
    omega: float = 2.0 * np.pi / (STEPS * DT)  # one loop in the run [rad/s]
    max_range: float = 20.0
    # true noise: on the controls the filter reads (PythonRobotics' R_sim) and the sensor (Q_sim)
    control_sigma: tuple[float, float] = (1.0, math.radians(10.0))
    range_sigma: float = 0.2
    bearing_sigma: float = math.radians(1.0)
    # the filter
    cx: tuple[float, float, float] = (0.5, 0.5, math.radians(30.0))  # pose noise std per step
    reuse_cx_as_r: bool = False
    r_sigma: tuple[float, float] | None = None  # filter's (σ_r, σ_b); None: the true ones
    init: str = "improper"  # or "proper"
    init_variance: float = 1.0
    associate_gate: float = 9.21  # d² below which the nearest landmark is taken (χ²₂ 99 %)
    new_landmark_gate: float = 9.21  # d² above which a new landmark is opened
    shuffle: bool = True  # measurements of one step in random order
    # what third-party filters do (issue 38); the defaults keep the runs above bit for bit
    mount: tuple[float, float, float] = (0.0, 0.0, 0.0)  # sensor pose in the robot frame
    motion_noise: str = "pose"  # or "control": Q = G_u M G_uᵀ, M = diag(control_sigma²)
    initial_variance: float = 1e-9  # P0 = initial_variance · I (0: start known exactly)
    dropout: float = 0.0  # share of readings the sensor reports as range 0 (skipped)

    @property
    def Cx(self) -> np.ndarray:
        return np.diag(np.square(self.cx))

    @property
    def M(self) -> np.ndarray:
        """Control noise the filter assumes with ``motion_noise="control"``: the true one."""
        return np.diag(np.square(self.control_sigma))

    def step_covariance(self) -> np.ndarray:
        """Body-frame covariance of one Euler step under ``M``: ``J M Jᵀ``,
        ``J = ∂[vΔt, 0, ωΔt]/∂(v, ω)`` (3 × 3, rank 2)."""
        j = np.array([[self.dt, 0.0], [0.0, 0.0], [0.0, self.dt]])
        return j @ self.M @ j.T

    @property
    def R(self) -> np.ndarray:
        if self.reuse_cx_as_r:
            return self.Cx[0:2, 0:2].copy()
        s = self.r_sigma or (self.range_sigma, self.bearing_sigma)
        return np.diag(np.square(s))


@dataclass
class Run:
    """What one run leaves: truth, the log, the client's estimates and associations."""

    config: Config
    landmarks: np.ndarray  # (N, 2) true positions, index = true landmark
    times: np.ndarray  # (K+1,) t_0..t_K
    truth: np.ndarray  # (K+1, 3)
    controls: np.ndarray  # (K+1, 2): row k = the noisy control of step k (row 0: zeros)
    dead_reckoning: np.ndarray  # (K+1, 3): Euler integration of the noisy controls
    online: np.ndarray  # (K+1, 3): filter mean after each step's update
    meas_t: np.ndarray  # (J,)
    meas_z: np.ndarray  # (J, 2) range, bearing
    meas_true: np.ndarray  # (J,) true landmark index
    meas_assoc: np.ndarray  # (J,) client landmark index, -1 unassociated
    meas_new: np.ndarray  # (J,) bool: opened a new landmark
    nis: np.ndarray  # (J,) NIS of updates of existing landmarks (NaN otherwise)
    x: np.ndarray  # final state
    P: np.ndarray  # final covariance
    initial_covariance: np.ndarray = field(default_factory=lambda: 1e-9 * np.eye(3))
    recorder: Any = None  # the BundleRecorder the run reported to, if any

    @property
    def n_client_landmarks(self) -> int:
        return (self.x.shape[0] - 3) // 2

    def client_map(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Final landmark means (M, 2), marginals (M, 2, 2) and joint block (2M, 2M)."""
        m = self.n_client_landmarks
        block = self.P[3:, 3:]
        block = 0.5 * (block + block.T)
        idx = np.arange(m)
        marg = block.reshape(m, 2, m, 2)[idx, :, idx, :]
        return self.x[3:].reshape(m, 2), marg, block

    def truth_of_client_landmark(self) -> np.ndarray:
        """The true landmark of each client landmark: most of its measurements' (M,)."""
        m = self.n_client_landmarks
        out = np.full(m, -1)
        a = self.meas_assoc >= 0
        for j in range(m):
            ids = self.meas_true[a & (self.meas_assoc == j)]
            out[j] = np.bincount(ids).argmax() if ids.size else -1
        return out

    def association_stats(self) -> dict[str, float]:
        """Wrong associations (against each client landmark's majority truth), duplicates."""
        truth_of = self.truth_of_client_landmark()
        a = self.meas_assoc >= 0
        wrong = truth_of[self.meas_assoc[a]] != self.meas_true[a]
        seen = np.unique(self.meas_true).size
        return {
            "measurements": int(self.meas_t.size),
            "unassociated": int((~a).sum()),
            "wrong": int(wrong.sum()),
            "error_rate": float(wrong.mean()) if wrong.size else 0.0,
            "client_landmarks": self.n_client_landmarks,
            "true_landmarks_seen": int(seen),
            "mean_nis": float(np.nanmean(self.nis)),
        }


# ------------------------------------------------------------------------------ the filter


def euler(pose: np.ndarray, u: np.ndarray, dt: float) -> np.ndarray:
    """Forward Euler of the velocity model: heading at the start of the step."""
    x, y, th = pose
    return np.array([x + u[0] * dt * math.cos(th), y + u[0] * dt * math.sin(th), th + u[1] * dt])


def predict(x: np.ndarray, P: np.ndarray, u: np.ndarray, cfg: Config) -> None:
    """Prediction in place: ``x[:3] <- euler``, ``P <- G P Gᵀ + Fxᵀ Cx Fx`` (only the pose rows
    and columns change, so ``G`` is applied to them alone)."""
    th = x[2]
    g = np.eye(3)
    g[0, 2] = -u[0] * cfg.dt * math.sin(th)
    g[1, 2] = u[0] * cfg.dt * math.cos(th)
    x[:3] = euler(x[:3], u, cfg.dt)
    x[2] = wrap(float(x[2]))
    P[:3, :] = g @ P[:3, :]
    P[:, :3] = P[:, :3] @ g.T
    if cfg.motion_noise == "control":  # Q = G_u M G_uᵀ at the heading the step starts from
        gu = np.array([[cfg.dt * math.cos(th), 0.0], [cfg.dt * math.sin(th), 0.0], [0.0, cfg.dt]])
        P[:3, :3] += gu @ cfg.M @ gu.T
    else:
        P[:3, :3] += cfg.Cx


def sensor_pose(x: np.ndarray, mount: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """The sensor's pose ``x ∘ mount`` and its Jacobian on the robot pose (3 × 3)."""
    c, s = math.cos(x[2]), math.sin(x[2])
    ox, oy = c * mount[0] - s * mount[1], s * mount[0] + c * mount[1]
    a = np.array([[1.0, 0.0, -oy], [0.0, 1.0, ox], [0.0, 0.0, 1.0]])
    return np.array([x[0] + ox, x[1] + oy, x[2] + mount[2]]), a


def expected(
    x: np.ndarray, j: int, mount: tuple[float, float, float] | None = None
) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """Predicted measurement of landmark ``j``, its Jacobian on (pose, landmark) (2 × 5), and
    the state indices of those five columns (the sensor at ``x ∘ mount``)."""
    i = 3 + 2 * j
    p, a = (x, None) if mount is None or not any(mount) else sensor_pose(x, mount)
    dx, dy = x[i] - p[0], x[i + 1] - p[1]
    q = dx * dx + dy * dy
    r = math.sqrt(q)
    zhat = np.array([r, wrap(math.atan2(dy, dx) - p[2])])
    h = np.array(
        [[-dx / r, -dy / r, 0.0, dx / r, dy / r], [dy / q, -dx / q, -1.0, -dy / q, dx / q]]
    )
    if a is not None:
        h[:, :3] = h[:, :3] @ a
    return zhat, h, [0, 1, 2, i, i + 1]


def innovation(x: np.ndarray, P: np.ndarray, z: np.ndarray, j: int, R: np.ndarray, mount=None):  # type: ignore[no-untyped-def]
    zhat, h, cols = expected(x, j, mount)
    y = z - zhat
    y[1] = wrap(float(y[1]))
    S = h @ P[np.ix_(cols, cols)] @ h.T + R
    return y, S, h, cols


def update(
    x: np.ndarray, P: np.ndarray, y: np.ndarray, S: np.ndarray, h: np.ndarray, cols: list[int]
) -> tuple[np.ndarray, np.ndarray]:
    """EKF update with a sparse H (five non-zero columns): the textbook ``P <- (I - K H) P``."""
    PHt = P[:, cols] @ h.T
    K = np.linalg.solve(S, PHt.T).T
    x = x + K @ y
    P = P - K @ PHt.T
    P = 0.5 * (P + P.T)
    x[2] = wrap(float(x[2]))
    return x, P


def associate(
    x: np.ndarray,
    P: np.ndarray,
    z: np.ndarray,
    R: np.ndarray,
    mount=None,  # type: ignore[no-untyped-def]
) -> tuple[int, float]:
    """Mahalanobis nearest neighbour: (landmark, d²), (-1, inf) in an empty map."""
    m = (x.shape[0] - 3) // 2
    if m == 0:
        return -1, math.inf
    # vectorised over all landmarks
    p, a = (x, None) if mount is None or not any(mount) else sensor_pose(x, mount)
    lm = x[3:].reshape(m, 2)
    d = lm - p[:2]
    q = (d**2).sum(axis=1)
    r = np.sqrt(q)
    zhat_b = np.arctan2(d[:, 1], d[:, 0]) - p[2]
    y = np.column_stack((z[0] - r, wrap_array(z[1] - zhat_b)))
    H = np.zeros((m, 2, 5))
    H[:, 0, 0], H[:, 0, 1], H[:, 0, 3], H[:, 0, 4] = (
        -d[:, 0] / r,
        -d[:, 1] / r,
        d[:, 0] / r,
        d[:, 1] / r,
    )
    H[:, 1, 0], H[:, 1, 1], H[:, 1, 2] = d[:, 1] / q, -d[:, 0] / q, -1.0
    H[:, 1, 3], H[:, 1, 4] = -d[:, 1] / q, d[:, 0] / q
    if a is not None:
        H[:, :, :3] = H[:, :, :3] @ a
    idx = np.arange(m)
    li = 3 + 2 * idx
    cols = np.stack([np.zeros(m, int), np.ones(m, int), np.full(m, 2), li, li + 1], axis=1)
    Pb = P[cols[:, :, None], cols[:, None, :]]  # (m, 5, 5)
    S = H @ Pb @ H.transpose(0, 2, 1) + R
    d2 = np.einsum("ni,ni->n", y, np.linalg.solve(S, y[:, :, None])[:, :, 0])
    j = int(np.argmin(d2))
    return j, float(d2[j])


def add_landmark(
    x: np.ndarray, P: np.ndarray, z: np.ndarray, cfg: Config
) -> tuple[np.ndarray, np.ndarray]:
    """Augment the state with a landmark initialised from ``z`` (improper or proper)."""
    r, b = z
    p, sa = (x, np.eye(3)) if not any(cfg.mount) else sensor_pose(x, cfg.mount)
    a = p[2] + b
    lm = np.array([p[0] + r * math.cos(a), p[1] + r * math.sin(a)])
    n = x.shape[0]
    P2 = np.zeros((n + 2, n + 2))
    P2[:n, :n] = P
    if cfg.init == "improper":
        P2[n:, n:] = cfg.init_variance * np.eye(2)
    elif cfg.init == "proper":
        gx = np.array([[1.0, 0.0, -r * math.sin(a)], [0.0, 1.0, r * math.cos(a)]]) @ sa
        gz = np.array([[math.cos(a), -r * math.sin(a)], [math.sin(a), r * math.cos(a)]])
        P2[n:, :n] = gx @ P[:3, :]
        P2[:n, n:] = P2[n:, :n].T
        P2[n:, n:] = gx @ P[:3, :3] @ gx.T + gz @ cfg.R @ gz.T
    else:
        raise ValueError(f"init: expected 'improper' or 'proper', got {cfg.init!r}")
    return np.concatenate((x, lm)), P2


def _observe(
    cfg: Config, rng: np.random.Generator, lms: np.ndarray, pose: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The landmarks within range of the sensor at ``pose ∘ mount`` and their noisy
    range-bearing readings (a ``dropout`` share reported as range 0)."""
    if any(cfg.mount):
        pose = sensor_pose(pose, cfg.mount)[0]
    d = lms - pose[:2]
    rng_true = np.hypot(d[:, 0], d[:, 1])
    seen = np.flatnonzero(rng_true <= cfg.max_range)
    if cfg.shuffle:
        seen = rng.permutation(seen)
    zs = np.column_stack(
        (
            rng_true[seen] + rng.normal(0.0, cfg.range_sigma, seen.size),
            wrap_array(np.arctan2(d[seen, 1], d[seen, 0]) - pose[2])
            + rng.normal(0.0, cfg.bearing_sigma, seen.size),
        )
    )
    if cfg.dropout > 0.0:
        zs[rng.random(seen.size) < cfg.dropout, 0] = 0.0
    return seen, zs


def run(
    seed: int,
    cfg: Config | None = None,
    landmarks: np.ndarray | None = None,
    recorder: object | None = None,
) -> Run:
    """Simulate and filter one run (numpy ``default_rng(seed)``).

    ``recorder``: a :class:`slamrel.formats.recorder.BundleRecorder` the filter reports to
    as it runs, as a user's filter would (its control per step, with the step's covariance
    under ``motion_noise="control"``; each reading with the landmark it was associated with
    or initialised, none for a dropout the filter skipped or one left between the gates;
    its own pose and covariance after each step, and before the first).
    """
    cfg = cfg or Config()
    rng = np.random.default_rng(seed)
    lms = loop_world() if landmarks is None else np.asarray(landmarks, float)
    K, dt = cfg.steps, cfg.dt
    R = cfg.R
    times = dt * np.arange(K + 1)
    truth = np.zeros((K + 1, 3))
    dr = np.zeros((K + 1, 3))
    online = np.zeros((K + 1, 3))
    controls = np.zeros((K + 1, 2))
    x = np.zeros(3)
    P = cfg.initial_variance * np.eye(3)
    rec: Any = recorder
    step_cov = cfg.step_covariance() if cfg.motion_noise == "control" else None
    if rec is not None:  # row 0 opens the log (control_stamp "end"); the start estimate
        rec.control(0.0, 0.0, 0.0, None if step_cov is None else np.zeros((3, 3)))
        rec.online(0.0, x, P)
    mt: list[float] = []
    mz: list[np.ndarray] = []
    mtrue: list[int] = []
    massoc: list[int] = []
    mnew: list[bool] = []
    mnis: list[float] = []
    u_cmd = np.array([cfg.v, cfg.omega])
    for k in range(1, K + 1):
        truth[k] = euler(truth[k - 1], u_cmd, dt)
        truth[k, 2] = wrap(float(truth[k, 2]))
        ud = u_cmd + rng.normal(0.0, cfg.control_sigma)  # what the odometry reports
        controls[k] = ud
        dr[k] = euler(dr[k - 1], ud, dt)
        seen, zs = _observe(cfg, rng, lms, truth[k])  # every landmark within range
        # the filter
        predict(x, P, ud, cfg)
        if rec is not None:
            rec.control(times[k], ud[0], ud[1], step_cov)
        mount = cfg.mount if any(cfg.mount) else None
        for i, z in zip(seen, zs):
            if z[0] <= 0.0:  # a dropout: the filter skips it (the log keeps it)
                if rec is not None:
                    rec.measurement(times[k], z[0], z[1], None)
                continue
            j, d2 = associate(x, P, z, R, mount)
            new = j < 0 or d2 > cfg.new_landmark_gate
            nis = math.nan
            if new:
                x, P = add_landmark(x, P, z, cfg)
                j = (x.shape[0] - 3) // 2 - 1
                if cfg.init == "improper":  # PythonRobotics updates with it too
                    x, P = update(x, P, *innovation(x, P, z, j, R, mount))
            elif d2 <= cfg.associate_gate:
                y, S, h, cols = innovation(x, P, z, j, R, mount)
                nis = float(y @ np.linalg.solve(S, y))
                x, P = update(x, P, y, S, h, cols)
            else:
                j = -1  # between the gates: left unassociated
            mt.append(times[k])
            mz.append(z)
            mtrue.append(int(i))
            massoc.append(j)
            mnew.append(new)
            mnis.append(nis)
            if rec is not None:
                rec.measurement(times[k], z[0], z[1], j if j >= 0 else None)
        online[k] = x[:3]
        if rec is not None:
            rec.online(times[k], x[:3], P[:3, :3])
    return Run(
        config=cfg,
        landmarks=lms,
        times=times,
        truth=truth,
        controls=controls,
        dead_reckoning=dr,
        online=online,
        meas_t=np.array(mt),
        meas_z=np.array(mz).reshape(-1, 2),
        meas_true=np.array(mtrue, dtype=int),
        meas_assoc=np.array(massoc, dtype=int),
        meas_new=np.array(mnew, dtype=bool),
        nis=np.array(mnis),
        x=x,
        P=P,
        initial_covariance=cfg.initial_variance * np.eye(3),
        recorder=rec,
    )
