"""Poses with covariances of an external filter, for its NEES (``slamrel nees``).

Layouts
-------
``tum-cov``   29 numbers a line: TUM's ``t x y z qx qy qz qw``, then the 21 values of the upper
              triangle, row by row, of the 6×6 pose covariance over ``(x, y, z, rx, ry, rz)``
              (the order of ROS's ``PoseWithCovariance``): ``c11 c12 c13 c14 c15 c16 c22 c23 …
              c66``. The error it is the covariance of is chosen with the error frame
              (:func:`relation_metric.consistency.pose_errors`; ROS's ``parent`` by default).
``openvins``  20 numbers a line, the file OpenVINS's ov_eval reads (``Loader::load_data``):
              ``t tx ty tz qx qy qz qw Pr11 Pr12 Pr13 Pr22 Pr23 Pr33 Pt11 Pt12 Pt13 Pt22 Pt23
              Pt33``: the upper triangles of the orientation and of the position covariance
              (no cross terms). The quaternion's numbers are ROS's Hamilton ``q_ItoG`` (the same
              numbers as OpenVINS's JPL ``q_GtoI``). The covariance is put into the 6×6 order
              ``(x, y, z, rx, ry, rz)`` (position block first); ov_eval's error is the
              ``openvins`` frame.
``se2-cov``   10 numbers a line: ``t x y θ`` and the upper triangle ``xx xy xθ yy yθ θθ`` of the
              3×3 covariance (the order of the iSAM/g2o files' triangles).
``bag``       a ROS bag topic ``BAG:TOPIC`` of ``geometry_msgs/PoseWithCovarianceStamped`` or
              ``nav_msgs/Odometry`` (:mod:`slamrel.formats.bags`): ``pose.covariance``.

A text file's layout is told by its number of columns (29, 20 or 10: no two agree). Every
covariance must be symmetric (to 1e-9 relative) and positive definite; the first one that is
not is refused with its line. Rows come back in time order (counted and warned about).
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from relation_metric.checks import MAX_INFORMATION, check_covariances
from relation_metric.errors import InputError
from relation_metric.timeorder import TimeOrder, TimeOrderWarning, sort_by_time
from slamrel.constants import COVARIANCE_LAYOUTS
from slamrel.formats.trajectories import unit_quaternions

__all__ = ["COVARIANCE_LAYOUTS", "DEFAULT_FRAME", "PosesWithCovariance", "read_pose_covariances"]

#: The error frame each layout's covariance is of, unless the user says otherwise.
DEFAULT_FRAME = {"tum-cov": "parent", "openvins": "openvins", "se2-cov": "parent", "bag": "parent"}
_COLUMNS = {29: "tum-cov", 20: "openvins", 10: "se2-cov"}


@dataclass(frozen=True)
class PosesWithCovariance:
    """A filter's poses with covariances, in time order.

    Attributes
    ----------
    timestamps : ndarray, shape (N,)
    poses : ndarray, shape (N, 7) or (N, 3)
        SE(3) ``[x, y, z, qx, qy, qz, qw]`` (unit quaternions) or SE(2) ``[x, y, θ]``.
    covariances : ndarray, shape (N, 6, 6) or (N, 3, 3)
    layout : str
        One of :data:`COVARIANCE_LAYOUTS`.
    lines : ndarray of int, shape (N,)
        The file line (bag: message number) of each row.
    time_order : TimeOrder
    """

    timestamps: NDArray[np.float64]
    poses: NDArray[np.float64]
    covariances: NDArray[np.float64]
    layout: str
    lines: NDArray[np.int64]
    time_order: TimeOrder


def _triangle(values: NDArray[np.float64], d: int) -> NDArray[np.float64]:
    """Symmetric (N, d, d) from the row-major upper triangles (N, d(d+1)/2)."""
    iu = np.triu_indices(d)
    out = np.zeros((values.shape[0], d, d))
    out[:, iu[0], iu[1]] = values
    out[:, iu[1], iu[0]] = values
    return out


def read_pose_covariances(
    path: str | os.PathLike[str], layout: str | None = None
) -> PosesWithCovariance:
    """Read a filter's poses with covariances (see the module docstring for the layouts).

    ``layout`` None: ``bag`` for a ``BAG:TOPIC``, else told by the number of columns.
    """
    from slamrel.formats.bags import COVARIANCE_TYPES, names_bag, read_bag_poses, split_bag_spec

    name = os.fspath(path)
    if layout is not None and layout not in COVARIANCE_LAYOUTS:
        raise InputError(
            f"unknown layout {layout!r}; expected one of {', '.join(COVARIANCE_LAYOUTS)}",
            path=name,
        )
    if layout == "bag" or (layout is None and names_bag(name)):
        spec = split_bag_spec(name)
        if spec is None:
            raise InputError("expected a bag topic BAG:TOPIC", path=name)
        got = read_bag_poses(spec)
        if got.covariances is None:
            what = (
                "an all-zero covariance (not filled in)"
                if got.msgtype in COVARIANCE_TYPES
                else "no covariance"
            )
            raise InputError(
                f"topic {spec.topic!r} ({got.msgtype}) carries {what}; expected "
                "geometry_msgs/PoseWithCovarianceStamped or nav_msgs/Odometry with covariances",
                path=name,
            )
        t, poses, cov = got.timestamps, got.poses, got.covariances
        lines = np.arange(1, t.size + 1)
        fmt = "bag"
    elif layout in (None, "se2-cov") and _is_online_csv(name):
        return _online_csv(name)
    else:
        t, poses, cov, lines, fmt = _read_text(name, layout)
    if poses.shape[1] == 7:
        poses = np.column_stack((poses[:, :3], unit_quaternions(poses[:, 3:], name, lines)))
    check_covariances(cov, path=name, lines=lines, definite=True)  # NEES inverts it
    with np.errstate(all="ignore"):  # too small to invert: infinite, refused just below
        info = np.linalg.inv(cov)
    check_covariances(
        info,
        path=name,
        lines=lines,
        what="information (inverse covariance; a variance below about 1e-200)",
        max_abs=MAX_INFORMATION,
        allow_unknown=False,
    )
    order, report = sort_by_time(t, lines=lines, path=name, what="pose")
    if report.out_of_order:
        warnings.warn(
            f"{name}: {report.describe('pose')}; put in time order", TimeOrderWarning, stacklevel=2
        )
        t, poses, cov, lines = t[order], poses[order], cov[order], lines[order]
    same = np.flatnonzero(np.diff(t) == 0)
    if same.size:
        k = int(same[0]) + 1
        raise InputError(
            f"two poses at t = {t[k]:.9g} s (this line and line {int(lines[k - 1])}); expected one "
            "pose per timestamp",
            path=name,
            line=int(lines[k]),
        )
    return PosesWithCovariance(t, poses, cov, fmt, lines, report)


def _is_online_csv(name: str) -> bool:
    """Is ``name`` a SLAM result bundle's ``online.csv`` (a header ``t,x,y,theta,cxx,...``)?"""
    from slamrel.formats.bundle import ONLINE_COVARIANCE_COLUMNS
    from slamrel.formats.text import read_source

    if not os.path.isfile(name):
        return False
    first = next(iter(read_source(name).data_lines()), None)
    head = {h.strip().lower() for h in first[1].split(",")} if first else set()
    return {"t", "x", "y", "theta", *ONLINE_COVARIANCE_COLUMNS} <= head


def _online_csv(name: str) -> PosesWithCovariance:
    """A bundle's ``online.csv`` by its one reader (:func:`~slamrel.formats.bundle.read_online`)
    as ``se2-cov`` rows; poses whose covariance is zero or singular (filters write them for
    their first steps) have no NEES: left out, counted in a warning (with the first line)."""
    from slamrel.formats.bundle import OnlineCovarianceWarning, read_online

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        online = read_online(name)
    for w in caught:  # the reader's own warnings, except the one said again below
        if not issubclass(w.category, OnlineCovarianceWarning):
            warnings.warn(w.message, w.category, stacklevel=3)
    assert online.covariances is not None  # _is_online_csv saw the columns
    cov = online.covariances
    ok = np.linalg.eigvalsh(cov)[:, 0] > 0.0
    t, poses = online.trajectory.timestamps, online.trajectory.poses
    lines = np.arange(2, t.size + 2)  # rows in time order, after the header
    if not ok.all():
        warnings.warn(
            f"{name}:{int(lines[~ok][0])}: {int((~ok).sum())} of {t.size} online pose "
            "covariance(s) zero or singular; those poses have no NEES and are left out",
            OnlineCovarianceWarning,
            stacklevel=3,
        )
    order = sort_by_time(t[ok], lines=lines[ok], path=name, what="pose")[1]
    return PosesWithCovariance(t[ok], poses[ok], cov[ok], "se2-cov", lines[ok], order)


def _read_text(
    name: str, layout: str | None
) -> tuple[NDArray, NDArray, NDArray, NDArray[np.int64], str]:
    from slamrel.formats.text import read_numeric_table, read_source

    src = read_source(name)
    if layout is None:
        first = next((text for _, text in src.data_lines()), None)
        n = 0 if first is None else len(first.split())
        layout = _COLUMNS.get(n)
        if layout is None:
            raise InputError(
                f"cannot tell the layout from {n} columns; expected 29 (tum-cov: TUM and the "
                "21-value upper triangle of the 6x6 covariance), 20 (openvins: TUM, orientation "
                "and position triangles) or 10 (se2-cov: t x y theta and the 3x3 triangle)",
                path=name,
            )
    width = {"tum-cov": 29, "openvins": 20, "se2-cov": 10}[layout]
    values, row_lines = read_numeric_table(
        name,
        columns=tuple(f"c{k}" for k in range(width)),
        describe=f"a {layout} file of poses with covariances ({width} numbers a line)",
        source=src,
    )
    lines = np.asarray([row_lines(k) for k in range(values.shape[0])], dtype=np.int64)
    t = values[:, 0]
    if layout == "se2-cov":
        return t, values[:, 1:4], _triangle(values[:, 4:10], 3), lines, layout
    poses = values[:, 1:8]
    if layout == "tum-cov":
        return t, poses, _triangle(values[:, 8:29], 6), lines, layout
    cov = np.zeros((values.shape[0], 6, 6))
    cov[:, 3:, 3:] = _triangle(values[:, 8:14], 3)  # orientation (ov_eval's Pr)
    cov[:, :3, :3] = _triangle(values[:, 14:20], 3)  # position (ov_eval's Pt)
    return t, poses, cov, lines, layout
