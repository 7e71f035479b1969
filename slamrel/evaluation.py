"""Files-level evaluation: what ``slamrel evaluate REFERENCE ESTIMATE`` scores, as a library.

:func:`evaluate_files` reads REFERENCE (a Freiburg ``.relations`` file, a reference
trajectory or a SLAM result bundle with ``groundtruth.csv``) and ESTIMATE as the command does
and scores the estimate with the relation metric; :func:`score_files` also returns what the
command writes (:class:`FileEvaluation`). The scoring options are an
:class:`~slamrel.evaluation_options.EvaluateOptions`, whose defaults are the command's. What
is dropped or reordered on the way is said in warnings and counted in the notes. Messages
name the options of ``slamrel evaluate`` (``--strict``, ``--reference-format``, ...), whose
Python names are the fields of :class:`EvaluateOptions`.
"""

from __future__ import annotations

import dataclasses
import os
import warnings
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Literal

import numpy as np

from relation_metric.alignment import AffineAlignment, absolute_trajectory_error
from relation_metric.errors import InputError, OptionError
from relation_metric.evaluate import Evaluation, evaluate
from relation_metric.relations import RelationSet, generate_relations
from relation_metric.time_association import synchronize
from relation_metric.timeorder import FILTER_TIME_TOLERANCE, RepeatedTimeWarning, zero_length
from relation_metric.trajectory import Trajectory
from slamrel.constants import EVO_MAX_TIME_DIFF, STRATEGY_OPTION_WORDS, TRAJECTORY_FORMATS
from slamrel.evaluation_options import SCORING_OPTIONS, EvaluateOptions
from slamrel.formats.bags import is_bag, names_bag
from slamrel.formats.relations import read_relations
from slamrel.formats.text import read_numeric_table, read_source
from slamrel.formats.trajectories import (
    RELATIONS_EXTENSIONS,
    TRAJECTORY_EXTENSIONS,
    LoadedTrajectory,
    PlanarProjectionWarning,
    first_of_each_timestamp,
    read_trajectory,
    sniff_trajectory_format,
    with_repeats_kept,
    without_exact_repeats,
    without_repeated_times,
)

__all__ = [
    "EvaluateOptions",
    "FileEvaluation",
    "evaluate_files",
    "score_files",
    "load_reference",
    "load_trajectory",
    "in_option_words",
    "relation_axes",
]


@dataclasses.dataclass(frozen=True)
class FileEvaluation:
    """An evaluation of files and what ``slamrel evaluate`` writes of it."""

    #: The relation-metric evaluation (relations named by time, also with ``sync``).
    evaluation: Evaluation
    #: The estimate it scored (the synchronised poses with ``sync``; lifted to SE(3) for
    #: 6-DoF relations), as the figure draws it.
    estimate: Trajectory
    #: The JSON of ``--json``: the evaluation (rotation in degrees when asked), its group,
    #: what was skipped, dropped or reordered on the way, the ATE when asked.
    result: dict[str, Any]
    #: The relation set: the strategy that generated the relations from a reference
    #: trajectory (``consecutive`` by default); ``None`` for a .relations file, whose
    #: relations may mix kinds. Written as the ``set`` column of ``--per-relation``.
    relation_set: str | None = None
    #: The (estimate, reference) the ATE compares (the synchronised pairs with ``sync``);
    #: None for a .relations file.
    ate_inputs: tuple[Trajectory, Trajectory] | None = None
    #: The reference trajectory (after the time window), drawn by the figure; ``None`` for a
    #: .relations file.
    reference: Trajectory | None = None


def evaluate_files(
    reference: str | os.PathLike[str],
    estimate: str | os.PathLike[str],
    options: EvaluateOptions | None = None,
    **overrides: Any,
) -> Evaluation:
    """``slamrel evaluate REFERENCE ESTIMATE [options]`` as a function: its evaluation.

    The files are read and scored exactly as the command does (REFERENCE a ``.relations``
    file, a reference trajectory or a bundle directory; the time-order rule; repeated
    reference times and zero-length relations dropped; see docs/formats.md), with ``options``
    (default: the command's defaults) and each field of :class:`EvaluateOptions` given as a
    keyword overriding it, e.g. ``evaluate_files(ref, est, strategy="loops", radius=2.0,
    max_time_diff=0.05)``. What is dropped or reordered on the way is said in warnings.

    Raises
    ------
    TypeError
        For a keyword that is not a field of :class:`EvaluateOptions`.
    ValueError
        For an option value out of its range (the parameter named).
    InputError
        For anything wrong with the files (file and line named), as the command.
    """
    unknown = sorted(set(overrides) - set(SCORING_OPTIONS))
    if unknown:
        raise TypeError(
            f"evaluate_files() got unknown options {', '.join(unknown)}; expected some of "
            + ", ".join(SCORING_OPTIONS)
        )
    chosen = dataclasses.replace(options or EvaluateOptions(), **overrides)
    return score_files(reference, estimate, chosen).evaluation


def score_files(
    reference: str | os.PathLike[str],
    estimate: str | os.PathLike[str],
    options: EvaluateOptions,
    *,
    degrees: bool = False,
    ate: bool = False,
    n_to_align: int | None = None,
    drift: bool = False,
    axes: bool = False,
) -> FileEvaluation:
    """Read REFERENCE and ESTIMATE as ``slamrel evaluate`` does and score the estimate.

    ``degrees`` states the rotation of :attr:`FileEvaluation.result` in degrees; ``ate``
    adds the aligned absolute trajectory error to it (needs a reference trajectory), its
    alignments fitted on the first ``n_to_align`` matched poses (None: all); ``drift`` adds
    the KITTI drift (:func:`relation_metric.drift.kitti_drift`) of the pose-by-pose
    synchronised pairs (needs a reference trajectory); ``axes`` adds the per-axis
    translational relation errors (:func:`relation_axes`).
    """
    reference, estimate = os.fspath(reference), os.fspath(estimate)
    _warn_same_file(reference, estimate)
    notes: dict[str, Any] = {}
    relations, ref_traj = load_reference(reference, options, notes)
    skip = options.skip_invalid_poses or options.mode == "metricevaluator"
    loaded = _load_estimate(estimate, options, skip, notes)
    odometry = _load_odometry(options, skip, notes) if options.odometry else None
    scored = _windowed(
        _offset(loaded.trajectory, options.t_offset), options, notes, estimate, "estimate"
    )
    ate_pair = (scored, ref_traj)
    if options.pairs_from == "estimate" and not options.sync:
        raise OptionError(
            "chooses the pose pairs on the estimate, which needs the pose-by-pose "
            "association first: add --sync (as evo, which always associates first)",
            option="--pairs-from estimate",
        )
    if ref_traj is not None and not options.sync:
        _warn_denser_reference(ref_traj, scored, relations, reference)
    if options.sync:
        if ref_traj is None:
            raise OptionError(
                f"needs a reference trajectory, not a .relations file ({reference})",
                option="--sync",
            )
        _warn_evo_tolerance(options.max_time_diff)
        ref_sync, est_sync = synchronize(ref_traj, scored, max_diff=options.max_time_diff)
        notes["synchronized_pairs"] = len(ref_sync)
        if len(ref_sync) < 2:
            raise InputError(
                f"--sync pairs only {len(ref_sync)} pose(s) with {estimate} within "
                f"--max-time-diff {options.max_time_diff:g} s; relations need at least 2",
                path=reference,
            )
        relations = _generate_pairs(ref_sync, est_sync, options)
        scored = est_sync
        ate_pair = _same_times(est_sync, ref_sync)
    if len(relations) == 0:
        raise InputError(_why_no_relations(reference, ref_traj, options, notes), path=reference)
    with in_option_words({"strict=True": "--strict", "interpolate=True": "--interpolate"}):
        ev = evaluate(
            relations,
            scored,
            odometry=odometry,
            mode=options.mode,  # type: ignore[arg-type]  # checked: one of MODES
            weights=options.weights,  # type: ignore[arg-type]  # a tuple after the checks
            max_time_diff=options.max_time_diff,
            interpolate=options.interpolate,
            max_interpolation_gap=options.max_interpolation_gap,
            strict=options.strict,
            estimate_name=estimate,
            relations_name=reference,
        )
    if options.sync:  # name the pose pairs by the reference's times in the outputs
        i = ev.relations.first.astype(np.int64)
        j = ev.relations.second.astype(np.int64)
        t = ref_sync.timestamps
        ev = dataclasses.replace(
            ev, relations=RelationSet(t[i], t[j], ev.relations.delta, key="time")
        )
    ev_estimate = scored.lifted() if ev.relations.group.name == "SE3" else scored
    result = ev.as_dict(degrees=degrees)
    result["group"] = ev.relations.group.name
    if loaded.skipped:
        result["estimate_records_skipped"] = dict(loaded.skipped)
    result.update(notes)
    _add_extras(
        result,
        ev,
        ate_pair,
        ref_traj,
        reference,
        options.max_time_diff,
        ate=ate,
        n_to_align=n_to_align,
        axes=axes,
        drift=drift,
    )
    generated = None if ref_traj is None else (options.strategy or "consecutive")
    pair = None if ate_pair[1] is None else (ate_pair[0], ate_pair[1])
    return FileEvaluation(
        ev, ev_estimate, result, relation_set=generated, ate_inputs=pair, reference=ref_traj
    )


def _load_estimate(
    estimate: str, options: EvaluateOptions, skip: bool, notes: dict[str, Any]
) -> LoadedTrajectory:
    """ESTIMATE read as a trajectory (``skip``: records with non-finite values skipped and
    counted), refused with ``strict`` when not in time order or with a time repeated; what
    reading it projected, reordered or dropped is said in ``notes``."""
    loaded = load_trajectory(
        estimate,
        options.format,
        skip_invalid=skip,
        role="estimate",
        planar=options.planar,
        times=options.times,
    )
    _refuse_if_strict(options, loaded, estimate)
    _note_projection(notes, "estimate", loaded)
    notes["estimate_out_of_order"] = loaded.time_order.as_dict()
    notes["estimate_repeated_times"] = loaded.repeated.as_dict()
    return loaded


def _add_extras(
    result: dict[str, Any],
    ev: Evaluation,
    ate_pair: tuple[Trajectory, Trajectory | None],
    ref_traj: Trajectory | None,
    reference: str,
    tol: float,
    *,
    ate: bool,
    n_to_align: int | None,
    axes: bool,
    drift: bool,
) -> None:
    """Add to ``result`` what :func:`score_files` was asked for beyond the relation metric:
    the aligned ATE, the per-axis relation errors, the KITTI drift (the first and the last
    on the scored pose pairs ``ate_pair``: they need the reference trajectory ``ref_traj``)."""
    if ate:
        if ref_traj is None:
            raise OptionError(
                f"needs a reference trajectory, not a .relations file ({reference})",
                option="--ate",
            )
        ate_estimate, ate_reference = ate_pair
        assert ate_reference is not None  # the reference (just checked) or its synchronised copy
        result["ate"] = _ate(ate_estimate, ate_reference, tol, n_to_align)
    if axes:
        result["relation_axes"] = {k: v.as_dict() for k, v in relation_axes(ev).items()}
    if drift:
        if ref_traj is None:
            raise OptionError(
                f"needs a reference trajectory, not a .relations file ({reference})",
                option="--kitti-drift",
            )
        result["kitti_drift"] = _kitti_drift(ate_pair, tol, reference)


def _why_no_relations(
    reference: str, ref_traj: Trajectory | None, options: EvaluateOptions, notes: dict[str, Any]
) -> str:
    """Why no relation is left to score (statistics of none would be a NaN table)."""
    if ref_traj is None:
        dropped = notes.get("relations_zero_length_dropped", 0)
        dup = notes.get("relations_duplicates", {}).get("count", 0)
        why = f"{dropped} zero-length (t1 == t2) and {dup} repeated line(s) were dropped"
        return f"no relation left to score: {why}; expected at least one relation"
    strategy = options.strategy or "consecutive"
    knobs = {
        "consecutive": "a smaller --step",
        "distance": "a smaller --distance",
        "time": "fewer --seconds",
        "loops": "a larger --radius or a smaller --min-separation-time",
        "global": "a smaller --min-distance",
    }.get(strategy, "other strategy options")
    return (
        f"no relation was selected: --strategy {strategy} generated none from the "
        f"{len(ref_traj)} reference poses; expected at least one ({knobs})"
    )


def _is_relations_file(path: str, options: EvaluateOptions) -> bool:
    """Whether REFERENCE is read as a Freiburg .relations file: the extension decides first.

    ``.relations``/``.rel`` → relations; an extension that names a trajectory format
    (``.tum``, ``.csv``, ``.g2o``, ``.log``, ``.clf``), ``--reference-format``, ``--strategy``
    or a directory → a reference trajectory. Other files are sniffed; 8 numeric columns fit
    both readings and are told apart by their last four columns
    (:func:`_eight_columns_are_relations`), the guess said in a warning.
    """

    p = Path(path)
    if p.is_dir() or options.reference_format is not None or names_bag(path):
        return False
    ext = p.suffix.lower()
    if ext in RELATIONS_EXTENSIONS:
        if options.strategy is not None:
            raise OptionError(
                f"{path}: a {ext} file holds relations, but --strategy generates relations from a "
                "reference trajectory; drop --strategy, or pass --reference-format to read "
                "the file as a trajectory",
                option="--strategy",
            )
        return True
    if ext in TRAJECTORY_EXTENSIONS or options.strategy is not None:
        return False
    fmt = sniff_trajectory_format(read_source(path))
    if fmt == "tum":
        return _eight_columns_are_relations(path)
    if fmt is None:
        raise InputError(
            "cannot recognise the reference: expected a Freiburg .relations file (8 columns "
            "t1 t2 x y z roll pitch yaw; name it *.relations) or a reference trajectory "
            "(CARMEN records, VERTEX_SE2 lines, a t,x,y,theta CSV header, 8 columns (TUM) or "
            "4 columns (t x y theta)); pass --reference-format or rename the file",
            path=path,
        )
    return False


#: Rows of unit quaternions from which an 8-column file is a TUM trajectory without a warning.
_SURE_ROWS = 10


def _eight_columns_are_relations(path: str) -> bool:
    """Tell a TUM trajectory from Freiburg relations, both 8 numbers a line, by content.

    A TUM file's last four columns are unit quaternions (its reader refuses any other); a
    relations file's are ``z roll pitch yaw``, whose norm is 1 only by accident. Every row a
    unit quaternion (≥ 2 rows) → TUM; otherwise relations. Relations are said in a warning
    with how to state it, and so is TUM on fewer than :data:`_SURE_ROWS` rows; a TUM file of
    more rows (evo's ``.txt`` files) is read without a word: that many unit norms by accident
    do not happen. A file that cannot be told apart (fewer than 2 rows, all unit) is refused
    naming both readings.
    """

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the reader proper warns (cut-off last line, …)
        values, _ = read_numeric_table(
            path, columns=("c1", "c2", "c3", "c4", "c5", "c6", "c7", "c8")
        )
    unit = np.abs(np.linalg.norm(values[:, 4:8], axis=1) - 1.0) <= 1e-3
    if unit.all() and values.shape[0] < 2:
        raise InputError(
            "ambiguous reference: 8 numeric columns read either as a Freiburg .relations "
            "file (t1 t2 x y z roll pitch yaw) or as a TUM trajectory (t x y z qx qy qz qw); "
            "say which: rename it to *.relations (or *.rel) to read relations, or pass "
            "--reference-format tum (or a --strategy) to generate relations from a TUM "
            "reference trajectory",
            path=path,
        )
    if unit.all() and values.shape[0] >= _SURE_ROWS:
        return False
    if unit.all():
        warnings.warn(
            f"{path}: read as a TUM trajectory (every row ends in a unit quaternion); rename it "
            "to *.tum or pass --reference-format tum to say so",
            UserWarning,
            stacklevel=2,
        )
        return False
    k = int(np.flatnonzero(~unit)[0])
    warnings.warn(
        f"{path}: read as Freiburg relations (t1 t2 x y z roll pitch yaw): row {k + 1} does "
        "not end in a unit quaternion, so it is no TUM trajectory; rename it to *.relations "
        "to say so",
        UserWarning,
        stacklevel=2,
    )
    return True


def load_reference(
    reference: str, options: EvaluateOptions, notes: dict[str, Any] | None = None
) -> tuple[RelationSet, Trajectory | None]:
    """Relations from a .relations file, or generated from a reference trajectory.

    Returns the relations and the reference trajectory (None for a .relations file; with
    ``sync`` the relations are empty, generated after the pose-by-pose association). What
    was dropped or reordered on the way is added to ``notes`` (JSON-ready):
    ``relations_zero_length_dropped`` for a .relations file; ``reference_out_of_order`` and
    ``reference_repeated_times_dropped`` for a reference trajectory.
    """

    notes = {} if notes is None else notes
    if _is_relations_file(reference, options):
        report: dict[str, Any] = {}
        relations = read_relations(reference, report=report)
        relations = _without_duplicates(relations, report, reference, options, notes)
        zero = zero_length(relations.first, relations.second)
        dropped = int(np.count_nonzero(zero))
        notes["relations_zero_length_dropped"] = dropped
        if dropped:
            warnings.warn(
                f"{reference}: dropped {dropped} relation(s) with t1 == t2 (zero-length "
                "relations would score 0 and pull the mean down)",
                RepeatedTimeWarning,
                stacklevel=2,
            )
            relations = relations.subset(~zero)
        relations = _relations_in_window(relations, options, notes)
        if relations.has_out_of_plane and options.planar:
            assert relations.out_of_plane is not None  # has_out_of_plane: there are some
            oop = np.abs(relations.out_of_plane)
            warnings.warn(
                f"{reference}: 6-DoF relations scored in 2-D (--planar): discarding "
                f"their out-of-plane parts (|z| up to {float(oop[:, 0].max()):.3g} m, |roll| up "
                f"to {float(np.degrees(oop[:, 1].max())):.3g} deg, |pitch| up to "
                f"{float(np.degrees(oop[:, 2].max())):.3g} deg)",
                PlanarProjectionWarning,
                stacklevel=2,
            )
            relations = RelationSet(
                relations.first, relations.second, relations.delta, key=relations.key
            )
        return relations, None
    loaded = load_trajectory(
        reference,
        options.reference_format,
        role="reference",
        planar=options.planar,
        times=options.reference_times,
        format_option="--reference-format",
    )
    ref = Path(reference)
    _refuse_if_strict(options, loaded, str(ref / "groundtruth.csv" if ref.is_dir() else ref))
    _note_projection(notes, "reference", loaded)
    notes["reference_out_of_order"] = loaded.time_order.as_dict()
    notes["reference_repeated_times_dropped"] = loaded.repeated_dropped
    traj = _windowed(loaded.trajectory, options, notes, reference, "reference")
    if options.sync:  # relations are generated after the pose-by-pose association
        return RelationSet(np.empty(0), np.empty(0), np.empty((0, 3))), traj
    try:
        return _generate(traj, options), traj
    except InputError as exc:
        if exc.path is not None:
            raise
        window = options.t_start is not None or options.t_end is not None
        said = exc.message + (" inside --t-start/--t-end" if window else "")
        raise type(exc)(said, path=reference) from None


class DuplicateRelationWarning(RepeatedTimeWarning):
    """Lines of a .relations file that repeat an earlier line exactly (counted)."""


def _without_duplicates(
    relations: RelationSet,
    report: dict[str, Any],
    reference: str,
    options: EvaluateOptions,
    notes: dict[str, Any],
) -> RelationSet:
    """Relations without the lines that repeat an earlier line (kept in metricevaluator mode).

    A repeated line is one measurement written twice; scored twice it weighs double. The
    repeats are dropped, counted (``relations_duplicates``) and warned about; the
    metricevaluator mode keeps them (the C++ tool scores every line) and says so.
    """
    repeat = report["duplicates"]
    count = int(np.count_nonzero(repeat))
    keep = options.mode == "metricevaluator"
    lines = report["duplicate_lines"]
    notes["relations_duplicates"] = {
        "count": count,
        "dropped": bool(count and not keep),
        "first_line": None if lines is None else lines[1],
    }
    if not count:
        return relations
    what = (
        "kept and scored twice, as the metricEvaluator does (--mode metricevaluator)"
        if keep
        else "dropped (a measurement written twice would weigh double)"
    )
    warnings.warn(
        f"{reference}: {count} relation line(s) repeat an earlier line exactly (first line "
        f"{lines[1]}, a repeat of line {lines[0]}); {what}",
        DuplicateRelationWarning,
        stacklevel=3,
    )
    return relations if keep else relations.subset(~repeat)


def _generate(
    reference: Trajectory, options: EvaluateOptions, *, key: Literal["time", "index"] = "time"
) -> RelationSet:
    """Relations generated from ``reference`` with the strategy options (default consecutive)."""
    with in_option_words(STRATEGY_OPTION_WORDS):
        return generate_relations(
            reference,
            "consecutive" if options.strategy is None else options.strategy,  # type: ignore[arg-type]
            step=options.step,
            distance=options.distance,
            radius=options.radius,
            min_separation_time=options.min_separation_time,
            min_separation_distance=options.min_separation_distance,
            count=options.count,
            min_distance=options.min_distance,
            seed=options.seed,
            chained=options.chained,
            seconds=options.seconds,
            key=key,
        )


def _note_projection(notes: dict[str, Any], role: str, loaded: LoadedTrajectory) -> None:
    """``--planar``: what the projection of a 3-D file discarded, for ``--json``."""
    if loaded.discarded is not None:
        notes.setdefault("planar_projection", {})[role] = dict(loaded.discarded._asdict())


def _refuse_if_strict(options: EvaluateOptions, loaded: LoadedTrajectory, path: str) -> None:
    """``--strict``: a trajectory not in time order, or with a timestamp repeated, is an
    error (file:line)."""
    rep = loaded.repeated
    if options.strict and rep.count:
        raise InputError(
            f"{rep.count} pose(s) repeat the timestamp of the pose before them "
            f"(t = {rep.time:.9g} s, line {rep.earlier_line} and this one); --strict refuses "
            "repeated timestamps (without --strict exact repeats are dropped and counted, an "
            "estimate with two different poses for one time is refused, a reference keeps the "
            "first)",
            path=path,
            line=rep.first_line,
        )
    if options.strict and loaded.out_of_order:
        raise InputError(
            f"{loaded.time_order.describe('pose')}; --strict refuses a trajectory that is not "
            "in time order (without --strict its poses are put in time order and counted)",
            path=path,
            line=loaded.time_order.first_line,
        )


def _warn_same_file(reference: str, estimate: str) -> None:
    """The same file as REFERENCE and ESTIMATE scores every relation 0: say so."""
    ref = Path(reference)
    ref_file = ref / "groundtruth.csv" if ref.is_dir() else ref
    if os.path.realpath(ref_file) == os.path.realpath(estimate):
        warnings.warn(
            f"{estimate}: given as both REFERENCE and ESTIMATE; the estimate is scored "
            "against itself (every error 0)",
            UserWarning,
            stacklevel=2,
        )


def _load_odometry(options: EvaluateOptions, skip: bool, notes: dict[str, Any]) -> Trajectory:
    """The ``--odometry`` log (refused with ``--strict`` when out of time order)."""
    assert options.odometry is not None  # called only with an odometry log
    loaded = load_trajectory(
        options.odometry,
        options.odometry_format,
        pose="odometry",
        skip_invalid=skip,
        role="odometry",
        planar=options.planar,
        format_option="--odometry-format",
    )
    _refuse_if_strict(options, loaded, options.odometry)
    notes["odometry_out_of_order"] = loaded.time_order.as_dict()
    notes["odometry_repeated_times"] = loaded.repeated.as_dict()
    return loaded.trajectory


def _same_times(est: Trajectory, ref: Trajectory) -> tuple[Trajectory, Trajectory]:
    """Synchronised pairs with one time base, so the ATE's nearest-time match is the pairing."""
    t = est.timestamps if np.all(np.diff(est.timestamps) > 0) else ref.timestamps
    return Trajectory(t, est.poses), Trajectory(t, ref.poses)


def _ate(
    estimate: Trajectory, reference: Trajectory, tol: float, n_to_align: int | None = None
) -> dict[str, Any]:
    """The ATE without alignment and with each alignment (``--ate``).

    Rigid and similarity (Umeyama), 4-DoF (3-D only: yaw and translation), origin (first
    pose on first pose) and affine (positions only: no rotation statistics, its map's
    ``matrix`` instead of a scale); each with its per-axis, in-plane and height errors.
    """
    out: dict[str, Any] = {}
    three_d = estimate.group.name == "SE3" or reference.group.name == "SE3"
    aligns = ("none", "se3", "sim3", "4dof") if three_d else ("none", "se2", "sim2")
    for align in aligns + ("origin", "affine"):
        r = absolute_trajectory_error(
            estimate, reference, align=align, max_time_diff=tol, n_to_align=n_to_align
        )
        entry: dict[str, Any] = {"translation": r.translation_stats.as_dict()}
        if isinstance(r.alignment, AffineAlignment):
            entry["matrix"] = r.alignment.matrix.tolist()
            entry["rank"] = r.alignment.rank
        else:
            entry["rotation"] = r.rotation_stats.as_dict()
            entry["scale"] = r.alignment.scale
        entry["matched"] = r.matched
        entry["aligned_on"] = r.aligned_on
        entry["axes"] = {k: v.as_dict() for k, v in r.axes.summaries().items()}
        out[align] = entry
    return out


def relation_axes(ev: Evaluation) -> dict[str, Any]:
    """Per-axis translational errors of the scored relations: summaries of ``|e_x|``,
    ``|e_y|`` (and ``|e_z|``), the in-plane ``‖(e_x, e_y)‖`` and (3-D) the height ``|e_z|``,
    where ``e = (δ_ij ⊖ δ*_ij)``'s translation is in the frame of the relation's first
    reference pose (the body frame: for KITTI's camera frame z is forward, y down).
    Unweighted (the metricEvaluator's weights do not apply)."""
    from relation_metric.alignment import AxisErrors

    dim = 3 if ev.relations.group.name == "SE3" else 2
    return AxisErrors(ev.errors.vector[ev.valid, :dim]).summaries()


def _kitti_drift(
    pair: tuple[Trajectory, Trajectory | None], tol: float, reference: str
) -> dict[str, Any]:
    """``--kitti-drift``: the devkit's drift on the pose-by-pose synchronised pairs."""
    from relation_metric.drift import kitti_drift

    estimate, ref = pair
    assert ref is not None  # checked by the caller
    ref_sync, est_sync = synchronize(ref, estimate, max_diff=tol)
    d = kitti_drift(ref_sync.lifted().poses, est_sync.lifted().poses)
    if d.segments == 0:
        length = float(ref_sync.path_length()[-1])
        raise InputError(
            f"no KITTI segment fits: the reference path is {length:.1f} m long over the "
            f"{len(ref_sync)} synchronised poses, shorter than the shortest segment (100 m)",
            path=reference,
        )
    out = d.as_dict()
    out["pairs"] = len(ref_sync)
    return out


def _offset(traj: Trajectory, t_offset: float) -> Trajectory:
    """``--t-offset``: the estimate with ``t_offset`` added to every timestamp."""
    if t_offset == 0.0:
        return traj
    return Trajectory(traj.timestamps + t_offset, traj.poses)


def _windowed(
    traj: Trajectory, options: EvaluateOptions, notes: dict[str, Any], path: str, role: str
) -> Trajectory:
    """``--t-start``/``--t-end``: the poses with ``t_start ≤ t ≤ t_end`` (counted in notes)."""
    if options.t_start is None and options.t_end is None:
        return traj
    t = traj.timestamps
    keep = np.ones(t.shape, dtype=bool)
    if options.t_start is not None:
        keep &= t >= options.t_start
    if options.t_end is not None:
        keep &= t <= options.t_end
    notes.setdefault("time_window_dropped", {})[role] = int(np.count_nonzero(~keep))
    if np.count_nonzero(keep) < 2:
        raise InputError(
            f"fewer than 2 poses lie in the time window [{options.t_start}, {options.t_end}] s "
            f"(the {role} spans {t[0]:.6f} .. {t[-1]:.6f} s"
            + (f" after --t-offset {options.t_offset:g}" if role == "estimate" else "")
            + ")",
            path=path,
        )
    return Trajectory(t[keep], traj.poses[keep])


def _relations_in_window(
    relations: RelationSet, options: EvaluateOptions, notes: dict[str, Any]
) -> RelationSet:
    """``--t-start``/``--t-end`` on a .relations file: relations with both ends inside."""
    if options.t_start is None and options.t_end is None:
        return relations
    lo = -np.inf if options.t_start is None else options.t_start
    hi = np.inf if options.t_end is None else options.t_end
    inside = (relations.first >= lo) & (relations.first <= hi)
    inside &= (relations.second >= lo) & (relations.second <= hi)
    notes.setdefault("time_window_dropped", {})["relations"] = int(np.count_nonzero(~inside))
    return relations.subset(inside)


def _generate_pairs(ref_sync: Trajectory, est_sync: Trajectory, options: EvaluateOptions) -> Any:
    """Relations on synchronised pairs, the pose pairs chosen on ``options.pairs_from``.

    ``"estimate"`` (evo's default): the strategy runs on the estimate (its path length, its
    times); the relations' ``δ*`` are still the reference's motions between the matched poses.
    """
    if options.pairs_from == "reference":
        return _generate(ref_sync, options, key="index")
    on_est = _generate(est_sync, options, key="index")
    i = on_est.first.astype(np.int64)
    j = on_est.second.astype(np.int64)
    return RelationSet.from_trajectory_pairs(ref_sync, i, j, key="index")


class DenserReferenceWarning(UserWarning):
    """The reference has many more poses per second than the estimate."""


#: A reference this many times denser than the estimate is warned about.
DENSER_FACTOR = 5.0


def _warn_denser_reference(
    ref: Trajectory, est: Trajectory, relations: RelationSet, reference: str
) -> None:
    """Relations generated on a much denser reference mostly join reference poses that
    map to the same or neighbouring estimate poses: say so (EuRoC: 200 Hz vs 10 Hz)."""
    if len(ref) < 2 or len(est) < 2:
        return
    ref_rate = (len(ref) - 1) / max(ref.span()[1] - ref.span()[0], 1e-300)
    est_rate = (len(est) - 1) / max(est.span()[1] - est.span()[0], 1e-300)
    if ref_rate > DENSER_FACTOR * est_rate:
        warnings.warn(
            f"{reference}: the reference has {ref_rate:.4g} poses/s, the estimate "
            f"{est_rate:.4g} ({ref_rate / est_rate:.3g}x denser): the {len(relations)} "
            "relations are generated between reference poses, most of whose ends share an "
            "estimate pose or lie between two; evo associates pose by pose first (--sync "
            "--max-time-diff 0.01)",
            DenserReferenceWarning,
            stacklevel=3,
        )


class ToleranceWarning(UserWarning):
    """The pose-by-pose association's tolerance is not evo's default."""


def _warn_evo_tolerance(max_time_diff: float) -> None:
    """``--sync`` with a tolerance other than evo's ``t_max_diff`` (0.01 s): say so."""
    if max_time_diff != EVO_MAX_TIME_DIFF:
        warnings.warn(
            f"--sync with --max-time-diff {max_time_diff:g} s: evo's default t_max_diff is "
            f"{EVO_MAX_TIME_DIFF:g} s, so evo pairs the poses differently; pass "
            f"--max-time-diff {EVO_MAX_TIME_DIFF:g} to match it",
            ToleranceWarning,
            stacklevel=3,
        )


@contextmanager
def in_option_words(words: Mapping[str, str]) -> Iterator[None]:
    """Say the library's parameters in the command's options, in errors and warnings.

    The libraries name what would change an outcome by the parameter of their call
    (``strict=True``, ``pass format=...``); the command knows which of its options sets it.
    Inside the block each phrase of ``words`` (``{"strict=True": "--strict"}``) is replaced
    by its option words in the message of an :class:`InputError` (re-raised with the same
    file and line) and of every warning (shown when the block ends, in order).
    """

    def say(text: str) -> str:
        for phrase, option in words.items():
            text = text.replace(phrase, option)
        return text

    caught: list[warnings.WarningMessage] = []
    try:
        with warnings.catch_warnings(record=True) as caught:
            yield
    except InputError as exc:
        said = say(exc.message)
        if said == exc.message:
            raise
        raise type(exc)(said, path=exc.path, line=exc.line) from None
    finally:
        for w in caught:
            warnings.warn_explicit(say(str(w.message)), w.category, w.filename, w.lineno)


def load_trajectory(
    path: str,
    fmt: str | None,
    *,
    pose: str = "laser",
    skip_invalid: bool = False,
    role: str = "reference",
    planar: bool = False,
    times: str | None = None,
    format_option: str = "--format",
    repeats: str | None = None,
    repeats_option: str = "",
) -> LoadedTrajectory:
    """Read a trajectory given to ``slamrel evaluate`` (or another command).

    ``role`` is what the trajectory is for:

    - ``"reference"``: a bundle directory means its ``groundtruth.csv`` (read under the
      filter-log time rule, as ``recover`` reads it); poses that repeat an earlier pose's
      timestamp are dropped, counted and warned about (:func:`without_repeated_times`).
    - ``"estimate"`` / ``"odometry"``: a bundle directory is refused (a bundle holds no
      estimated trajectory; its ground truth would be scored against itself); two different
      poses for one timestamp are refused naming both lines, exact repeats dropped and
      counted (:func:`without_exact_repeats`).

    Poses out of time order are sorted and counted (``LoadedTrajectory.time_order``).
    3-D formats (TUM, KITTI, EuRoC) are read as SE(3) when their motion leaves the plane;
    ``planar`` (``--planar``) projects them onto the plane with a warning that states the
    out-of-plane motion discarded. ``times`` is a KITTI times file. The reader's messages
    name the command's options (``format_option`` for its ``format``).

    ``repeats`` overrides the role's rule for poses sharing a timestamp: ``"keep"`` keeps
    them all as evo does (:func:`with_repeats_kept`), ``"first"`` keeps the first of each
    (:func:`first_of_each_timestamp`), ``"refuse"`` or None applies the role's rule above;
    either way they are counted and said. ``repeats_option`` names the command's option in
    the refusal.
    """
    p = Path(path)
    if p.is_dir() and not is_bag(p):
        if role != "reference":
            online = p / "online.csv"
            also = f", or pass {online} (the filter's online estimate)" if online.is_file() else ""
            raise InputError(
                f"is a directory (a SLAM result bundle?), given as the {role.upper()}; a bundle "
                "holds no estimated trajectory, only the ground truth: recover one with "
                f"'slamrel recover {path} -o est.tum' and pass est.tum{also}",
                path=path,
            )
        gt = p / "groundtruth.csv"
        if not gt.is_file():
            raise InputError(
                "is a directory without groundtruth.csv; expected a trajectory file or a "
                "SLAM result bundle with ground truth",
                path=path,
            )
        loaded = read_trajectory(gt, format="csv", max_step_back=FILTER_TIME_TOLERANCE)
        return without_repeated_times(loaded, gt)
    if fmt is not None and fmt not in TRAJECTORY_FORMATS:
        raise InputError(f"unknown format {fmt!r}", path=path)
    words = {
        "format=...": format_option,
        "skip_invalid=True": "the metricevaluator mode, or --skip-invalid-poses,",
        'dimension="2d"': "--planar",
    }
    with in_option_words(words):
        loaded = read_trajectory(
            path,
            format=fmt,
            pose=pose,  # type: ignore[arg-type]
            skip_invalid=skip_invalid,
            dimension="2d" if planar else "auto",
            times=times,
        )
    if repeats == "keep":
        return with_repeats_kept(loaded, path, what=role)
    if repeats == "first":
        return first_of_each_timestamp(loaded, path, what=role)
    if role == "reference":
        return without_repeated_times(loaded, path)
    hint = f"; {repeats_option} keep reads it as evo does" if repeats_option else ""
    return without_exact_repeats(loaded, path, what=role, hint=hint)
