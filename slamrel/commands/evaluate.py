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
from slamrel.commands.common import (
    add_strategy_arguments,
    check_outputs,
    input_files,
    stats_table,
)
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
    p.add_argument(
        "reference",
        metavar="REFERENCE",
        help=".relations file or reference trajectory (a ROS bag topic as BAG:TOPIC)",
    )
    p.add_argument(
        "estimate",
        metavar="ESTIMATE",
        help="estimated trajectory (CARMEN, TUM, t x y θ, g2o, CSV, KITTI, EuRoC, or a ROS bag "
        "topic BAG:TOPIC / tf chain BAG:/tf:PARENT.CHILD with the 'bags' extra)",
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
    p.add_argument(
        "--evo-zip",
        metavar="FILE",
        help="write the relation errors as an evo result zip (for evo_res); its title is "
        "evo_rpe's when the relations are evo's RPE pairs (--sync with --strategy consecutive, "
        "or distance --chained, mode paper), so evo_res reads it beside evo's own zips",
    )
    p.add_argument(
        "--evo-ape-zip",
        metavar="FILE",
        help="write the absolute pose error as an evo_ape result zip (for evo_res; needs a "
        "reference trajectory), aligned by --evo-ape-align",
    )
    p.add_argument(
        "--evo-ape-align",
        choices=("none", "se3", "sim3"),
        default="none",
        help="alignment of --evo-ape-zip: none (evo_ape's default), se3 (-a) or sim3 (-as); "
        "se2/sim2 for planar trajectories (default: %(default)s)",
    )
    p.add_argument(
        "--evo-part",
        choices=("trans", "rot"),
        default="trans",
        help="which error the evo zips hold: translation [m] or rotation angle [rad, deg with "
        "--degrees] (default: %(default)s)",
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

    outputs = [args.json, args.per_relation, args.plot, args.evo_zip, args.evo_ape_zip]
    check_outputs(outputs, input_files([args.reference, args.estimate, args.odometry]))
    options = EvaluateOptions(**{name: getattr(args, name) for name in SCORING_OPTIONS})
    scored = score_files(args.reference, args.estimate, options, degrees=args.degrees, ate=args.ate)
    _write_outputs(args, scored)
    if not args.quiet:
        print(summary_text(scored, degrees=args.degrees))
    return 0


def _write_outputs(args: argparse.Namespace, scored: FileEvaluation) -> None:
    """``--json``, ``--per-relation``, ``--evo-zip`` and ``--plot``, in that order."""
    from slamrel.formats.results import (
        evo_delta,
        write_evo_zip,
        write_json,
        write_per_relation_csv,
    )

    ev = scored.evaluation
    if args.json:
        write_json(args.json, scored.result)
    if args.per_relation:
        sets = None
        if scored.relation_set is not None:
            sets = [scored.relation_set] * len(ev.relations)
        write_per_relation_csv(args.per_relation, ev, degrees=args.degrees, relation_sets=sets)
    if args.evo_zip:
        delta = evo_delta(
            sync=args.sync,
            strategy=args.strategy,
            step=args.step,
            distance=args.distance,
            chained=args.chained,
            mode=args.mode,
        )
        write_evo_zip(
            args.evo_zip,
            ev,
            part=args.evo_part,
            est_name=_evo_name(args.estimate),
            ref_name=_evo_name(args.reference),
            degrees=args.degrees,
            delta=delta if args.weights is None else None,
        )
    if args.evo_ape_zip:
        _write_evo_ape(args, scored)
    if args.plot:
        from slamrel.plots.relation_errors import evaluation_figure, save_figure

        save_figure(evaluation_figure(ev, scored.estimate, degrees=args.degrees), args.plot)


def _evo_name(path: str) -> str:
    """The name evo gives a trajectory: a bag topic's name, else the file's name."""
    from slamrel.formats.bags import split_bag_spec

    spec = split_bag_spec(path)
    return os.path.basename(path) if spec is None else spec.topic


def _write_evo_ape(args: argparse.Namespace, scored: FileEvaluation) -> None:
    """``--evo-ape-zip``: the APE of the (synchronised) estimate after ``--evo-ape-align``."""
    from relation_metric.alignment import absolute_trajectory_error
    from relation_metric.errors import OptionError
    from slamrel.formats.results import write_evo_ape_zip

    if scored.ate_inputs is None:
        raise OptionError(
            f"needs a reference trajectory, not a .relations file ({args.reference})",
            option="--evo-ape-zip",
        )
    est, ref = scored.ate_inputs
    align = args.evo_ape_align
    planar = est.group.name == "SE2" and ref.group.name == "SE2"
    if planar and align != "none":
        align = {"se3": "se2", "sim3": "sim2"}[align]
    r = absolute_trajectory_error(est, ref, align=align, max_time_diff=args.max_time_diff)
    if args.evo_part == "trans":
        errors, part = r.translation, "trans"
    else:
        import numpy as np

        errors = np.degrees(r.rotation) if args.degrees else r.rotation
        part = "rot_deg" if args.degrees else "rot"
    assert r.timestamps is not None  # absolute_trajectory_error sets them
    write_evo_ape_zip(
        args.evo_ape_zip,
        errors,
        r.timestamps,
        part=part,
        align=align,
        est_name=_evo_name(args.estimate),
        ref_name=_evo_name(args.reference),
    )


def ate_text(ate: dict, *, degrees: bool) -> str:
    """The ATE of ``--ate`` as evo prints an APE: rmse, mean, median, std, min, max, sse.

    One row per alignment and part; ``std`` here is evo's, the population standard deviation
    (the JSON's ``std`` is the sample one, n − 1); ``sse = Σ e² = rmse² · n``.
    """
    import math

    unit = "deg" if degrees else "rad"
    names = ("rmse", "mean", "median", "std", "min", "max", "sse", "count")
    rows = []
    for part, label in (("translation", "translation [m]"), ("rotation", f"rotation [{unit}]")):
        scale = math.degrees(1.0) if degrees and part == "rotation" else 1.0  # the JSON's rad
        for align, r in ate.items():
            s, n = r[part], r["matched"]
            std = s["std"] * math.sqrt((n - 1) / n) if n > 1 and s["std"] is not None else 0.0
            vals = [s["rmse"], s["mean"], s["median"], std, s["min"], s["max"]]
            vals = [v * scale for v in vals] + [(s["rmse"] * scale) ** 2 * n]
            rows.append((f"ATE {label} {align}", vals, n))
    width = max(len(label) for label, _, _ in rows)
    lines = [" " * width + "".join(f"{k:>15}" for k in names)]
    for label, vals, n in rows:
        lines.append(f"{label:<{width}}" + "".join(f"{v:>15.6f}" for v in vals) + f"{n:>15d}")
    return "\n".join(lines) + "\n(std: population, as evo; the JSON's std is the sample std)"


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
        text += "\n" + ate_text(result["ate"], degrees=degrees)
    return text
