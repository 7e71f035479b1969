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

import numpy as np
from numpy.typing import NDArray

from relation_metric.errors import InputError
from relation_metric.textio import PathLike, RowLines, read_numeric_table
from relation_metric.trajectory import Trajectory, readonly

__all__ = ["MrclamRobot", "read_mrclam_robot", "read_barcodes", "N_ROBOTS"]

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
