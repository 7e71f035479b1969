"""Files scored as ``evo_ape`` and ``evo_rpe`` score them: what ``slamrel ape``/``rpe`` compute.

evo's command line names the input kind first (``tum REF EST``, ``kitti REF EST``, ``euroc
GT.csv EST.tum``, ``bag BAG REF_TOPIC EST_TOPIC``, ``bag2 …``); :func:`evo_files` reads the
two trajectories with slamrel's readers (:mod:`slamrel.formats.trajectories`) and then
follows evo's steps in evo's order:

1. the **reference** alone is cut to ``[t_start, t_end]`` (evo crops it before the
   association; a bound of 0 counts as none, as evo's test ``if t_start or t_end``);
2. the poses are associated by time (:func:`~relation_metric.time_association.synchronize`,
   evo's nearest-time matching with ``t_max_diff`` and ``t_offset``); KITTI files have no
   times and are paired pose by pose (they must have as many poses), and their RPE uses the
   rotation blocks as written (evo's arithmetic, :func:`relation_metric.pose_error.
   relative_pose_errors`), not the re-orthonormalised quaternions: on KITTI's own files
   (6–9 digits) the two readings differ by up to ~5e-5 relative;
3. the estimate is aligned, both are projected, and the APE or RPE is computed
   (:mod:`relation_metric.pose_error`); the statistics are evo's
   (:func:`~relation_metric.stats.evo_statistics`, population ``std``).

Where slamrel reads a file differently from evo, it says so: by default a reference pose
repeating an earlier pose's timestamp is dropped (warned), an estimate with two different
poses at one timestamp is refused (evo keeps both silently); ``duplicate_stamps="keep"``
(``--duplicate_stamps keep``) keeps them all as evo does, counted and warned, and gives
evo's numbers; ``"first"`` keeps the first of each timestamp in both.
"""

from __future__ import annotations

from contextlib import nullcontext
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from relation_metric import se3
from relation_metric.errors import InputError, OptionError
from relation_metric.pose_error import (
    PoseErrors,
    absolute_pose_errors,
    relative_pose_errors,
)
from relation_metric.stats import evo_statistics
from relation_metric.time_association import synchronize
from relation_metric.trajectory import Trajectory
from slamrel.evaluation import load_trajectory
from slamrel.formats.bags import one_opening
from slamrel.formats.trajectories import read_kitti_matrices

__all__ = ["EvoOptions", "EvoResult", "evo_files", "INPUT_KINDS", "RELATION_TITLES"]

#: evo's input kinds (its sub-commands) and the formats of (reference, estimate).
INPUT_KINDS = {
    "tum": ("tum", "tum"),
    "kitti": ("kitti", "kitti"),
    "euroc": ("euroc", "tum"),
    "bag": ("bag", "bag"),
    "bag2": ("bag", "bag"),
}

#: evo's words for each pose relation (``PoseRelation``) and its unit (``Unit``).
RELATION_TITLES = {
    "full": ("full transformation", "unit-less"),
    "trans_part": ("translation part", "m"),
    "rot_part": ("rotation part", "unit-less"),
    "angle_rad": ("rotation angle in radians", "rad"),
    "angle_deg": ("rotation angle in degrees", "deg"),
    "point_distance": ("point distance", "m"),
}
_DELTA_UNIT_WORDS = {"f": "frames", "d": "deg", "r": "rad", "m": "m"}


@dataclass(frozen=True)
class EvoOptions:
    """The options of ``evo_ape``/``evo_rpe`` with evo's names and defaults.

    ``metric`` ``"ape"`` or ``"rpe"``; ``kind`` a key of :data:`INPUT_KINDS`; ``reference`` and
    ``estimate`` file paths, or for bags the bag in ``reference`` and the topics in
    ``ref_topic``/``est_topic``. ``n_to_align`` −1 means all poses (evo's default).
    ``duplicate_stamps`` ``"keep"`` (evo's reading), ``"first"`` or ``"refuse"`` (module doc).
    """

    metric: str
    kind: str
    reference: str
    estimate: str
    ref_topic: str | None = None
    est_topic: str | None = None
    pose_relation: str = "trans_part"
    align: bool = False
    correct_scale: bool = False
    align_origin: bool = False
    n_to_align: int = -1
    delta: float = 1.0
    delta_unit: str = "f"
    delta_tol: float = 0.1
    all_pairs: bool = False
    pairs_from_reference: bool = False
    t_max_diff: float = 0.01
    t_offset: float = 0.0
    t_start: float | None = None
    t_end: float | None = None
    project_to_plane: str | None = None
    duplicate_stamps: str = "refuse"


@dataclass(frozen=True)
class EvoResult:
    """An APE or RPE as evo reports it: ``title``, ``stats`` (evo's), ``errors`` and where.

    ``timestamps`` and ``seconds_from_start`` are the estimate's times of the errors (RPE: of
    each pair's second pose, from the first synchronised pose; None for KITTI, which has no
    times); ``info`` is the ``info.json`` of evo's result zip.
    """

    title: str
    stats: dict[str, float]
    errors: NDArray[np.float64]
    info: dict[str, str]
    timestamps: NDArray[np.float64] | None
    seconds_from_start: NDArray[np.float64] | None
    reference: Trajectory
    estimate: Trajectory
    pairs: PoseErrors

    def pretty(self) -> str:
        """evo's console text: the title, a blank line, the statistics by name."""
        rows = "".join(f"{k:>10}\t{v:.6f}\n" for k, v in sorted(self.stats.items()))
        return f"{self.title}\n\n{rows}"


def evo_files(options: EvoOptions) -> EvoResult:
    """Read the files of ``options`` and compute the APE or RPE as evo does (module doc)."""
    o = options
    _check(o)
    ref, est, ref_name, est_name, rotations = _load(o)
    timed = o.kind != "kitti"
    if timed:
        ref = _cropped(ref, o.t_start, o.t_end)
        ref, est = synchronize(ref, est, max_diff=o.t_max_diff, offset=o.t_offset)
    elif len(ref) != len(est):
        raise InputError(
            f"KITTI files are paired pose by pose and must have as many poses: {len(ref)} "
            f"in {o.reference}, {len(est)} in {o.estimate}"
        )
    align = _alignment(o)
    n = None if o.n_to_align == -1 else o.n_to_align
    if o.metric == "ape":
        pe = absolute_pose_errors(
            ref,
            est,
            o.pose_relation,
            align=align,
            n_to_align=n,
            plane=o.project_to_plane,
            rotations=rotations,
        )
    else:
        pe = relative_pose_errors(
            ref,
            est,
            o.pose_relation,
            delta=o.delta,
            delta_unit=o.delta_unit,
            rel_delta_tol=o.delta_tol,
            all_pairs=o.all_pairs,
            pairs_from_reference=o.pairs_from_reference,
            align=align,
            n_to_align=n,
            plane=o.project_to_plane,
            rotations=rotations,
        )
    title = evo_title(o)
    name, unit = RELATION_TITLES[o.pose_relation]
    info = {
        "title": title,
        "ref_name": ref_name,
        "est_name": est_name,
        "label": f"{o.metric.upper()} ({unit})",
    }
    t = est.timestamps[pe.second] if timed else None
    since = None if t is None else t - est.timestamps[0]
    return EvoResult(title, evo_statistics(pe.errors), pe.errors, info, t, since, ref, est, pe)


def _check(o: EvoOptions) -> None:
    """Option combinations evo refuses, said in slamrel's words before any file is read."""
    if o.align and o.align_origin:
        raise OptionError("can't be used with --align_origin (as in evo)", option="--align")
    if o.n_to_align != -1 and o.n_to_align < 2:
        raise OptionError(
            f"the alignment needs at least 2 poses, got {o.n_to_align} (-1: all, the default)",
            option="--n_to_align",
        )
    if o.kind not in INPUT_KINDS:
        raise OptionError(f"unknown input kind {o.kind!r}", option=o.kind)
    if o.metric not in ("ape", "rpe"):
        raise ValueError(f"metric must be 'ape' or 'rpe', got {o.metric!r}")


def _alignment(o: EvoOptions) -> str:
    """evo's flags as one alignment of :data:`relation_metric.pose_error.EVO_ALIGNMENTS`."""
    if o.align_origin:
        return "origin"
    if o.align:
        return "sim3" if o.correct_scale else "se3"
    return "scale" if o.correct_scale else "none"


def _load(o: EvoOptions) -> tuple[Trajectory, Trajectory, str, str, Any]:
    """The two trajectories (SE(3)), evo's names for them (paths as given, or topics) and,
    for KITTI, the rotation blocks as written (else None)."""
    ref_fmt, est_fmt = INPUT_KINDS[o.kind]
    if o.kind == "kitti":
        m_ref, _ = read_kitti_matrices(o.reference)
        m_est, _ = read_kitti_matrices(o.estimate)
        ref_k, est_k = (
            Trajectory(np.arange(m.shape[0], dtype=np.float64), se3.from_matrix(m))
            for m in (m_ref, m_est)
        )
        return ref_k, est_k, o.reference, o.estimate, (m_ref[:, :, :3], m_est[:, :, :3])
    if ref_fmt == "bag":
        assert o.ref_topic is not None and o.est_topic is not None
        ref_path, est_path = f"{o.reference}:{o.ref_topic}", f"{o.reference}:{o.est_topic}"
        names = (o.ref_topic, o.est_topic)
    else:
        ref_path, est_path = o.reference, o.estimate
        names = (o.reference, o.estimate)
    with one_opening(o.reference) if ref_fmt == "bag" else nullcontext():
        ref, est = (
            load_trajectory(
                path,
                fmt,
                role=role,
                format_option=o.kind,
                repeats=o.duplicate_stamps,
                repeats_option="--duplicate_stamps",
            )
            for path, fmt, role in (
                (ref_path, ref_fmt, "reference"),
                (est_path, est_fmt, "estimate"),
            )
        )
    return ref.trajectory.lifted(), est.trajectory.lifted(), names[0], names[1], None


def _cropped(ref: Trajectory, t_start: float | None, t_end: float | None) -> Trajectory:
    """evo's ``reduce_to_time_range`` of the reference, applied when ``t_start or t_end``."""
    if not (t_start or t_end):
        return ref
    t = ref.timestamps
    lo = t[0] if t_start is None else t_start
    hi = t[-1] if t_end is None else t_end
    if lo > hi:
        raise OptionError(f"{lo} is after --t_end {hi}", option="--t_start")
    keep = (t >= lo) & (t <= hi)
    if np.count_nonzero(keep) == 0:
        raise InputError(
            f"no reference pose lies in [{lo}, {hi}] s (the reference spans {t[0]:.6f} .. "
            f"{t[-1]:.6f} s)"
        )
    return Trajectory(t[keep], ref.poses[keep])


def evo_title(o: EvoOptions) -> str:
    """The title evo gives the result (printed first, and ``info.json``'s ``title``)."""
    name, unit = RELATION_TITLES[o.pose_relation]
    if o.metric == "ape":
        title = f"APE w.r.t. {name} ({unit})"
    else:
        delta = int(o.delta) if o.delta_unit == "f" else o.delta
        pairs = "all pairs" if o.all_pairs else "consecutive pairs"
        title = (
            f"RPE w.r.t. {name} ({unit})\nfor delta = {delta} "
            f"({_DELTA_UNIT_WORDS[o.delta_unit]}) using {pairs}"
        )
    if o.align and not o.correct_scale:
        title += "\n(with SE(3) Umeyama alignment)"
    elif o.align and o.correct_scale:
        title += "\n(with Sim(3) Umeyama alignment)"
    elif o.correct_scale:
        title += "\n(scale corrected)"
    elif not o.align_origin:
        title += "\n(not aligned)"
    if (o.align or o.correct_scale) and o.n_to_align != -1:
        title += f" (aligned poses: {o.n_to_align})"
    if o.align_origin:
        title += "\n(with origin alignment)"
    if o.project_to_plane:
        title += f"\n(projected to {o.project_to_plane} plane)"
    return title
