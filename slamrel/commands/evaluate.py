"""``slamrel evaluate``: score an estimate with the relation metric."""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Any

import numpy as np

from relation_metric.alignment import absolute_trajectory_error
from relation_metric.evaluate import Evaluation, evaluate
from relation_metric.formats import TRAJECTORY_FORMATS
from relation_metric.metric import MODES
from relation_metric.relations import RelationSet, read_relations
from relation_metric.results import write_evo_zip, write_json, write_per_relation_csv
from relation_metric.trajectory import Trajectory
from slamrel.commands import options as opt
from slamrel.commands.common import (
    add_strategy_arguments,
    check_outputs,
    load_trajectory_arg,
    relations_from_args,
    stats_table,
)

HELP = "score an estimated trajectory against reference relations"


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "evaluate",
        help=HELP,
        description=HELP
        + ". REFERENCE is a Freiburg .relations file, or a reference trajectory (or a SLAM "
        "result bundle with groundtruth.csv) from which relations are generated with "
        "--strategy.",
    )
    p.add_argument("reference", metavar="REFERENCE", help=".relations file or reference trajectory")
    p.add_argument(
        "estimate", metavar="ESTIMATE", help="estimated trajectory (CARMEN, TUM, t x y θ, g2o, CSV)"
    )
    p.add_argument(
        "--format", choices=TRAJECTORY_FORMATS, help="format of ESTIMATE (default: recognised)"
    )
    p.add_argument(
        "--reference-format", choices=TRAJECTORY_FORMATS, help="format of a reference trajectory"
    )
    p.add_argument("--odometry", metavar="LOG", help="odometry log that corrects far timestamps")
    p.add_argument("--odometry-format", choices=TRAJECTORY_FORMATS)
    p.add_argument(
        "--max-time-diff",
        type=opt.nonnegative_float,
        default=0.1,
        metavar="S",
        help="nearest-pose tolerance [s] (default 0.1)",
    )
    p.add_argument(
        "--interpolate", action="store_true", help="interpolate on SE(2) beyond the tolerance"
    )
    p.add_argument(
        "--max-interpolation-gap",
        type=opt.positive_float,
        default=1.0,
        metavar="S",
        help="longest gap interpolated over [s]",
    )
    p.add_argument(
        "--mode", choices=MODES, default="paper", help="error definition (default: paper)"
    )
    p.add_argument(
        "--weights",
        type=opt.weights,
        metavar="W",
        help="wx,wy,wz,wroll,wpitch,wyaw (default all 1)",
    )
    p.add_argument("--degrees", action="store_true", help="report rotation in degrees")
    p.add_argument("--strict", action="store_true", help="unassociated relations are an error")
    p.add_argument(
        "--skip-invalid-poses",
        action="store_true",
        help="skip CARMEN pose records with non-finite values "
        "(counted; default in metricevaluator mode)",
    )
    p.add_argument(
        "--ate",
        action="store_true",
        help="also the aligned absolute trajectory error (needs a reference trajectory)",
    )
    p.add_argument("--json", metavar="FILE", help="write the results as JSON")
    p.add_argument("--per-relation", metavar="FILE", help="write per-relation errors as CSV")
    p.add_argument(
        "--plot", type=opt.figure_file, metavar="FILE", help="write a figure (.png/.svg/.pdf)"
    )
    p.add_argument("--evo-zip", metavar="FILE", help="write an evo result zip (for evo_res)")
    p.add_argument(
        "--evo-part",
        choices=("trans", "rot"),
        default="trans",
        help="which error the evo zip holds",
    )
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")
    add_strategy_arguments(p, default=None)
    p.set_defaults(func=run)


def _is_relations_file(path: str, args: argparse.Namespace) -> bool:
    if args.strategy is not None or args.reference_format is not None or Path(path).is_dir():
        return False
    return Path(path).suffix.lower() in (".relations", ".rel") or _looks_like_relations(path)


def _looks_like_relations(path: str) -> bool:
    from relation_metric.formats import detect_trajectory_format

    try:
        fmt = detect_trajectory_format(path)
    except Exception:
        return True  # let the relations reader produce the precise error
    return fmt == "tum"  # 8 numeric columns: a .relations file unless --strategy says otherwise


def load_reference(args: argparse.Namespace) -> tuple[RelationSet, Trajectory | None]:
    """Relations from a .relations file, or generated from a reference trajectory."""
    if _is_relations_file(args.reference, args):
        return read_relations(args.reference), None
    reference = load_trajectory_arg(args.reference, args.reference_format).trajectory
    if args.strategy is None:
        args.strategy = "consecutive"
    return relations_from_args(reference, args), reference


def run(args: argparse.Namespace) -> int:
    outputs = [args.json, args.per_relation, args.plot, args.evo_zip]
    check_outputs(outputs, [args.reference, args.estimate, args.odometry])
    relations, reference = load_reference(args)
    skip = args.skip_invalid_poses or args.mode == "metricevaluator"
    estimate = load_trajectory_arg(args.estimate, args.format, skip_invalid=skip)
    odometry = None
    if args.odometry:
        odometry = load_trajectory_arg(
            args.odometry, args.odometry_format, pose="odometry", skip_invalid=skip
        ).trajectory
    ev = evaluate(
        relations,
        estimate.trajectory,
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
    result = ev.as_dict(degrees=args.degrees)
    if estimate.skipped:
        result["estimate_records_skipped"] = dict(estimate.skipped)
    if args.ate:
        if reference is None:
            from relation_metric.errors import InputError

            raise InputError(
                "--ate needs a reference trajectory, not a .relations file", path=args.reference
            )
        result["ate"] = _ate(estimate.trajectory, reference, args.max_time_diff)
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
        from relation_metric.plots import evaluation_figure, save_figure

        save_figure(evaluation_figure(ev, estimate.trajectory, degrees=args.degrees), args.plot)
    if not args.quiet:
        print(summary_text(ev, result, degrees=args.degrees))
    return 0


def _ate(estimate: Trajectory, reference: Trajectory, tol: float) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for align in ("none", "se2", "sim2"):
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
    from relation_metric.evaluate import error_summaries

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
    )
    text = head + "\n" + stats_table(rows)
    if "ate" in result:
        a = result["ate"]
        text += "\nATE translation rmse [m]: " + ", ".join(
            f"{k} {a[k]['translation']['rmse']:.6f}" for k in ("none", "se2", "sim2")
        )
    return text
