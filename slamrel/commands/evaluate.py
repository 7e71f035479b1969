"""``slamrel evaluate``: score an estimate with the relation metric.

The parser (built on every ``slamrel --help``: no numpy) takes its scoring defaults from
:class:`~slamrel.evaluation_options.EvaluateOptions`; :func:`run` scores the files with
:func:`slamrel.evaluation.score_files` and writes the outputs.
"""

from __future__ import annotations

import argparse
import os
from types import SimpleNamespace
from typing import TYPE_CHECKING

from relation_metric.constants import MODES
from slamrel.commands import options as opt
from slamrel.commands.common import add_strategy_arguments, check_outputs, stats_table
from slamrel.constants import EVALUATE_DEFAULTS, TRAJECTORY_FORMATS

if TYPE_CHECKING:  # the library is imported in run(): start-up stays light
    from slamrel.evaluation import FileEvaluation

#: The defaults of the scoring options (defined once: slamrel.constants.EVALUATE_DEFAULTS).
DEFAULT = SimpleNamespace(**EVALUATE_DEFAULTS)

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
    _input_arguments(p)
    _association_arguments(p)
    _output_arguments(p)
    _view_arguments(p)
    add_strategy_arguments(p, default=DEFAULT.strategy)
    p.set_defaults(func=run)


def _input_arguments(p: argparse.ArgumentParser) -> None:
    """REFERENCE, ESTIMATE and their formats."""
    p.add_argument("reference", metavar="REFERENCE", help=".relations file or reference trajectory")
    p.add_argument(
        "estimate",
        metavar="ESTIMATE",
        help="estimated trajectory (CARMEN, TUM, t x y θ, g2o, CSV, KITTI, EuRoC)",
    )
    p.add_argument(
        "--format", choices=TRAJECTORY_FORMATS, help="format of ESTIMATE (default: recognised)"
    )
    p.add_argument(
        "--reference-format", choices=TRAJECTORY_FORMATS, help="format of a reference trajectory"
    )


def _association_arguments(p: argparse.ArgumentParser) -> None:
    """Timestamp association, error definition and what counts as an error."""
    p.add_argument("--odometry", metavar="LOG", help="odometry log that corrects far timestamps")
    p.add_argument("--odometry-format", choices=TRAJECTORY_FORMATS)
    p.add_argument(
        "--max-time-diff",
        type=opt.nonnegative_float,
        default=DEFAULT.max_time_diff,
        metavar="S",
        help="nearest-pose tolerance [s] (default %(default)s)",
    )
    p.add_argument(
        "--interpolate", action="store_true", help="interpolate on SE(2)/SE(3) beyond the tolerance"
    )
    p.add_argument(
        "--max-interpolation-gap",
        type=opt.positive_float,
        default=DEFAULT.max_interpolation_gap,
        metavar="S",
        help="longest gap interpolated over [s]",
    )
    p.add_argument(
        "--mode",
        choices=MODES,
        default=DEFAULT.mode,
        help="error definition (default: %(default)s)",
    )
    p.add_argument(
        "--weights",
        type=opt.weights,
        metavar="W",
        help="wx,wy,wz,wroll,wpitch,wyaw (default all 1)",
    )
    p.add_argument("--degrees", action="store_true", help="report rotation in degrees")
    p.add_argument(
        "--strict",
        action="store_true",
        help="unassociated relations, and trajectories not in time order, are an error",
    )
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


def _output_arguments(p: argparse.ArgumentParser) -> None:
    """The files written besides the printed table."""
    p.add_argument("--json", metavar="FILE", help="write the results as JSON")
    p.add_argument(
        "--per-relation",
        metavar="FILE",
        help="write per-relation errors as CSV (for slamrel compare; relations generated "
        "with --strategy carry its name in a column 'set')",
    )
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


def _view_arguments(p: argparse.ArgumentParser) -> None:
    """How 3-D inputs are scored, evo-style synchronisation, KITTI times, quiet."""
    p.add_argument(
        "--planar",
        action="store_true",
        help="score 3-D inputs (TUM/KITTI/EuRoC with out-of-plane motion, 6-DoF relations) in "
        "2-D: z, roll and pitch are discarded, with a warning that states how much",
    )
    p.add_argument(
        "--sync",
        action="store_true",
        help="associate reference and estimate pose by pose first, as evo does (nearest time "
        "within --max-time-diff; use 0.01 for evo's default t_max_diff), then generate the "
        "relations on the matched poses (needs a reference trajectory)",
    )
    p.add_argument("--times", metavar="FILE", help="KITTI ESTIMATE: timestamps, one a line")
    p.add_argument("--reference-times", metavar="FILE", help="KITTI REFERENCE: timestamps")
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")


def run(args: argparse.Namespace) -> int:
    """``slamrel evaluate``: outputs checked, the files scored, the outputs written and printed.

    The library is imported here, not when the parser is built.
    """
    from slamrel.evaluation import score_files
    from slamrel.evaluation_options import SCORING_OPTIONS, EvaluateOptions

    outputs = [args.json, args.per_relation, args.plot, args.evo_zip]
    check_outputs(outputs, [args.reference, args.estimate, args.odometry])
    options = EvaluateOptions(**{name: getattr(args, name) for name in SCORING_OPTIONS})
    scored = score_files(args.reference, args.estimate, options, degrees=args.degrees, ate=args.ate)
    _write_outputs(args, scored)
    if not args.quiet:
        print(summary_text(scored, degrees=args.degrees))
    return 0


def _write_outputs(args: argparse.Namespace, scored: FileEvaluation) -> None:
    """``--json``, ``--per-relation``, ``--evo-zip`` and ``--plot``, in that order."""
    from slamrel.formats.results import write_evo_zip, write_json, write_per_relation_csv

    ev = scored.evaluation
    if args.json:
        write_json(args.json, scored.result)
    if args.per_relation:
        sets = None
        if scored.relation_set is not None:
            sets = [scored.relation_set] * len(ev.relations)
        write_per_relation_csv(args.per_relation, ev, degrees=args.degrees, relation_sets=sets)
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

        save_figure(evaluation_figure(ev, scored.estimate, degrees=args.degrees), args.plot)


def summary_text(scored: FileEvaluation, *, degrees: bool) -> str:
    """The console summary of an evaluation."""
    import numpy as np

    from relation_metric.evaluate import error_summaries

    ev, result = scored.evaluation, scored.result
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
    dup = result.get("relations_duplicates")
    if dup and dup["count"]:
        done = "dropped" if dup["dropped"] else "kept (metricevaluator mode)"
        text += (
            f"\nrelations: {dup['count']} line(s) repeating an earlier line exactly {done}, "
            f"first at line {dup['first_line']}"
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
