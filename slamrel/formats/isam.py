"""The iSAM/GTSAM planar text format: ``ODOMETRY`` and ``LANDMARK`` lines.

``ODOMETRY i j dx dy dθ`` + 6 values: the relative motion ``x_i⁻¹ ∘ x_j`` and the upper
triangle, row-first (``xx xy xθ yy yθ θθ``), of its noise matrix.
``EDGE2`` is read as a synonym of ``ODOMETRY`` (same fields, same noise order): iSAM's own
``Loader`` accepts both, and its ``city10000.txt`` uses ``EDGE2`` throughout. A TORO file
also has ``EDGE2`` records (with another information order, ``xx xy yy θθ xθ yθ``), but it
always has ``VERTEX2`` records too: a file is iSAM text when its first data line is
``ODOMETRY`` or ``LANDMARK``, or ``EDGE2`` and no line is a ``VERTEX2``/``VERTEX`` record.
``LANDMARK k l x y`` + 3 values: landmark ``l`` seen from pose ``k`` at ``(x, y)`` in the pose
frame (``x_k⁻¹ · l``) and ``xx xy yy`` of its noise matrix.

Pose and landmark ids share one number space (Victoria Park: landmark 5 is seen from pose 4,
pose 6 follows).

The format's own definition (iSAM's ``Loader::parse_line``) reads the noise numbers as the
upper-triangular **square-root information** matrix ``R`` (``Rᵀ R = Σ⁻¹``, row-first): that
is the default, ``noise="sqrt-information"``. Some copies store covariances in the same places
instead (the copy of Victoria Park shipped with GTSAM: 0.0001 m², a 0.01 m standard
deviation, where the original iSAM copy has 100 = 1/0.01): read those with
``noise="covariance"``. The numbers alone cannot say which convention a file uses, so nothing
is guessed; but when the standard deviations the chosen convention implies are implausible
(odometry steps uncertain by kilometres or by more than π radians) and the other
convention's are plausible, :func:`read_isam` warns (:class:`NoiseConventionWarning`) and
names the other ``noise`` value.
"""

from __future__ import annotations

import re
import warnings
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from recovery.bundle import Bundle
from recovery.models import MotionModel, SensorModel
from relation_metric import se2
from relation_metric.checks import MAX_INFORMATION, check_covariances
from relation_metric.errors import InputError
from relation_metric.ids import first_missing, refuse_self_loops, rows_of
from relation_metric.trajectory import Trajectory
from slamrel.backends.graph import PoseGraph, initial_landmarks
from slamrel.formats.text import (
    PathLike,
    SourceText,
    exact_record_ids,
    read_keyword_records,
    read_source,
)

__all__ = [
    "IsamData",
    "ISAM_RECORDS",
    "ISAM_ODOMETRY_SYNONYM",
    "DEFAULT_NOISE",
    "NoiseConventionWarning",
    "is_isam",
    "read_isam",
    "isam_log_bundle",
]

NoiseConvention = Literal["covariance", "sqrt-information"]
NOISE_CONVENTIONS: tuple[NoiseConvention, ...] = ("sqrt-information", "covariance")
DEFAULT_NOISE: NoiseConvention = "sqrt-information"
"""iSAM's own definition of the noise numbers (see the module docstring)."""
ISAM_RECORDS = ("ODOMETRY", "LANDMARK")
"""The record names of the format; a file whose first data line is one of them is iSAM text."""
ISAM_ODOMETRY_SYNONYM = "EDGE2"
"""iSAM's other spelling of ``ODOMETRY`` (also TORO's edge record: see :func:`is_isam`)."""
_TORO_VERTEX = re.compile(r"^[ \t\ufeff]*VERTEX2?[ \t]", re.MULTILINE)

# Plausibility of the standard deviations a convention implies (per record, the median over
# the file): a translation beyond _MAX_SIGMA_XY metres or a rotation beyond π radians is not
# a measurement's noise, it is the other convention read wrongly.
_MAX_SIGMA_XY = 100.0
_MAX_SIGMA_THETA = np.pi


class NoiseConventionWarning(UserWarning):
    """The noise numbers look like the other convention (see :func:`read_isam`)."""


def is_isam(source: SourceText) -> bool:
    """Whether ``source`` is iSAM text: its first data line (after comments, blank lines and
    a byte order mark, by the rules of :class:`~slamrel.formats.text.SourceText`) starts
    with one of :data:`ISAM_RECORDS`, or with ``EDGE2`` in a file without TORO's
    ``VERTEX2``/``VERTEX`` records. The one test every command uses."""
    for _, text in source.data_lines():
        first = text.split(None, 1)[0]
        if first == ISAM_ODOMETRY_SYNONYM:
            return not any(_TORO_VERTEX.search(line) for line in source.lines)
        return first in ISAM_RECORDS
    return False


@dataclass(frozen=True)
class IsamData:
    """An iSAM file as a pose graph with landmarks.

    Attributes
    ----------
    graph : PoseGraph
        Initial guess from chaining the odometry; landmarks from their first sighting.
    pose_ids, landmark_ids : ndarray of int
        The file's ids of the graph's poses and landmarks (graph index → file id).
    """

    graph: PoseGraph
    pose_ids: NDArray[np.int64]
    landmark_ids: NDArray[np.int64]


def _information(
    upper: NDArray[np.float64],
    size: int,
    convention: str,
    *,
    path: PathLike,
    lines: NDArray[np.int64],
    kind: str,
) -> NDArray[np.float64]:
    """Information matrices from upper-triangle rows ``(K, size (size+1)/2)``.

    A covariance must be symmetric positive definite (it is inverted; negative variances and
    zero or singular covariances raise :class:`InputError` at their line); a square-root
    information matrix ``R`` must have a non-zero diagonal (``Rᵀ R`` invertible).
    """
    iu = np.triu_indices(size)
    m = np.zeros((upper.shape[0], size, size))
    m[:, iu[0], iu[1]] = upper
    if convention == "sqrt-information":
        diag = np.diagonal(m, axis1=1, axis2=2)
        bad = np.flatnonzero((diag == 0).any(axis=1))
        if bad.size:
            raise InputError(
                f"{kind}: square-root information with a zero on its diagonal (singular); "
                "expected an invertible upper-triangular R",
                path=path,
                line=int(lines[bad[0]]),
            )
        root = np.sqrt(MAX_INFORMATION)
        big = np.flatnonzero((np.abs(upper) > root).any(axis=1))
        if big.size:
            raise InputError(
                f"{kind}: square-root information entry "
                f"{float(np.abs(upper[big[0]]).max()):.6g} is beyond {root:.6g} (information "
                f"beyond {MAX_INFORMATION:.6g}, where the sums of squares of a solve overflow)",
                path=path,
                line=int(lines[big[0]]),
            )
        rtr = np.swapaxes(m, 1, 2) @ m  # Rᵀ R
        check_covariances(rtr, path=path, lines=lines, what=f"{kind} information (Rᵀ R)",
                          max_abs=MAX_INFORMATION)  # fmt: skip
        return rtr
    sym = m + np.swapaxes(np.triu(m, 1), 1, 2)
    check_covariances(sym, path=path, lines=lines, what=f"{kind} covariance", definite=True)
    with np.errstate(all="ignore"):
        info = np.linalg.inv(sym)
    bad = np.flatnonzero(~np.isfinite(info).all(axis=(1, 2)))
    if bad.size:
        raise InputError(
            f"{kind} covariance: too small to invert in double precision; expected variances "
            "above about 1e-300",
            path=path,
            line=int(lines[bad[0]]),
        )
    check_covariances(info, path=path, lines=lines, what=f"{kind} information (inverse covariance)",
                      max_abs=MAX_INFORMATION)  # fmt: skip
    return info.astype(np.float64, copy=False)


def _implied_sigmas(upper: NDArray[np.float64], size: int, convention: str) -> NDArray[np.float64]:
    """Median over the records of the standard deviations ``convention`` implies, per axis
    (from the diagonal: ``√Σ_ii`` for a covariance, ``1/|R_ii|`` for a square-root
    information matrix, exact for a diagonal ``R``)."""
    diag = upper[:, [k * size - k * (k - 1) // 2 for k in range(size)]]
    with np.errstate(divide="ignore", invalid="ignore"):
        sig = np.sqrt(np.abs(diag)) if convention == "covariance" else 1.0 / np.abs(diag)
    return np.asarray(np.median(sig, axis=0), dtype=np.float64)


def _plausible(sig: NDArray[np.float64]) -> bool:
    limits = np.array([_MAX_SIGMA_XY, _MAX_SIGMA_XY, _MAX_SIGMA_THETA])[: sig.size]
    return bool(np.all(np.isfinite(sig)) and np.all(sig <= limits))


def _check_convention(
    upper: NDArray[np.float64], size: int, noise: str, *, path: PathLike, kind: str
) -> None:
    """Warn when ``noise`` makes the records' noise implausible and the other convention
    would not (see the module docstring)."""
    if upper.shape[0] == 0:
        return
    other = "covariance" if noise == "sqrt-information" else "sqrt-information"
    mine, theirs = _implied_sigmas(upper, size, noise), _implied_sigmas(upper, size, other)
    if _plausible(mine) or not _plausible(theirs):
        return
    axes = ("x", "y", "theta")[:size]
    said = ", ".join(f"{a} {v:.3g}" for a, v in zip(axes, mine))
    warnings.warn(
        f"{path}: {kind} noise read as {noise} implies median standard deviations of "
        f"{said} (metres, radians): implausible; these numbers look like a {other} "
        f"(pass noise={other!r})",
        NoiseConventionWarning,
        stacklevel=3,
    )


def read_isam(
    path: PathLike,
    *,
    noise: NoiseConvention = DEFAULT_NOISE,
    source: SourceText | None = None,
) -> IsamData:
    """Read an iSAM/GTSAM text file (see the module docstring).

    ``noise`` is what the noise numbers are: ``"sqrt-information"`` (iSAM's definition, the
    default) or ``"covariance"``. ``source`` is the already-read text of ``path``.
    """
    if noise not in NOISE_CONVENTIONS:
        raise ValueError(f"noise must be 'sqrt-information' or 'covariance', got {noise!r}")
    src = read_source(path) if source is None else source
    path = src.path
    recs = read_keyword_records(
        path, {"ODOMETRY": 12, ISAM_ODOMETRY_SYNONYM: 12, "LANDMARK": 8}, source=src
    )
    # EDGE2 is ODOMETRY by another name: both kept, in file order
    o_lines = np.concatenate((recs["ODOMETRY"][1], recs[ISAM_ODOMETRY_SYNONYM][1]))
    in_file_order = np.argsort(o_lines, kind="stable")
    o_lines = o_lines[in_file_order]
    o_vals = np.concatenate(
        (recs["ODOMETRY"][0].reshape(-1, 11), recs[ISAM_ODOMETRY_SYNONYM][0].reshape(-1, 11))
    )[in_file_order]
    z_vals, z_lines = recs["LANDMARK"]
    # ids exact (as TORO and g2o read them): 3.5 refused, 2**60 never rounded onto 2**60 + 1
    o_ids, z_ids = (
        np.stack(
            [exact_record_ids(vals[:, c], lines, src, c + 1, f"{kind} id {c + 1}") for c in (0, 1)],
            axis=1,
        ).reshape(-1, 2)
        for vals, lines, kind in ((o_vals, o_lines, "ODOMETRY"), (z_vals, z_lines, "LANDMARK"))
    )
    odo = o_vals
    if odo.shape[0] == 0:
        raise InputError("no ODOMETRY lines", path=path)
    refuse_self_loops(o_ids, o_lines, path, "ODOMETRY")
    o = odo
    z = z_vals
    pose_ids = np.unique(o_ids)
    landmark_ids = np.unique(z_ids[:, 1])
    clash = np.intersect1d(pose_ids, landmark_ids)
    if clash.size:
        line = int(z_lines[np.flatnonzero(z_ids[:, 1] == clash[0])[0]])
        raise InputError(f"id {clash[0]} is used for a pose and a landmark", path=path, line=line)
    pi = np.searchsorted(pose_ids, o_ids[:, 0])
    pj = np.searchsorted(pose_ids, o_ids[:, 1])
    _check_convention(o[:, 5:11], 3, noise, path=path, kind="ODOMETRY")
    _check_convention(z[:, 4:7], 2, noise, path=path, kind="LANDMARK")
    info_pp = _information(o[:, 5:11], 3, noise, path=path, lines=o_lines, kind="ODOMETRY")
    # initial guess: chain the odometry edges k -> k+1 (in id order)
    chain = pj == pi + 1
    step = np.full((pose_ids.size - 1, 3), np.nan)
    step[pi[chain]] = o[chain, 2:5]
    gap = np.flatnonzero(~np.isfinite(step[:, 0]))
    if gap.size:
        raise InputError(
            f"pose {pose_ids[gap[0] + 1]} has no ODOMETRY from pose {pose_ids[gap[0]]}; "
            "cannot chain an initial guess",
            path=path,
        )
    poses = se2.cumulative_compose(step)
    if z.size:
        pk = rows_of(pose_ids, z_ids[:, 0])
        bad = first_missing(pk)
        if bad is not None:
            raise InputError(
                f"LANDMARK seen from unknown pose {int(z_ids[bad, 0])}",
                path=path,
                line=int(z_lines[bad]),
            )
        pl = rows_of(landmark_ids, z_ids[:, 1])
        info_pl = _information(z[:, 4:7], 2, noise, path=path, lines=z_lines, kind="LANDMARK")
        lm0 = initial_landmarks(poses, pk, pl, z[:, 2:4], landmark_ids.size)
    else:
        pk = pl = np.empty(0, np.int64)
        info_pl = np.empty((0, 2, 2))
        lm0 = np.empty((0, 2))
    graph = PoseGraph(
        poses=poses,
        landmarks=lm0,
        pp_i=pi,
        pp_j=pj,
        pp_z=o[:, 2:5],
        pp_info=info_pp,
        pl_k=pk,
        pl_l=pl,
        pl_z=z[:, 2:4],
        pl_info=info_pl,
    )
    return IsamData(graph=graph, pose_ids=pose_ids, landmark_ids=landmark_ids)


def isam_log_bundle(data: IsamData, *, sigma_scale: float = 1.0) -> Bundle:
    """The iSAM problem as an EKF-SLAM log bundle (odometry model, range-bearing sensor).

    Poses get the time ``t = k`` (the file has no time); the odometry poses chain the
    ``ODOMETRY`` steps; ``LANDMARK`` observations ``(x, y)`` become range-bearing
    ``(‖z‖, atan2(z_y, z_x))`` with known association. The bundle's models have constant
    standard deviations, so the file's noise matrices are summarised: the odometry
    ``σ_x, σ_y, σ_θ`` are the medians of the diagonal square roots; the isotropic observation
    σ becomes ``σ_range = σ`` and ``σ_bearing = σ / median range``. The map is the
    first-sighting guess (a log bundle needs one; EKF-SLAM replaces it); no ground truth.
    """
    g = data.graph
    n = g.n_poses
    r = np.hypot(g.pl_z[:, 0], g.pl_z[:, 1])
    if not r.size or not float(np.median(r)) > 0:
        raise InputError(
            "LANDMARK observations: "
            + ("none" if not r.size else "the median range is 0")
            + "; a range-bearing log bundle needs landmarks seen at a positive range"
        )
    chain = g.pp_j == g.pp_i + 1
    cov_pp = np.linalg.inv(g.pp_info[chain])
    sig_odo = np.sqrt(np.median(np.diagonal(cov_pp, axis1=1, axis2=2), axis=0)) * sigma_scale
    cov_pl = np.linalg.inv(g.pl_info)
    sig_xy = float(np.sqrt(np.median(np.diagonal(cov_pl, axis1=1, axis2=2)))) * sigma_scale
    b = np.arctan2(g.pl_z[:, 1], g.pl_z[:, 0])
    order = np.argsort(g.pl_k, kind="stable")
    t = np.arange(n, dtype=np.float64)
    ids = data.landmark_ids
    return Bundle(
        motion=MotionModel("odometry", sigma=tuple(float(s) for s in sig_odo)),
        sensor=SensorModel(sig_xy, sig_xy / float(np.median(r))),
        measurement_times=t[g.pl_k[order]],
        measurements=np.column_stack((r[order], b[order])),
        measurement_landmarks=ids[g.pl_l[order]],
        measurement_associated=np.ones(order.size, dtype=bool),
        map_ids=ids,
        map_xy=g.landmarks,
        map_marginals=np.zeros((ids.size, 2, 2)),
        initial_pose=g.poses[0],
        initial_covariance=1e-9 * np.eye(3),
        odometry=Trajectory(t, g.poses),
        description=(
            "iSAM/GTSAM text file as an EKF-SLAM log (t = pose index); map = first-sighting guess"
        ),
    )
