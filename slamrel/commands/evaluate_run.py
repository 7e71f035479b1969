"""The work of ``slamrel evaluate`` (imported when the command runs, not to build its parser)."""

from __future__ import annotations

import argparse
import dataclasses
import os
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from relation_metric.alignment import absolute_trajectory_error
from relation_metric.errors import InputError
from relation_metric.evaluate import Evaluation, error_summaries, evaluate
from relation_metric.relations import RelationSet
from relation_metric.time_association import synchronize
from relation_metric.timeorder import RepeatedTimeWarning, zero_length
from relation_metric.trajectory import Trajectory
from slamrel.commands.common import (
    check_outputs,
    in_option_words,
    load_trajectory_arg,
    relations_from_args,
    stats_table,
)
from slamrel.evaluation_options import SCORING_OPTIONS
from slamrel.formats.relations import read_relations
from slamrel.formats.results import write_evo_zip, write_json, write_per_relation_csv
from slamrel.formats.text import read_numeric_table, read_source
from slamrel.formats.trajectories import (
    RELATIONS_EXTENSIONS,
    TRAJECTORY_EXTENSIONS,
    LoadedTrajectory,
    PlanarProjectionWarning,
    sniff_trajectory_format,
)


def _is_relations_file(path: str, args: argparse.Namespace) -> bool:
    """Whether REFERENCE is read as a Freiburg .relations file: the extension decides first.

    ``.relations``/``.rel`` → relations; an extension that names a trajectory format
    (``.tum``, ``.csv``, ``.g2o``, ``.log``, ``.clf``), ``--reference-format``, ``--strategy``
    or a directory → a reference trajectory. Other files are sniffed; 8 numeric columns fit
    both readings and are told apart by their last four columns
    (:func:`_eight_columns_are_relations`), the guess said in a warning.
    """

    p = Path(path)
    if p.is_dir() or args.reference_format is not None:
        return False
    ext = p.suffix.lower()
    if ext in RELATIONS_EXTENSIONS:
        if args.strategy is not None:
            raise InputError(
                f"a {ext} file holds relations, but --strategy generates relations from a "
                "reference trajectory; drop --strategy, or pass --reference-format to read "
                "the file as a trajectory",
                path=path,
            )
        return True
    if ext in TRAJECTORY_EXTENSIONS or args.strategy is not None:
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


def _eight_columns_are_relations(path: str) -> bool:
    """Tell a TUM trajectory from Freiburg relations, both 8 numbers a line, by content.

    A TUM file's last four columns are unit quaternions (its reader refuses any other); a
    relations file's are ``z roll pitch yaw``, whose norm is 1 only by accident. Every row a
    unit quaternion (≥ 2 rows) → TUM; otherwise relations. Either way the guess is said in a
    warning with how to state it; a file that cannot be told apart (fewer than 2 rows, all
    unit) is refused naming both readings.
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
    args: argparse.Namespace, notes: dict[str, Any] | None = None
) -> tuple[RelationSet, Trajectory | None]:
    """Relations from a .relations file, or generated from a reference trajectory.

    What was dropped or reordered on the way is added to ``notes`` (JSON-ready):
    ``relations_zero_length_dropped`` for a .relations file; ``reference_out_of_order`` and
    ``reference_repeated_times_dropped`` for a reference trajectory.
    """

    notes = {} if notes is None else notes
    if _is_relations_file(args.reference, args):
        relations = read_relations(args.reference)
        zero = zero_length(relations.first, relations.second)
        dropped = int(np.count_nonzero(zero))
        notes["relations_zero_length_dropped"] = dropped
        if dropped:
            warnings.warn(
                f"{args.reference}: dropped {dropped} relation(s) with t1 == t2 (zero-length "
                "relations would score 0 and pull the mean down)",
                RepeatedTimeWarning,
                stacklevel=2,
            )
            relations = relations.subset(~zero)
        if relations.has_out_of_plane and args.planar:
            assert relations.out_of_plane is not None  # has_out_of_plane: there are some
            oop = np.abs(relations.out_of_plane)
            warnings.warn(
                f"{args.reference}: 6-DoF relations scored in 2-D (--planar): discarding "
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
    loaded = load_trajectory_arg(
        args.reference,
        args.reference_format,
        role="reference",
        planar=args.planar,
        times=args.reference_times,
        format_option="--reference-format",
    )
    ref = Path(args.reference)
    _refuse_if_strict(args, loaded, str(ref / "groundtruth.csv" if ref.is_dir() else ref))
    _note_projection(notes, "reference", loaded)
    notes["reference_out_of_order"] = loaded.time_order.as_dict()
    notes["reference_repeated_times_dropped"] = loaded.repeated_dropped
    if args.strategy is None:
        args.strategy = "consecutive"
    if args.sync:  # relations are generated after the pose-by-pose association, in run()
        return RelationSet(np.empty(0), np.empty(0), np.empty((0, 3))), loaded.trajectory
    return relations_from_args(loaded.trajectory, args), loaded.trajectory


def _note_projection(notes: dict[str, Any], role: str, loaded: LoadedTrajectory) -> None:
    """``--planar``: what the projection of a 3-D file discarded, for ``--json``."""
    if loaded.discarded is not None:
        notes.setdefault("planar_projection", {})[role] = dict(loaded.discarded._asdict())


def _refuse_if_strict(args: argparse.Namespace, loaded: LoadedTrajectory, path: str) -> None:
    """``--strict``: a trajectory that was not in time order is an error (file:line)."""
    if args.strict and loaded.out_of_order:
        raise InputError(
            f"{loaded.time_order.describe('pose')}; --strict refuses a trajectory that is not "
            "in time order (without --strict its poses are put in time order and counted)",
            path=path,
            line=loaded.time_order.first_line,
        )


def _warn_same_file(args: argparse.Namespace) -> None:
    """The same file as REFERENCE and ESTIMATE scores every relation 0: say so."""
    ref = Path(args.reference)
    ref_file = ref / "groundtruth.csv" if ref.is_dir() else ref
    if os.path.realpath(ref_file) == os.path.realpath(args.estimate):
        warnings.warn(
            f"{args.estimate}: given as both REFERENCE and ESTIMATE; the estimate is scored "
            "against itself (every error 0)",
            UserWarning,
            stacklevel=2,
        )


def run(args: argparse.Namespace) -> int:
    """``slamrel evaluate``: outputs checked, then :func:`score`, then written and printed."""
    outputs = [args.json, args.per_relation, args.plot, args.evo_zip]
    check_outputs(outputs, [args.reference, args.estimate, args.odometry])
    ev, ev_estimate, result = score(args)
    _write_outputs(args, ev, ev_estimate, result)
    if not args.quiet:
        print(summary_text(ev, result, degrees=args.degrees))
    return 0


def score(args: argparse.Namespace) -> tuple[Evaluation, Trajectory, dict[str, Any]]:
    """Read REFERENCE and ESTIMATE as ``slamrel evaluate`` does and score the estimate.

    Returns the evaluation, the estimate it scored (lifted to SE(3) for 3-D relations) and
    the JSON of ``--json`` (the evaluation, what was dropped or reordered, the ATE).
    """
    _warn_same_file(args)
    notes: dict[str, Any] = {}
    relations, reference = load_reference(args, notes)
    skip = args.skip_invalid_poses or args.mode == "metricevaluator"
    estimate = load_trajectory_arg(
        args.estimate,
        args.format,
        skip_invalid=skip,
        role="estimate",
        planar=args.planar,
        times=args.times,
    )
    _refuse_if_strict(args, estimate, args.estimate)
    _note_projection(notes, "estimate", estimate)
    notes["estimate_out_of_order"] = estimate.time_order.as_dict()
    odometry = _load_odometry(args, skip, notes) if args.odometry else None
    scored = estimate.trajectory
    ate_pair = (estimate.trajectory, reference)
    if args.sync:
        if reference is None:
            raise InputError(
                "--sync needs a reference trajectory, not a .relations file", path=args.reference
            )
        ref_sync, est_sync = synchronize(reference, scored, max_diff=args.max_time_diff)
        notes["synchronized_pairs"] = len(ref_sync)
        relations = relations_from_args(ref_sync, args, key="index")
        scored = est_sync
        ate_pair = _same_times(est_sync, ref_sync)
    with in_option_words({"strict=True": "--strict"}):
        ev = evaluate(
            relations,
            scored,
            odometry=odometry,
            mode=args.mode,
            weights=args.weights,
            max_time_diff=args.max_time_diff,
            interpolate=args.interpolate,
            max_interpolation_gap=args.max_interpolation_gap,
            strict=args.strict,
            estimate_name=args.estimate,
            relations_name=args.reference,
        )
    if args.sync:  # name the pose pairs by the reference's times in the outputs (CSV, zip, plot)
        i = ev.relations.first.astype(np.int64)
        j = ev.relations.second.astype(np.int64)
        t = ref_sync.timestamps
        ev = dataclasses.replace(
            ev, relations=RelationSet(t[i], t[j], ev.relations.delta, key="time")
        )
    ev_estimate = scored.lifted() if ev.relations.group.name == "SE3" else scored
    result = ev.as_dict(degrees=args.degrees)
    result["group"] = ev.relations.group.name
    if estimate.skipped:
        result["estimate_records_skipped"] = dict(estimate.skipped)
    result.update(notes)
    if args.ate:
        if reference is None:
            raise InputError(
                "--ate needs a reference trajectory, not a .relations file", path=args.reference
            )
        ate_estimate, ate_reference = ate_pair
        assert ate_reference is not None  # the reference (just checked) or its synchronised copy
        result["ate"] = _ate(ate_estimate, ate_reference, args.max_time_diff)
    return ev, ev_estimate, result


def evaluate_files(
    reference: str | os.PathLike[str], estimate: str | os.PathLike[str], **options: Any
) -> Evaluation:
    """``slamrel evaluate REFERENCE ESTIMATE [options]`` as a function: its evaluation.

    The files are read and scored exactly as the command does (REFERENCE a ``.relations``
    file, a reference trajectory or a bundle directory; the time-order rule; repeated
    reference times and zero-length relations dropped; see the README), with each option of
    :data:`SCORING_OPTIONS` given under its Python name and with the command's default when
    omitted, e.g. ``evaluate_files(ref, est, strategy="loops", radius=2.0,
    max_time_diff=0.05)``. What is dropped or reordered on the way is said in warnings.
    Values are taken as given (a ``weights`` string as ``"1,1,0,0,0,0"``); the library
    checks them where the command's parser would.

    Raises
    ------
    TypeError
        For an option that is not in :data:`SCORING_OPTIONS`.
    InputError
        For anything wrong with the files (file and line named), as the command.
    """
    unknown = sorted(set(options) - set(SCORING_OPTIONS))
    if unknown:
        raise TypeError(
            f"evaluate_files() got unknown options {', '.join(unknown)}; expected some of "
            + ", ".join(SCORING_OPTIONS)
        )
    from slamrel.commands import evaluate as command

    parser = argparse.ArgumentParser(prog="slamrel")
    command.register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["evaluate", "--", os.fspath(reference), os.fspath(estimate)])
    for name, value in options.items():
        setattr(args, name, value)
    return score(args)[0]


def _load_odometry(args: argparse.Namespace, skip: bool, notes: dict[str, Any]) -> Trajectory:
    """The ``--odometry`` log (refused with ``--strict`` when out of time order)."""
    loaded = load_trajectory_arg(
        args.odometry,
        args.odometry_format,
        pose="odometry",
        skip_invalid=skip,
        role="odometry",
        planar=args.planar,
        format_option="--odometry-format",
    )
    _refuse_if_strict(args, loaded, args.odometry)
    notes["odometry_out_of_order"] = loaded.time_order.as_dict()
    return loaded.trajectory


def _write_outputs(
    args: argparse.Namespace, ev: Evaluation, ev_estimate: Trajectory, result: dict[str, Any]
) -> None:
    """``--json``, ``--per-relation``, ``--evo-zip`` and ``--plot``, in that order."""
    if args.json:
        write_json(args.json, result)
    if args.per_relation:
        write_per_relation_csv(args.per_relation, ev, degrees=args.degrees)
    if args.evo_zip:
        write_evo_zip(
            args.evo_zip,
            ev,
            part=args.evo_part,
            est_name=os.path.basename(args.estimate),
            ref_name=os.path.basename(args.reference),
            degrees=args.degrees,
        )
    if args.plot:
        from slamrel.plots.relation_errors import evaluation_figure, save_figure

        save_figure(evaluation_figure(ev, ev_estimate, degrees=args.degrees), args.plot)


def _same_times(est: Trajectory, ref: Trajectory) -> tuple[Trajectory, Trajectory]:
    """Synchronised pairs with one time base, so the ATE's nearest-time match is the pairing."""
    t = est.timestamps if np.all(np.diff(est.timestamps) > 0) else ref.timestamps
    return Trajectory(t, est.poses), Trajectory(t, ref.poses)


def _ate(estimate: Trajectory, reference: Trajectory, tol: float) -> dict[str, Any]:

    out: dict[str, Any] = {}
    three_d = estimate.group.name == "SE3" or reference.group.name == "SE3"
    for align in ("none", "se3", "sim3") if three_d else ("none", "se2", "sim2"):
        r = absolute_trajectory_error(estimate, reference, align=align, max_time_diff=tol)
        out[align] = {
            "translation": r.translation_stats.as_dict(),
            "rotation": r.rotation_stats.as_dict(),
            "scale": r.alignment.scale,
            "matched": r.matched,
        }
    return out


def summary_text(ev: Evaluation, result: dict[str, Any], *, degrees: bool) -> str:
    """The console summary of an evaluation."""

    unit = "deg" if degrees else "rad"
    rot_values = ev.errors.rotation[ev.valid]
    rot = error_summaries(np.degrees(rot_values) if degrees else rot_values)
    rows = [
        ("translation abs [m]", ev.translation["abs"]),
        ("translation sqr [m²]", ev.translation["sqr"]),
        (f"rotation abs [{unit}]", rot["abs"]),
        (f"rotation sqr [{unit}²]", rot["sqr"]),
    ]
    if ev.errors.mode == "metricevaluator":
        rows.append(("weighted (metricEvaluator)", ev.combined["abs"]))
    head = (
        f"relations: {result['relations']} ({result['associated_by_odometry']} via odometry, "
        f"{result['interpolated']} interpolated, {result['unassociated']} unassociated); "
        f"mode: {ev.errors.mode}"
        + (f"; {ev.relations.group.name}" if ev.relations.group.name == "SE3" else "")
    )
    text = head + "\n" + stats_table(rows)
    for name in ("estimate", "odometry", "reference"):
        order = result.get(f"{name}_out_of_order")
        if order and order["count"]:
            text += (
                f"\n{name}: {order['count']} pose(s) out of time order (largest step back "
                f"{order['max_step_back_s']:.6f} s, first at line {order['first_line']}); "
                "put in time order"
            )
    if result.get("reference_repeated_times_dropped"):
        text += (
            f"\nreference: {result['reference_repeated_times_dropped']} pose(s) repeating an "
            "earlier timestamp dropped"
        )
    if result.get("relations_zero_length_dropped"):
        text += (
            f"\nrelations: {result['relations_zero_length_dropped']} zero-length (t1 == t2) dropped"
        )
    if "ate" in result:
        a = result["ate"]
        text += "\nATE translation rmse [m]: " + ", ".join(
            f"{k} {v['translation']['rmse']:.6f}" for k, v in a.items()
        )
    return text
