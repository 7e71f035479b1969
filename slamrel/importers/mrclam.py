"""UTIAS Multi-Robot Cooperative Localization and Mapping (MRCLAM) datasets.

Leung, Halpern, Barfoot, Liu, "The UTIAS Multi-Robot Cooperative Localization and Mapping
Dataset", IJRR 2011. A dataset directory holds, per robot N, ``RobotN_Odometry.dat``
(``time v ω``), ``RobotN_Measurement.dat`` (``time barcode range bearing``),
``RobotN_Groundtruth.dat`` (``time x y θ``, Vicon), and ``Barcodes.dat`` (``subject
barcode``), ``Landmark_Groundtruth.dat`` (``subject x y σx σy``). Subjects 1–5 are the
robots, the others landmarks. ``#`` lines are headers; tabs and spaces separate fields.

Measurements are mapped from barcodes to subjects; sightings of robots are counted and left
out of landmark SLAM; barcodes that are in no table are counted and left out. Nothing is
dropped without being counted in :class:`MrclamRobot`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from relation_metric import se2
from relation_metric.errors import InputError
from relation_metric.textio import PathLike, RowLines, read_numeric_table
from relation_metric.trajectory import Trajectory, readonly

__all__ = ["MrclamRobot", "NoiseFit", "fit_noise", "read_mrclam_robot", "read_barcodes", "N_ROBOTS"]

N_ROBOTS = 5


@dataclass(frozen=True)
class MrclamRobot:
    """One robot's logs, ready for landmark SLAM.

    Attributes
    ----------
    robot : int
    controls : ndarray, shape (K, 3)
        ``[t, v, ω]``, each held until the next row (velocity-model input).
    measurements : ndarray, shape (M, 4)
        ``[t, range, bearing, subject]`` of landmark sightings only.
    groundtruth : Trajectory
    robot_sightings : int
        Measurements of other robots (subjects 1–5), left out.
    unknown_barcodes : dict of int → int
        Barcodes in no table, with their counts, left out.
    """

    robot: int
    controls: NDArray[np.float64]
    measurements: NDArray[np.float64]
    groundtruth: Trajectory
    robot_sightings: int
    unknown_barcodes: dict[int, int]


def _check_times(path: Path, t: NDArray[np.float64], lines: RowLines) -> None:
    back = np.flatnonzero(np.diff(t) < 0)
    if back.size:
        k = int(back[0]) + 1
        raise InputError(
            f"time goes backwards: {t[k]!r} after {t[k - 1]!r}", path=path, line=lines(k)
        )


def read_barcodes(directory: PathLike) -> dict[int, int]:
    """``barcode → subject`` from ``Barcodes.dat``."""
    path = Path(directory) / "Barcodes.dat"
    values, lines = read_numeric_table(
        path, columns=("subject", "barcode"), describe="Barcodes.dat"
    )
    codes = values[:, 1].astype(np.int64)
    uniq, counts = np.unique(codes, return_counts=True)
    if (counts > 1).any():
        dup = int(uniq[counts > 1][0])
        k = int(np.flatnonzero(codes == dup)[1])
        raise InputError(f"barcode {dup} is given twice", path=path, line=lines(k))
    return dict(zip(codes.tolist(), values[:, 0].astype(np.int64).tolist()))


def read_mrclam_robot(directory: PathLike, robot: int) -> MrclamRobot:
    """Read robot ``robot`` (1–5) of an MRCLAM dataset directory."""
    d = Path(directory)
    if not d.is_dir():
        raise InputError("not a directory; expected an MRCLAM dataset folder", path=d)
    if not 1 <= robot <= N_ROBOTS:
        raise InputError(f"robot must be 1..{N_ROBOTS}, got {robot}", path=d)
    barcodes = read_barcodes(d)
    odo_path = d / f"Robot{robot}_Odometry.dat"
    odo, odo_lines = read_numeric_table(
        odo_path, columns=("time", "v", "omega"), describe="MRCLAM odometry"
    )
    _check_times(odo_path, odo[:, 0], odo_lines)
    meas_path = d / f"Robot{robot}_Measurement.dat"
    meas, meas_lines = read_numeric_table(
        meas_path, columns=("time", "barcode", "range", "bearing"), describe="MRCLAM measurements"
    )
    _check_times(meas_path, meas[:, 0], meas_lines)
    gt_path = d / f"Robot{robot}_Groundtruth.dat"
    gt, gt_lines = read_numeric_table(
        gt_path, columns=("time", "x", "y", "theta"), describe="MRCLAM ground truth"
    )
    _check_times(gt_path, gt[:, 0], gt_lines)
    code = meas[:, 1].astype(np.int64)
    if np.any(meas[:, 1] != code):
        k = int(np.flatnonzero(meas[:, 1] != code)[0])
        raise InputError("barcode must be an integer", path=meas_path, line=meas_lines(k))
    table_codes = np.fromiter(barcodes.keys(), dtype=np.int64)
    table_subjects = np.fromiter(barcodes.values(), dtype=np.int64)
    order = np.argsort(table_codes)
    pos = np.clip(np.searchsorted(table_codes[order], code), 0, table_codes.size - 1)
    known = table_codes[order][pos] == code
    subject = np.where(known, table_subjects[order][pos], -1)
    is_robot = known & (subject <= N_ROBOTS)
    landmark = known & ~is_robot
    unknown_codes, unknown_counts = np.unique(code[~known], return_counts=True)
    measurements = np.column_stack(
        (meas[landmark, 0], meas[landmark, 2], meas[landmark, 3], subject[landmark])
    )
    return MrclamRobot(
        robot=robot,
        controls=readonly(odo),
        measurements=readonly(measurements),
        groundtruth=Trajectory(gt[:, 0], gt[:, 1:4]),
        robot_sightings=int(is_robot.sum()),
        unknown_barcodes=dict(zip(unknown_codes.tolist(), unknown_counts.tolist())),
    )


@dataclass(frozen=True)
class NoiseFit:
    """Noise parameters fitted from one robot's logs against its ground truth.

    Attributes
    ----------
    sigma_v, sigma_omega : float
        Per-row standard deviations of the velocity-model controls (BUNDLE.md ``velocity``
        model), from odometry vs. ground-truth motion over ``window`` seconds.
    bias_v, bias_omega : float
        Mean control errors (reported, not modelled).
    sigma_range, sigma_bearing : float
        Robust (1.4826 · MAD) standard deviations of measurement residuals against the
        ground truth; ``outlier_fraction`` of the residuals lie beyond 5 σ.
    window : float
    """

    sigma_v: float
    sigma_omega: float
    bias_v: float
    bias_omega: float
    sigma_range: float
    sigma_bearing: float
    outlier_fraction: float
    window: float


def _interp_poses(gt: Trajectory, t: NDArray[np.float64]) -> NDArray[np.float64]:
    """Ground-truth poses at times ``t`` (linear in x, y; shortest-arc in θ)."""
    x = np.interp(t, gt.timestamps, gt.poses[:, 0])
    y = np.interp(t, gt.timestamps, gt.poses[:, 1])
    th = np.interp(t, gt.timestamps, np.unwrap(gt.poses[:, 2]))
    return np.column_stack((x, y, se2.wrap_angle(th)))


def fit_noise(
    robot: MrclamRobot, landmarks: NDArray[np.float64], *, window: float = 1.0
) -> NoiseFit:
    """Fit velocity-model and range-bearing noise from data (how, in :class:`NoiseFit`).

    Controls: over consecutive windows of ``window`` seconds inside the ground truth's time
    span, the travelled distance ``Σ v_k dt_k`` and turn ``Σ ω_k dt_k`` of the odometry are
    compared with the ground truth's path length and heading change. With independent
    per-row errors held over ``dt_k``, ``Var(window error) = σ² Σ dt_k²``, so
    ``σ² = Var / mean(Σ dt_k²)``.

    Measurements: each landmark measurement against the range and bearing predicted from
    the interpolated ground-truth pose and the surveyed landmark (``landmarks``: rows
    ``[subject, x, y]``).
    """
    c = robot.controls
    gt = robot.groundtruth
    t = c[:, 0]
    dt = np.diff(t, append=t[-1])
    inside = (t >= gt.timestamps[0]) & (t + dt <= gt.timestamps[-1])
    w_id = np.floor((t - t[0]) / window).astype(np.int64)
    w_id = np.where(inside, w_id, -1)
    keep = w_id >= 0
    nw = int(w_id.max()) + 1 if keep.any() else 0
    dist = np.bincount(w_id[keep], weights=(c[:, 1] * dt)[keep], minlength=nw)
    turn = np.bincount(w_id[keep], weights=(c[:, 2] * dt)[keep], minlength=nw)
    dt2 = np.bincount(w_id[keep], weights=(dt * dt)[keep], minlength=nw)
    t0 = np.full(nw, np.inf)
    t1 = np.full(nw, -np.inf)
    np.minimum.at(t0, w_id[keep], t[keep])
    np.maximum.at(t1, w_id[keep], (t + dt)[keep])
    ok = np.isfinite(t0) & (dt2 > 0)
    # ground-truth path length and heading change over [t0, t1] of each window, sampled
    # at the ground truth's own rate
    s_gt = gt.path_length()
    th_gt = np.unwrap(gt.poses[:, 2])
    true_dist = np.interp(t1[ok], gt.timestamps, s_gt) - np.interp(t0[ok], gt.timestamps, s_gt)
    true_turn = np.interp(t1[ok], gt.timestamps, th_gt) - np.interp(t0[ok], gt.timestamps, th_gt)
    e_d = np.abs(dist[ok]) - true_dist  # odometry speed is signed; path length is not
    e_t = turn[ok] - true_turn
    mdt2 = float(np.mean(dt2[ok]))
    sigma_v = float(np.sqrt(np.var(e_d) / mdt2))
    sigma_w = float(np.sqrt(np.var(e_t) / mdt2))
    # measurements
    m = robot.measurements
    subj = landmarks[:, 0].astype(np.int64)
    order = np.argsort(subj)
    pos = np.clip(np.searchsorted(subj[order], m[:, 3].astype(np.int64)), 0, subj.size - 1)
    known = subj[order][pos] == m[:, 3].astype(np.int64)
    in_gt = (m[:, 0] >= gt.timestamps[0]) & (m[:, 0] <= gt.timestamps[-1])
    use = known & in_gt
    poses = _interp_poses(gt, m[use, 0])
    lm_xy = landmarks[order][pos[use], 1:3]
    k_p_l = se2.inverse_transform_points(poses, lm_xy)
    r_res = m[use, 1] - np.hypot(k_p_l[:, 0], k_p_l[:, 1])
    b_res = se2.wrap_angle(m[use, 2] - np.arctan2(k_p_l[:, 1], k_p_l[:, 0]))

    def robust(x: NDArray[np.float64]) -> float:
        return float(1.4826 * np.median(np.abs(x - np.median(x))))

    sr, sb = robust(r_res), robust(b_res)
    out = (np.abs(r_res - np.median(r_res)) > 5 * sr) | (np.abs(b_res - np.median(b_res)) > 5 * sb)
    return NoiseFit(
        sigma_v=sigma_v,
        sigma_omega=sigma_w,
        bias_v=float(np.mean(e_d) / np.mean(np.bincount(w_id[keep], weights=dt[keep])[ok])),
        bias_omega=float(np.mean(e_t) / np.mean(np.bincount(w_id[keep], weights=dt[keep])[ok])),
        sigma_range=sr,
        sigma_bearing=sb,
        outlier_fraction=float(out.mean()) if out.size else 0.0,
        window=window,
    )


def mrclam_bundle(
    directory: PathLike, robot: int, *, noise: NoiseFit | None = None, window: float = 1.0
) -> Any:
    """One robot of an MRCLAM dataset as a SLAM log bundle (velocity model, known association).

    The map is the surveyed landmarks (``Landmark_Groundtruth.dat``; subjects are the ids),
    the ground truth the Vicon trajectory. Noise parameters are fitted from the data with
    :func:`fit_noise` unless given. The log starts at the first control inside the ground
    truth's span; the initial pose is the ground truth there (a tight prior fixes the frame).
    """
    from recovery.bundle import Bundle
    from recovery.models import MotionModel, SensorModel

    d = Path(directory)
    r = read_mrclam_robot(d, robot)
    lm_path = d / "Landmark_Groundtruth.dat"
    lm, lm_lines = read_numeric_table(
        lm_path, columns=("subject", "x", "y", "sx", "sy"), describe="MRCLAM landmarks"
    )
    fit = fit_noise(r, lm[:, :3], window=window) if noise is None else noise
    gt = r.groundtruth
    c = r.controls
    keep_c = (c[:, 0] >= gt.timestamps[0]) & (c[:, 0] <= gt.timestamps[-1])
    c = c[keep_c]
    m = r.measurements
    keep_m = (m[:, 0] >= c[0, 0]) & (m[:, 0] <= c[-1, 0])
    m = m[keep_m]
    x0 = _interp_poses(gt, np.array([c[0, 0]]))[0]
    ids = lm[:, 0].astype(np.int64)
    known = np.isin(m[:, 3].astype(np.int64), ids)
    return Bundle(
        motion=MotionModel("velocity", sigma=(fit.sigma_v, fit.sigma_omega)),
        sensor=SensorModel(fit.sigma_range, fit.sigma_bearing),
        measurement_times=m[known, 0],
        measurements=m[known, 1:3],
        measurement_landmarks=m[known, 3].astype(np.int64),
        measurement_associated=np.ones(int(known.sum()), dtype=bool),
        map_ids=ids,
        map_xy=lm[:, 1:3],
        map_marginals=np.stack([np.diag(np.square(s)) for s in lm[:, 3:5]]),
        initial_pose=x0,
        initial_covariance=np.diag([1e-4, 1e-4, 1e-4]),
        controls=c,
        groundtruth=gt,
        landmarks_groundtruth=(ids, lm[:, 1:3]),
        description=(
            f"MRCLAM {d.name} robot {robot}: {r.robot_sightings} robot sightings and "
            f"{sum(r.unknown_barcodes.values())} unknown barcodes left out, "
            f"{int((~known).sum())} sightings of unsurveyed subjects left out; noise fitted "
            f"over {fit.window} s windows (sigma_v {fit.sigma_v:.4f}, sigma_omega "
            f"{fit.sigma_omega:.4f}, sigma_range {fit.sigma_range:.4f}, sigma_bearing "
            f"{fit.sigma_bearing:.4f}); map = surveyed landmarks"
        ),
    )
