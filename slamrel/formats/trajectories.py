"""Trajectory file formats: plain ``t x y θ``, TUM, CARMEN logs, g2o ``VERTEX_SE2``, CSV, KITTI,
EuRoC.

Every reader is strict (see :mod:`slamrel.formats.text`): a bad line raises
:class:`~relation_metric.errors.InputError` with file and line; the one tolerated defect is a
cut-off final line without newline, skipped with a warning. The format comes from the
extension first (:func:`detect_trajectory_format`), and the poses come back in time order
whatever the file order, counted (:mod:`relation_metric.timeorder`).

Formats
-------
``plain``  ``t x y θ`` per line.
``tum``    ``t x y z qx qy qz qw`` (what evo reads). A file whose motion leaves the plane (z
           varies, or roll/pitch are not zero) is read as SE(3) poses
           ``[x, y, z, qx, qy, qz, qw]`` (``dimension="auto"``, the default); a planar file
           as SE(2) ``[x, y, yaw]`` with ``yaw = atan2(2(qw qz + qx qy), 1 − 2(qy² + qz²))``.
           ``dimension="2d"`` projects a 3-D file onto the plane and warns
           (:class:`PlanarProjectionWarning`) with the out-of-plane motion it discards.
``carmen`` CARMEN log. Pose records: ``FLASER n r1..rn x y θ odom_x odom_y odom_θ
           ipc_timestamp hostname logger_timestamp``; ``ROBOTLASER1`` (laser pose and robot
           pose after the range and remission blocks); ``ODOM x y θ tv rv accel ipc_timestamp
           hostname logger_timestamp``. The time is the ipc timestamp. ``pose="laser"`` takes
           the laser pose of FLASER/ROBOTLASER1 (what the Freiburg relations refer to),
           ``pose="odometry"`` the odometry pose of FLASER and the robot pose of ROBOTLASER1.
           Other record types are skipped and counted.
``g2o``    ``VERTEX_SE2 id x y θ`` (:func:`slamrel.formats.g2o.read_g2o_records`: integer,
           unique ids); the vertex id becomes the timestamp. Other records are skipped and
           counted; skipped 3-D pose vertices (``VERTEX_SE3…``) also in a
           :class:`SkippedPoseWarning`.
``csv``    comma separated with the header ``t,x,y,theta`` (the SLAM result bundle's
           ``groundtruth.csv``); ``#`` comment lines allowed.
``kitti``  KITTI odometry poses: 12 numbers a line, the row-major 3×4 matrix ``[R | t]``.
           Timestamps come from a times file (one number a line, KITTI's ``times.txt``;
           ``times=``), else the line index is the timestamp. Always SE(3) unless planar.
``euroc``  EuRoC ground-truth CSV (``state_groundtruth_estimate0/data.csv``): the header
           ``#timestamp,p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],
           q_RS_z [],...``; timestamps in nanoseconds (read as seconds), quaternion ``w`` first.
           A ``.csv`` file with this header is read as ``euroc``.

The dimension rule (``dimension``) is the same for TUM, KITTI and EuRoC: ``"auto"`` reads
3-D when the motion leaves the plane (z range above 1e-9 m or a roll/pitch above 1e-9 rad),
``"3d"`` always, ``"2d"`` never (with the warning).
"""

from __future__ import annotations

import math
import os
import warnings
from collections import Counter
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, Literal, NamedTuple

import numpy as np
from numpy.typing import NDArray

from relation_metric.errors import InputError
from relation_metric.timeorder import (
    RepeatedTimes,
    TimeOrder,
    TimeOrderWarning,
    repeated_times,
    sort_by_time,
)
from relation_metric.trajectory import OutOfPlane, Trajectory, check_coordinates
from slamrel.constants import TRAJECTORY_FORMATS
from slamrel.formats.bags import (
    BagSpec,
    bag_topics,
    describe_bag_topics,
    is_bag,
    read_bag_poses,
    split_bag_spec,
)
from slamrel.formats.g2o import format_g2o_records, read_g2o_records
from slamrel.formats.text import (
    NUMBER_FORMAT,
    PathLike,
    SourceText,
    quote_token,
    read_csv_table,
    read_head,
    read_numeric_table,
    read_source,
    write_text_atomic,
)

__all__ = [
    "TRAJECTORY_FORMATS",
    "TRAJECTORY_EXTENSIONS",
    "LoadedTrajectory",
    "InvalidPoseWarning",
    "PlanarProjectionWarning",
    "SkippedPoseWarning",
    "DIMENSIONS",
    "CSV_HEADER",
    "detect_trajectory_format",
    "sniff_trajectory_format",
    "without_repeated_times",
    "without_exact_repeats",
    "with_repeats_kept",
    "first_of_each_timestamp",
    "read_trajectory",
    "read_kitti_matrices",
    "write_trajectory",
    "unit_quaternions",
    "yaw_from_quaternion",
    "quaternion_from_yaw",
]

DIMENSIONS = ("auto", "2d", "3d")
CSV_HEADER = "t,x,y,theta"
"""The header of the ``csv`` trajectory format (a SLAM result bundle's ``groundtruth.csv``
and ``odometry.csv``)."""
_EUROC_COLUMNS = (
    "timestamp",
    "p_rs_r_x [m]",
    "p_rs_r_y [m]",
    "p_rs_r_z [m]",
    "q_rs_w []",
    "q_rs_x []",
    "q_rs_y []",
    "q_rs_z []",
)

# File extensions that name a trajectory format: they decide, the content is not sniffed.
TRAJECTORY_EXTENSIONS = {
    ".tum": "tum",
    ".csv": "csv",
    ".g2o": "g2o",
    ".log": "carmen",
    ".clf": "carmen",
}
# Extensions of Freiburg relation files (relations between poses, not a trajectory).
RELATIONS_EXTENSIONS = (".relations", ".rel")

CARMEN_POSE_RECORDS = ("FLASER", "ROBOTLASER1", "ODOM")
# Record names of CARMEN logs that carry no pose we use; seeing one identifies the format.
_CARMEN_OTHER = (
    "PARAM",
    "SYNC",
    "RLASER",
    "RAWLASER1",
    "RAWLASER2",
    "RAWLASER3",
    "RAWLASER4",
    "TRUEPOS",
    "NMEAGGA",
    "NMEARMC",
    "SONAR",
    "BUMPER",
    "SCANMARK",
    "POSITIONLASER",
    "ROBOTLASER2",
)


class InvalidPoseWarning(UserWarning):
    """Pose records with non-finite values were skipped (``skip_invalid=True``)."""


class PlanarProjectionWarning(UserWarning):
    """A 3-D trajectory was projected onto the plane (``dimension="2d"``, ``--planar``)."""


class SkippedPoseWarning(UserWarning):
    """Pose records of a kind the reader does not read (a g2o file's ``VERTEX_SE3``) were
    skipped: the trajectory lacks those poses."""


class LoadedTrajectory(NamedTuple):
    """A trajectory read from a file, with what the reader left out.

    Attributes
    ----------
    trajectory : Trajectory
    format : str
        The format that was read.
    skipped : Mapping[str, int]
        Records not used, by kind (e.g. ``{"PARAM": 12, "invalid pose": 1}``).
    time_order : TimeOrder
        Poses that were out of time order in the file (they are sorted; see
        :mod:`relation_metric.timeorder`).
    repeated_dropped : int
        Poses dropped because they repeat an earlier pose's timestamp (references only,
        :func:`without_repeated_times`).
    discarded : OutOfPlane or None
        The out-of-plane motion a ``dimension="2d"`` read projected away (``None`` when
        nothing was projected).
    repeated : RepeatedTimes
        Poses whose time repeats the previous pose's (all are kept here; the caller decides:
        a reference keeps the first, :func:`without_repeated_times`; an estimate refuses two
        different poses for one time, :func:`without_exact_repeats`).
    """

    trajectory: Trajectory
    format: str
    skipped: Mapping[str, int]
    time_order: TimeOrder = TimeOrder()
    repeated_dropped: int = 0
    discarded: OutOfPlane | None = None
    repeated: RepeatedTimes = RepeatedTimes()

    @property
    def out_of_order(self) -> int:
        """Number of poses that were out of time order in the file."""
        return self.time_order.out_of_order


def yaw_from_quaternion(q: NDArray[np.float64]) -> NDArray[np.float64]:
    """Yaw of quaternions ``[qx, qy, qz, qw]`` (shape ``(..., 4)``), ZYX convention."""
    qx, qy, qz, qw = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


def quaternion_from_yaw(yaw: NDArray[np.float64]) -> NDArray[np.float64]:
    """Quaternions ``[qx, qy, qz, qw]`` of rotations about z, shape ``(..., 4)``."""
    yaw = np.asarray(yaw, dtype=np.float64)
    out = np.zeros(yaw.shape + (4,))
    out[..., 2] = np.sin(yaw / 2.0)
    out[..., 3] = np.cos(yaw / 2.0)
    return out


def detect_trajectory_format(path: PathLike, source: SourceText | None = None) -> str:
    """The trajectory format of a file: from its extension first, else from its content.

    An extension that names a format decides (:data:`TRAJECTORY_EXTENSIONS`: ``.tum``,
    ``.csv``, ``.g2o``, ``.log``/``.clf`` → carmen); a ``.relations``/``.rel`` file is not a
    trajectory. Only other extensions (``.txt``, ``.dat``, none, ...) are sniffed
    (:func:`sniff_trajectory_format`).
    """
    ext = Path(os.fspath(path)).suffix.lower()
    if ext == ".csv":
        src = read_head(path) if source is None else source
        return "euroc" if _is_euroc_header(src) else "csv"
    if ext in TRAJECTORY_EXTENSIONS:
        return TRAJECTORY_EXTENSIONS[ext]
    if ext in RELATIONS_EXTENSIONS:
        raise InputError(
            f"a {ext} file holds relations between poses, not a trajectory; pass format=... "
            "to read it as a trajectory anyway",
            path=path,
        )
    src = read_head(path) if source is None else source
    fmt = sniff_trajectory_format(src)
    if fmt is None and source is None:
        src = read_source(path)  # the head held no data line
        fmt = sniff_trajectory_format(src)
    if fmt is None:
        raise InputError(
            "cannot recognise the trajectory format (expected CARMEN records, VERTEX_SE2 "
            "lines, a t,x,y,theta CSV header, 8 columns (TUM) or 4 columns (t x y theta)); "
            "pass format=...",
            path=src.path,
        )
    return fmt


def sniff_trajectory_format(source: SourceText) -> str | None:
    """The format the first data line suggests, or None.

    A CARMEN record name → carmen, ``VERTEX``/``EDGE``/``FIX`` → g2o, a ``t,...`` header →
    csv, an EuRoC ``#timestamp,p_RS_R_x [m],...`` header → euroc, 8 whitespace-separated
    fields → tum, 12 → kitti, 4 → plain. Note that 8 numeric columns are
    also what a Freiburg ``.relations`` file looks like.
    """
    if _is_euroc_header(source):
        return "euroc"
    for _, text in source.data_lines():
        head = text.split(None, 1)[0].split(",")[0]
        if head in CARMEN_POSE_RECORDS or head in _CARMEN_OTHER:
            return "carmen"
        if head.startswith("VERTEX") or head.startswith("EDGE") or head == "FIX":
            return "g2o"
        if "," in text and head.lower() in ("t", "time", "timestamp"):
            return "csv"
        fields = text.split()
        if len(fields) == 8:
            return "tum"
        if len(fields) == 12:
            return "kitti"
        if len(fields) == 4:
            return "plain"
        return None
    return None


def read_trajectory(
    path: PathLike,
    *,
    format: str | None = None,
    pose: Literal["laser", "odometry"] = "laser",
    skip_invalid: bool = False,
    max_step_back: float | None = None,
    dimension: str = "auto",
    times: PathLike | None = None,
    what: str = "pose",
) -> LoadedTrajectory:
    """Read a trajectory file; its poses come back in time order.

    Parameters
    ----------
    path : str or PathLike
    format : {"plain", "tum", "carmen", "g2o", "csv"}, optional
        Recognised from the content when omitted (:func:`detect_trajectory_format`).
    pose : {"laser", "odometry"}
        Which pose of a CARMEN laser record to take (see the module docstring).
    skip_invalid : bool
        CARMEN only: skip pose records with non-finite values (counted under
        ``"invalid pose"`` and warned about) instead of raising. The original Freiburg
        metricEvaluator tolerates such records; real result logs contain them.
    max_step_back : float, optional
        The time-order rule (:mod:`relation_metric.timeorder`). ``None`` (timed poses:
        estimates, references): poses are stable-sorted by time whatever the file order,
        counted in ``LoadedTrajectory.time_order`` and warned about (``TimeOrderWarning``).
        A number of seconds (a log that drives a filter, e.g. a bundle's ground truth): a
        larger step back raises :class:`InputError`.
    dimension : {"auto", "2d", "3d"}
        TUM, KITTI, EuRoC: SE(3) poses ``(N, 7)`` when the motion leaves the plane
        (``"auto"``), always (``"3d"``), or never (``"2d"``: projected onto the plane, with a
        :class:`PlanarProjectionWarning` that states the discarded z range and roll/pitch).
        The planar formats are always SE(2) (``"3d"`` lifts them).
    times : str or PathLike, optional
        KITTI: a file with one timestamp a line (``times.txt``).
    what : str
        What a row is, for the coordinate and time-order messages (e.g. ``"odometry pose"``).

    Returns
    -------
    LoadedTrajectory
    """
    spec = split_bag_spec(path)
    if spec is not None or format == "bag" or is_bag(path):
        if format not in (None, "bag"):
            raise InputError(
                f"a ROS bag topic cannot be read as {format}; drop format=... (or pass bag)",
                path=path,
            )
        return _read_bag(path, spec, dimension=dimension, what=what)
    name = os.fspath(path)
    fmt = format or detect_trajectory_format(path)
    if fmt not in TRAJECTORY_FORMATS:
        raise InputError(
            f"unknown trajectory format {fmt!r}; expected one of {', '.join(TRAJECTORY_FORMATS)}",
            path=name,
        )
    if dimension not in DIMENSIONS:
        raise InputError(f"dimension must be one of {', '.join(DIMENSIONS)}, got {dimension!r}")
    skipped: Counter[str] = Counter()
    discarded: list[OutOfPlane] = []
    # The numeric tables (TUM, KITTI, plain) are read from the file by the table reader's
    # fast path; the other formats are parsed from the decoded text.
    src = None if fmt in ("tum", "kitti", "plain") else read_source(path)
    cut: int | None
    if fmt in ("tum", "kitti", "euroc"):
        t, poses, lines, cut = _read_3d(
            src, fmt, path=path, times=times, dimension=dimension, discarded=discarded
        )
    elif fmt == "plain":
        values, lines = read_numeric_table(
            path, columns=("t", "x", "y", "theta"), describe="a 't x y theta' trajectory"
        )
        t, poses, cut = values[:, 0], values[:, 1:4], lines.cut_off_line
    else:
        assert src is not None
        if fmt == "csv":
            t, poses, line_of = _read_csv_trajectory(src)
        elif fmt == "carmen":
            t, poses, line_of = _read_carmen(
                src, pose=pose, skip_invalid=skip_invalid, skipped=skipped
            )
        else:
            t, poses, line_of = _read_g2o(src, skipped=skipped)
        lines = line_of.__getitem__  # type: ignore[assignment]
        cut = src.cut_off_line()
    if cut is not None:
        skipped["truncated last line"] += 1
    if t.shape[0] == 0:
        hint = "" if format else "; pass format=... if that is not its format"
        raise InputError(f"no poses found (read as {fmt}){hint}", path=name)
    positions = poses[:, :3] if poses.shape[1] == 7 else poses[:, :2]
    check_coordinates(positions, what=what, path=name, line_of=lines)
    order, report = sort_by_time(t, tolerance=max_step_back, lines=lines, path=name, what=what)
    if report.out_of_order:
        t, poses = t[order], poses[order]
        warnings.warn(
            f"{name}: {report.describe(what)}; put in time order",
            TimeOrderWarning,
            stacklevel=2,
        )
    trajectory = Trajectory(t, poses)
    if dimension == "3d":
        trajectory = trajectory.lifted()

    def sorted_line(k: int) -> int:
        row = int(order[k]) if report.out_of_order else k
        return int(lines(row)) if callable(lines) else int(lines[row])

    _, repeated = repeated_times(t, poses, sorted_line)
    return LoadedTrajectory(
        trajectory,
        fmt,
        dict(skipped),
        report,
        discarded=discarded[0] if discarded else None,
        repeated=repeated,
    )


def _read_bag(
    path: PathLike, spec: BagSpec | None, *, dimension: str, what: str
) -> LoadedTrajectory:
    """A topic or tf chain of a ROS bag (:mod:`slamrel.formats.bags`) as a trajectory.

    Rows are messages: the "line" of a message is its 1-based index on the topic. The
    dimension rule and the time order are those of the text formats.
    """
    if spec is None:
        raise InputError(
            "is a ROS bag, which holds many topics: name the trajectory as BAG:TOPIC (or "
            f"BAG:/tf:PARENT.CHILD); {describe_bag_topics(bag_topics(path))}",
            path=path,
        )
    if dimension not in DIMENSIONS:
        raise InputError(f"dimension must be one of {', '.join(DIMENSIONS)}, got {dimension!r}")
    got = read_bag_poses(spec)
    name = str(spec)
    t, rows = got.timestamps, got.poses
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise InputError(f"message {int(bad[0]) + 1}: non-finite stamp", path=name)
    number = np.arange(1, t.size + 1)
    q = unit_quaternions(rows[:, 3:], name, number.__getitem__)
    discarded: list[OutOfPlane] = []
    poses = _poses_of_dimension(t, rows[:, :3], q, name, dimension, discarded)
    positions = poses[:, :3] if poses.shape[1] == 7 else poses[:, :2]
    check_coordinates(positions, what=what, path=name, line_of=number.__getitem__)
    order, report = sort_by_time(t, tolerance=None, lines=number, path=name, what=what)
    if report.out_of_order:
        t, poses = t[order], poses[order]
        warnings.warn(
            f"{name}: {report.describe(what)}; put in time order", TimeOrderWarning, stacklevel=3
        )
    trajectory = Trajectory(t, poses)
    if dimension == "3d":
        trajectory = trajectory.lifted()
    lines = number[order] if report.out_of_order else number
    _, repeated = repeated_times(t, poses, lambda k: int(lines[k]))
    return LoadedTrajectory(
        trajectory,
        "bag",
        dict(got.skipped),
        report,
        discarded=discarded[0] if discarded else None,
        repeated=repeated,
    )


def _is_euroc_header(src: SourceText) -> bool:
    for line in src.lines[:5]:
        text = line.strip().lower()
        if text:
            return text.startswith("#timestamp") and "p_rs_r_x" in text
    return False


def _read_3d(
    src: SourceText | None,
    fmt: str,
    *,
    path: PathLike,
    times: PathLike | None,
    dimension: str,
    discarded: list[OutOfPlane],
) -> tuple[NDArray, NDArray, Any, int | None]:
    """TUM, KITTI or EuRoC: times, poses (``(N, 7)`` or ``(N, 3)``), the row → line map and
    the cut-off last line skipped (``None``: none).

    ``src`` is the decoded text for EuRoC; TUM and KITTI are read from ``path`` by the table
    reader (its fast path first).
    """
    lines: Callable[[int], Any]
    name = os.fspath(path)
    if fmt == "tum":
        values, table_lines = read_numeric_table(
            path,
            columns=("t", "x", "y", "z", "qx", "qy", "qz", "qw"),
            describe="a TUM trajectory",
        )
        lines, cut = table_lines, table_lines.cut_off_line
        t, xyz, q = values[:, 0], values[:, 1:4], values[:, 4:8]
        q = unit_quaternions(q, name, lines)
    elif fmt == "euroc":
        assert src is not None
        first = next((k for k, line in enumerate(src.lines) if line.strip()), None)
        if first is None or not src.lines[first].lstrip().lower().startswith("#timestamp"):
            raise InputError(
                "expected an EuRoC header #timestamp,p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],"
                "q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z [] as the first line",
                path=src.path,
                line=1 if first is None else first + 1,
            )
        lines_fixed = list(src.lines)
        lines_fixed[first] = lines_fixed[first].lstrip()[1:]
        fixed = SourceText(src.path, lines_fixed, src.ends_with_newline)
        table = read_csv_table(
            src.path,
            required=_EUROC_COLUMNS,
            describe="an EuRoC ground-truth CSV (#timestamp [ns], p_RS_R_xyz, q_RS_wxyz)",
            source=fixed,
        )
        c = table.columns
        t = c["timestamp"] * 1e-9
        xyz = np.column_stack([c[k] for k in _EUROC_COLUMNS[1:4]])
        q = np.column_stack([c[k] for k in _EUROC_COLUMNS[5:8]] + [c[_EUROC_COLUMNS[4]]])
        lines = table.lines.__getitem__
        cut = src.cut_off_line()
        q = unit_quaternions(q, name, lines)
    else:  # kitti
        m, table_lines = read_kitti_matrices(path)
        lines, cut = table_lines, table_lines.cut_off_line
        from relation_metric import se3

        poses7 = se3.from_matrix(m) if m.shape[0] else np.zeros((0, 7))
        xyz, q = poses7[:, :3], poses7[:, 3:]
        t = _kitti_times(times, m.shape[0], name)
    return t, _poses_of_dimension(t, xyz, q, name, dimension, discarded), lines, cut


def read_kitti_matrices(path: PathLike) -> tuple[NDArray[np.float64], Any]:
    """The 3×4 matrices ``[R | t]`` of a KITTI pose file as written, shape ``(N, 3, 4)``, and
    the table's lines; a rotation block off orthonormal by more than 1e-3 is refused.

    The trajectory reader turns them into quaternions (re-orthonormalising a block written
    with few digits); evo's RPE uses the blocks as given (``slamrel ape|rpe kitti``).
    """
    name = os.fspath(path)
    values, lines = read_numeric_table(
        path,
        columns=tuple(f"r{i}{j}" for i in range(3) for j in range(4)),
        describe="a KITTI pose file (12 numbers: the 3x4 matrix [R | t], row by row)",
    )
    m = values.reshape(-1, 3, 4)
    r = m[:, :, :3]
    with np.errstate(over="ignore", invalid="ignore"):
        dev = np.abs(np.einsum("nij,nik->njk", r, r) - np.eye(3)).max(axis=(1, 2))
    bad = np.flatnonzero(~(dev <= 1e-3)) if m.shape[0] else np.empty(0, np.int64)
    if bad.size:
        k = int(bad[0])
        raise InputError(
            f"the rotation block is not orthonormal (|RᵀR − I| up to {float(dev[k]):.3g}); "
            "expected a KITTI pose [R | t] with a rotation matrix R",
            path=name,
            line=lines(k),
        )
    return m, lines


def unit_quaternions(q: NDArray, name: str, lines: Any) -> NDArray:
    """The quaternions ``(N, 4)`` divided by their norms; a norm off 1 by more than 1e-3 is
    refused with :class:`InputError` naming ``name`` and ``lines(k)`` (or ``lines[k]``).

    Every reader of quaternions normalises them here, before any path uses them: the planar
    yaw formula assumes ``‖q‖ = 1`` and is off by about ``2 (‖q‖ − 1)`` otherwise.
    """
    with np.errstate(over="ignore"):  # a huge component: norm inf, refused below
        norms = np.linalg.norm(q, axis=1)
    bad = np.flatnonzero(np.abs(norms - 1.0) > 1e-3)
    if bad.size:
        k = int(bad[0])
        raise InputError(
            f"quaternion norm {norms[k]:.6g}, expected a unit quaternion",
            path=name,
            line=int(lines(k) if callable(lines) else lines[k]),
        )
    return q / norms[:, None]


def _kitti_times(times: PathLike | None, n: int, pose_path: str) -> NDArray:
    if times is None:
        return np.arange(n, dtype=np.float64)
    values, _ = read_numeric_table(times, columns=("t",), describe="a KITTI times file")
    if values.shape[0] != n:
        raise InputError(
            f"{values.shape[0]} timestamps for the {n} poses of {pose_path}; expected one a pose",
            path=times,
        )
    return values[:, 0]


def _poses_of_dimension(
    t: NDArray,
    xyz: NDArray,
    q: NDArray,
    name: str,
    dimension: str,
    discarded: list[OutOfPlane],
) -> NDArray:
    """SE(3) rows, or the planar slice when the dimension rule says 2-D (see module doc)."""
    from relation_metric import se3

    if dimension == "3d" or xyz.shape[0] == 0:
        return np.column_stack((xyz, q))
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        unit = q / np.linalg.norm(q, axis=1, keepdims=True)
        rpy = se3.euler_zyx(unit)
    oop = OutOfPlane(
        z_range=float(xyz[:, 2].max() - xyz[:, 2].min()),
        max_abs_roll=float(np.abs(rpy[:, 0]).max()),
        max_abs_pitch=float(np.abs(rpy[:, 1]).max()),
    )
    planar = oop.is_planar()
    if dimension == "auto" and not planar:
        return np.column_stack((xyz, q))
    if not planar:
        discarded.append(oop)
        warnings.warn(
            f'{name}: 3-D trajectory scored in 2-D (dimension="2d"): discarding its '
            f"out-of-plane motion ({oop.describe()})",
            PlanarProjectionWarning,
            stacklevel=4,
        )
    return np.column_stack((xyz[:, 0], xyz[:, 1], yaw_from_quaternion(q)))


def without_repeated_times(loaded: LoadedTrajectory, path: PathLike) -> LoadedTrajectory:
    """A reference without the poses that repeat an earlier pose's timestamp.

    Two reference poses with one timestamp give a zero-length relation that every estimate
    matches perfectly, pulling the mean down silently. The first pose of each timestamp (in
    file order) is kept; the others are dropped, counted in ``repeated_dropped`` and warned
    about (``RepeatedTimeWarning``, naming ``path``).
    """
    from relation_metric.timeorder import RepeatedTimeWarning, first_of_each_time

    traj = loaded.trajectory
    keep = first_of_each_time(traj.timestamps)
    dropped = int(keep.size - np.count_nonzero(keep))
    if not dropped:
        return loaded
    warnings.warn(
        f"{os.fspath(path)}: dropped {dropped} reference pose(s) that repeat an earlier "
        "pose's timestamp (the first of each is kept; zero-length relations would score 0)",
        RepeatedTimeWarning,
        stacklevel=2,
    )
    return loaded._replace(
        trajectory=Trajectory(traj.timestamps[keep], traj.poses[keep]),
        repeated_dropped=loaded.repeated_dropped + dropped,
    )


def with_repeats_kept(
    loaded: LoadedTrajectory, path: PathLike, *, what: str = "estimate"
) -> LoadedTrajectory:
    """The trajectory with every pose kept, repeated timestamps too, as evo reads a file.

    evo keeps both poses of a repeated timestamp: the shorter trajectory of an association
    pairs each of them, the longer one offers the last of them to an exact time match
    (:func:`relation_metric.time_association.match_nearest_times`). Nothing is dropped; the
    repeats are counted (``LoadedTrajectory.repeated``) and said (``RepeatedTimeWarning``).
    """
    from relation_metric.timeorder import RepeatedTimeWarning

    rep = loaded.repeated
    if rep.count:
        warnings.warn(
            f"{os.fspath(path)}: kept all {rep.count} {what} pose(s) that repeat the previous "
            f"pose's timestamp ({rep.differing} with a different pose; first at line "
            f"{rep.first_line}), as evo does",
            RepeatedTimeWarning,
            stacklevel=2,
        )
    return loaded


def first_of_each_timestamp(
    loaded: LoadedTrajectory, path: PathLike, *, what: str = "estimate"
) -> LoadedTrajectory:
    """The first pose (in file order) of each timestamp; the others dropped, counted, said."""
    from relation_metric.timeorder import RepeatedTimeWarning, first_of_each_time

    rep = loaded.repeated
    if not rep.count:
        return loaded
    traj = loaded.trajectory
    keep = first_of_each_time(traj.timestamps)
    warnings.warn(
        f"{os.fspath(path)}: dropped {rep.count} {what} pose(s) that repeat the previous "
        f"pose's timestamp ({rep.differing} with a different pose; first at line "
        f"{rep.first_line}); the first of each timestamp is kept",
        RepeatedTimeWarning,
        stacklevel=2,
    )
    return loaded._replace(
        trajectory=Trajectory(traj.timestamps[keep], traj.poses[keep]),
        repeated_dropped=loaded.repeated_dropped + rep.count,
    )


def without_exact_repeats(
    loaded: LoadedTrajectory, path: PathLike, *, what: str = "estimate", hint: str = ""
) -> LoadedTrajectory:
    """An estimate (or odometry) with one pose per timestamp, or an :class:`InputError`.

    Two different poses for one timestamp make the pose of that time a guess (the nearest-time
    association took whichever came first, and the score depended on the row order): they are
    refused, naming both lines. Exact repeats (the same row written twice) are dropped,
    counted (``LoadedTrajectory.repeated``) and warned about (``RepeatedTimeWarning``).
    """
    from relation_metric.timeorder import RepeatedTimeWarning, first_of_each_time

    rep = loaded.repeated
    if not rep.count:
        return loaded
    if rep.differing:
        earlier = "" if rep.earlier_line is None else f" (line {rep.earlier_line})"
        raise InputError(
            f"two different {what} poses at t = {rep.time:.9g} s: this line and the one before "
            f"it in time{earlier}; {rep.differing} timestamp repeat(s) carry a different pose. "
            f"Expected one pose per timestamp (which one is meant is a guess; remove one){hint}",
            path=path,
            line=rep.first_line,
        )
    traj = loaded.trajectory
    keep = first_of_each_time(traj.timestamps)
    warnings.warn(
        f"{os.fspath(path)}: dropped {rep.count} {what} pose(s) that repeat the previous "
        f"pose exactly, timestamp and pose (first at line {rep.first_line})",
        RepeatedTimeWarning,
        stacklevel=2,
    )
    return loaded._replace(trajectory=Trajectory(traj.timestamps[keep], traj.poses[keep]))


def _read_csv_trajectory(src: SourceText) -> tuple[NDArray, NDArray, NDArray]:
    table = read_csv_table(
        src.path, required=CSV_HEADER.split(","), describe="a t,x,y,theta trajectory", source=src
    )
    c = table.columns
    return c["t"], np.column_stack((c["x"], c["y"], c["theta"])), table.lines


def _read_carmen(
    src: SourceText, *, pose: str, skip_invalid: bool, skipped: Counter[str]
) -> tuple[NDArray, NDArray, NDArray]:
    times: list[float] = []
    poses: list[tuple[float, float, float]] = []
    numbers: list[int] = []
    invalid_lines: list[int] = []
    for number, text in src.data_lines():
        fields = text.split()
        kind = fields[0]
        if kind not in CARMEN_POSE_RECORDS:
            skipped[kind] += 1
            continue
        t, p = _carmen_pose(fields, pose=pose, src=src, number=number)
        if not (math.isfinite(t) and all(math.isfinite(v) for v in p)):
            if not skip_invalid:
                raise InputError(
                    f"{kind} record with a non-finite pose or time ({' '.join(map(str, p))} "
                    f"at {t}); expected finite numbers (skip_invalid=True skips such records and "
                    "counts them)",
                    path=src.path,
                    line=number,
                )
            skipped["invalid pose"] += 1
            invalid_lines.append(number)
            continue
        times.append(t)
        poses.append(p)
        numbers.append(number)
    if invalid_lines:
        shown = ", ".join(str(n) for n in invalid_lines[:5])
        more = "" if len(invalid_lines) <= 5 else f" and {len(invalid_lines) - 5} more"
        warnings.warn(
            f"{src.path}: skipped {len(invalid_lines)} pose record(s) with non-finite values "
            f"(line {shown}{more})",
            InvalidPoseWarning,
            stacklevel=3,
        )
    arr = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    return np.asarray(times, dtype=np.float64), arr, np.asarray(numbers)


def _carmen_float(fields: list[str], k: int, what: str, src: SourceText, number: int) -> float:
    if k >= len(fields):
        raise InputError(
            f"{fields[0]} record too short: no field for {what} (has {len(fields)} fields)",
            path=src.path,
            line=number,
        )
    token = fields[k]
    try:
        if not token.isascii() or "_" in token:
            raise ValueError
        return float(token)
    except ValueError:
        raise InputError(
            f"{fields[0]} {what}: expected a number, got {quote_token(token)}",
            path=src.path,
            line=number,
        ) from None


def _carmen_count(fields: list[str], k: int, what: str, src: SourceText, number: int) -> int:
    value = _carmen_float(fields, k, what, src, number)
    if not (math.isfinite(value) and value >= 0 and value == int(value) and value < 2**31):
        raise InputError(
            f"{fields[0]} {what}: expected a non-negative count, got {quote_token(fields[k])}",
            path=src.path,
            line=number,
        )
    return int(value)


class CarmenLayout(NamedTuple):
    """Where the parts of one CARMEN record sit in its whitespace-split fields.

    The one description of the CARMEN record layouts, shared by the trajectory reader and
    the laser-scan reader (:mod:`slamrel.formats.laser`). Indices are into ``fields``
    (``fields[0]`` is the record name); ``None`` when the record has no such part.

    ``FLASER``/``RLASER n r1..rn x y θ odom_x odom_y odom_θ ipc_t host logger_t``;
    ``ROBOTLASER1``/``ROBOTLASER2 type start fov res max_range accuracy remission_mode n
    r1..rn m e1..em laser_x laser_y laser_θ robot_x robot_y robot_θ tv rv forward_safety
    side_safety turn_axis ipc_t host logger_t``; ``RAWLASER1..4 type start fov res max_range
    accuracy remission_mode n r1..rn m e1..em ipc_t host logger_t``; ``ODOM x y θ tv rv accel
    ipc_t host logger_t``.
    """

    kind: str
    readings: int
    ranges: int | None
    config: int | None
    laser: int | None
    robot: int | None
    time: int


CARMEN_LASER_RECORDS = ("FLASER", "RLASER", "ROBOTLASER1", "ROBOTLASER2") + tuple(
    f"RAWLASER{k}" for k in range(1, 5)
)
"""CARMEN records that carry a laser scan (see :class:`CarmenLayout`)."""


def carmen_layout(fields: list[str], src: SourceText, number: int) -> CarmenLayout:
    """The :class:`CarmenLayout` of one record (ODOM or a laser record), its length checked.

    Raises :class:`InputError` (file, line) for a count that is not a non-negative integer
    or a record whose field count does not match its counts.
    """
    kind = fields[0]
    if kind in ("FLASER", "RLASER"):
        n = _carmen_count(fields, 1, "number of readings", src, number)
        layout = CarmenLayout(kind, n, 2, None, n + 2, n + 5, n + 8)
        expected = n + 11
    elif kind in ("ROBOTLASER1", "ROBOTLASER2") or kind.startswith("RAWLASER"):
        n = _carmen_count(fields, 8, "number of readings", src, number)
        m = _carmen_count(fields, 9 + n, "number of remissions", src, number)
        if kind.startswith("ROBOT"):
            layout = CarmenLayout(kind, n, 9, 1, 10 + n + m, 13 + n + m, 21 + n + m)
            expected = n + m + 24
        else:
            layout = CarmenLayout(kind, n, 9, 1, None, None, 10 + n + m)
            expected = n + m + 13
    elif kind == "ODOM":
        layout = CarmenLayout(kind, 0, None, None, None, 1, 7)
        expected = 10
    else:
        raise InputError(f"{kind} is not a CARMEN pose or laser record", path=src.path, line=number)
    if len(fields) != expected:
        raise InputError(
            f"{kind} record: expected {expected} fields, got {len(fields)}",
            path=src.path,
            line=number,
        )
    return layout


def carmen_floats(
    fields: list[str], start: int, count: int, what: str, src: SourceText, number: int
) -> NDArray[np.float64]:
    """``fields[start:start + count]`` as floats; a bad token raises :class:`InputError`."""
    try:
        chunk = fields[start : start + count]
        joined = "".join(chunk)  # a token is non-ASCII or holds "_" iff their join does
        if not joined.isascii() or "_" in joined:
            raise ValueError
        return np.array(chunk, dtype=np.float64)
    except ValueError:
        for k in range(count):
            _carmen_float(fields, start + k, f"{what} {k + 1}", src, number)
        raise  # pragma: no cover - the loop above raises


def _carmen_pose(
    fields: list[str], *, pose: str, src: SourceText, number: int
) -> tuple[float, tuple[float, float, float]]:
    layout = carmen_layout(fields, src, number)
    base = layout.laser if pose == "laser" and layout.laser is not None else layout.robot
    assert base is not None
    p = tuple(_carmen_float(fields, base + k, c, src, number) for k, c in enumerate("xyθ"))
    t = _carmen_float(fields, layout.time, "ipc_timestamp", src, number)
    return t, p  # type: ignore[return-value]


def _read_g2o(src: SourceText, *, skipped: Counter[str]) -> tuple[NDArray, NDArray, NDArray]:
    """``VERTEX_SE2`` records (:func:`slamrel.formats.g2o.read_g2o_records`), in id order."""
    ids: dict[str, NDArray[np.int64]] = {}
    recs = read_g2o_records(src.path, ("VERTEX_SE2",), skipped=skipped, source=src, ids=ids)
    values, lines = recs["VERTEX_SE2"]
    _warn_skipped_3d_poses(src, skipped)
    big = np.flatnonzero(np.abs(ids["VERTEX_SE2"][:, 0]) >= 2**53)
    if big.size:  # a double cannot hold it: two poses could share one timestamp
        k = int(big[0])
        raise InputError(
            f"VERTEX_SE2 id {int(ids['VERTEX_SE2'][k, 0])} is used as the pose's timestamp, "
            "which a double holds exactly only below 2**53 in magnitude; expected smaller ids "
            "(a GTSAM symbol key's pose index, for example)",
            path=src.path,
            line=int(lines[k]),
        )
    order = np.argsort(values[:, 0], kind="stable")
    return values[order, 0], values[order, 1:4], lines[order]


def _warn_skipped_3d_poses(src: SourceText, skipped: Counter[str]) -> None:
    """Say that a g2o file's 3-D pose vertices were skipped (the count alone went to
    ``--json``): a file of ``VERTEX_SE3`` poses with a few ``VERTEX_SE2`` ones would give a
    trajectory of the latter only, without a word."""
    kinds = sorted(k for k in skipped if k.startswith("VERTEX_SE3"))
    if not kinds:
        return
    first = next(n for n, text in src.data_lines() if text.split(None, 1)[0] in kinds)
    counts = ", ".join(f"{skipped[k]} {k}" for k in kinds)
    warnings.warn(
        f"{src.path}: skipped {counts} record(s) (3-D poses, first at line {first}); the g2o "
        "trajectory format reads VERTEX_SE2 poses only",
        SkippedPoseWarning,
        stacklevel=4,
    )


def write_trajectory(
    path: PathLike,
    trajectory: Trajectory,
    *,
    format: str = "plain",
) -> None:
    """Write a trajectory atomically in one of :data:`TRAJECTORY_FORMATS`.

    Numbers are written with :data:`~slamrel.formats.text.NUMBER_FORMAT` (17 significant
    digits: the file reads back bit for bit). ``plain`` and ``tum`` have a ``#`` header line;
    ``kitti`` the 12 numbers of ``[R | t]`` a line, no header and no times (write the
    timestamps apart, one a line, as KITTI's ``times.txt``); ``csv`` the header
    :data:`CSV_HEADER` (the one writer of a bundle's ``groundtruth.csv``
    and ``odometry.csv``); ``carmen`` writes ``FLASER 0`` records (laser pose = odometry
    pose), which the original metricEvaluator reads; ``g2o`` writes ``VERTEX_SE2`` lines
    (:func:`slamrel.formats.g2o.format_g2o_records`) with the pose index as id.
    """
    t = trajectory.timestamps
    p = trajectory.poses
    n = len(trajectory)
    if p.shape[1] == 7 and format not in ("tum", "kitti"):
        raise InputError(
            f"a 3-D trajectory can be written as tum or kitti only, not {format}", path=path
        )
    if format == "plain":
        text = "# t x y theta\n" + _rows(np.column_stack((t, p)), [NUMBER_FORMAT] * 4)
    elif format == "tum":
        if p.shape[1] == 7:
            rows = np.column_stack((t, p))
        else:
            q = quaternion_from_yaw(p[:, 2])
            rows = np.column_stack((t, p[:, 0], p[:, 1], np.zeros(n), q))
        text = "# t x y z qx qy qz qw\n" + _rows(rows, [NUMBER_FORMAT] * 8)
    elif format == "kitti":
        from relation_metric import se3

        poses7 = p if p.shape[1] == 7 else trajectory.lifted().poses
        m = se3.to_matrix(poses7)[:, :3, :].reshape(n, 12) if n else np.zeros((0, 12))
        text = _rows(m, [NUMBER_FORMAT] * 12)
    elif format == "csv":
        text = CSV_HEADER + "\n" + _rows(np.column_stack((t, p)), [NUMBER_FORMAT] * 4, ",")
    elif format == "g2o":
        text = format_g2o_records("VERTEX_SE2", np.arange(n), p)
    elif format == "carmen":
        # FLASER 0 (no readings) x y θ odom_x odom_y odom_θ ipc_timestamp hostname logger_timestamp
        line = "FLASER 0" + f" {NUMBER_FORMAT}" * 7 + " slamrel " + NUMBER_FORMAT + "\n"
        text = line * n % tuple(np.column_stack((p, p, t, t)).ravel().tolist())
    else:
        raise InputError(
            f"unknown trajectory format {format!r}; expected one of "
            f"{', '.join(TRAJECTORY_FORMATS)}",
            path=path,
        )
    write_text_atomic(path, text)


def _rows(values: NDArray[np.float64], fmt: list[str], sep: str = " ") -> str:
    if values.shape[0] == 0:
        return ""
    line = sep.join(fmt)
    # One formatting pass over a flat tuple; much faster than np.savetxt for large arrays.
    return (line + "\n") * values.shape[0] % tuple(values.ravel().tolist())
