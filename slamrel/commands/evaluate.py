"""``slamrel evaluate``: score an estimate with the relation metric.

The parser (built on every ``slamrel --help``: no numpy) takes its scoring defaults from
:class:`~slamrel.evaluation_options.EvaluateOptions`; :func:`run` scores the files with
:func:`slamrel.evaluation.score_files` and writes the outputs.
"""

from __future__ import annotations

import argparse
import os
import textwrap
from types import SimpleNamespace
from typing import TYPE_CHECKING

from relation_metric.constants import MODES
from slamrel.commands import options as opt
from slamrel.commands.common import (
    add_strategy_arguments,
    add_sync_arguments,
    add_time_window_arguments,
    add_tolerance_argument,
    check_outputs,
    check_time_window,
    input_files,
    stats_table,
)
from slamrel.constants import (
    DUPLICATE_STAMPS,
    EVALUATE_DEFAULTS,
    PLOT_MODES,
    TRAJECTORY_FORMATS,
)

if TYPE_CHECKING:  # the library is imported in run(): start-up stays light
    from slamrel.evaluation import FileEvaluation

#: The defaults of the scoring options (defined once: slamrel.constants.EVALUATE_DEFAULTS).
DEFAULT = SimpleNamespace(**EVALUATE_DEFAULTS)

HELP = "score an estimated trajectory against reference relations"

#: The "evo equivalents" paragraph of ``slamrel evaluate --help``.
EVO_EQUIVALENTS = """\
evo equivalents (where the definitions agree, the numbers agree to the printed digit):
  evo_rpe tum REF EST --delta D --delta_unit f
      = slamrel evaluate REF EST --sync --max-time-diff 0.01 --step D --chained
  evo_rpe ... --delta D --delta_unit m
      = ... --strategy distance --distance D --chained --pairs-from estimate
        (evo picks the pairs on the estimate; with --pairs_from_reference, drop
        --pairs-from here); --all_pairs: the same without --chained
  TUM evaluate_rpe.py --fixed_delta --delta S --delta_unit s
      = ... --sync --pairs-from estimate --strategy time --seconds S (TUM's pair rule;
        its time matching, within twice the reference's median spacing, is not --sync's)
  evo_ape tum REF EST [-a | -as]
      = slamrel evaluate REF EST --ate --sync --max-time-diff 0.01 (its none / se3 / sim3
        rows); --n_to_align N = --n-to-align N; --align_origin = the origin row (4-DoF and
        affine rows too)
  --t_offset / --t_start / --t_end = --t-offset / --t-start / --t-end
  KITTI devkit drift (t_err %, r_err deg/m) = --kitti-drift
Where they differ: slamrel's default tolerance is --max-time-diff 0.1 s (evo's t_max_diff
is 0.01 s; --sync with another value is warned about); without --sync slamrel generates
relations between reference poses and matches each end to the estimate (a reference far
denser than the estimate, as EuRoC's 200 Hz ground truth against a 10 Hz estimate, is
warned about); with --sync the pairs come from the reference unless --pairs-from
estimate."""


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "evaluate",
        help=HELP,
        description=textwrap.fill(
            HELP + ". REFERENCE is a Freiburg .relations file, or a reference trajectory (or a "
            "SLAM result bundle with groundtruth.csv) from which relations are generated with "
            "--strategy.",
            width=88,
        ),
        epilog=EVO_EQUIVALENTS,
        formatter_class=argparse.RawDescriptionHelpFormatter,
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
    p.add_argument(
        "--odometry-format",
        choices=TRAJECTORY_FORMATS,
        help="format of the odometry log (default: recognised)",
    )
    add_tolerance_argument(p)
    p.add_argument(
        "--interpolate", action="store_true", help="interpolate on SE(2)/SE(3) beyond the tolerance"
    )
    p.add_argument(
        "--max-interpolation-gap",
        type=opt.positive_float,
        default=DEFAULT.max_interpolation_gap,
        metavar="S",
        help="longest gap interpolated over [s] (default: %(default)s)",
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
        "--duplicate-stamps",
        choices=DUPLICATE_STAMPS,
        default=DEFAULT.duplicate_stamps,
        help="poses of REFERENCE and ESTIMATE that share a timestamp: keep all (as evo), keep "
        "the first of each, or refuse two different estimate poses at one time (a reference "
        "keeps its first); counted and said (default: %(default)s)",
    )
    p.add_argument(
        "--skip-invalid-poses",
        action="store_true",
        help="CARMEN logs only (FLASER, ROBOTLASER1, ODOM records): skip pose records with "
        "non-finite values (counted; default in metricevaluator mode); other formats refuse "
        "them whatever this option",
    )
    p.add_argument(
        "--ate",
        action="store_true",
        help="also the absolute trajectory error (needs a reference trajectory): without "
        "alignment and after each alignment: rigid and similarity (Umeyama), 4-DoF (3-D: "
        "yaw about z and translation), origin (first pose on first pose) and affine "
        "(positions only); with per-axis, in-plane and height errors in --json",
    )
    p.add_argument(
        "--n-to-align",
        type=opt.int_range(2, 2**63 - 1),
        metavar="N",
        help="--ate: fit the alignments on the first N matched poses only, apply them to all "
        "(evo's --n_to_align; default: all poses)",
    )
    p.add_argument(
        "--axes",
        action="store_true",
        help="also the per-axis translational relation errors |e_x|, |e_y|, |e_z|, in-plane "
        "‖(e_x, e_y)‖ and height |e_z|, in the frame of each relation's first pose (printed, "
        "and relation_axes in --json)",
    )
    p.add_argument(
        "--kitti-drift",
        action="store_true",
        help="also the KITTI odometry drift (the devkit's: translational %% and rotational "
        "deg/m over 100..800 m segments of the reference path, every 10th start frame), on "
        "the pose-by-pose synchronised pairs (needs a reference trajectory)",
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
        "--plot-mode",
        choices=PLOT_MODES,
        default="auto",
        help="--plot: the plane the trajectories are drawn in, horizontal axis first (xz: x "
        "across, z up the page); auto: the two axes of largest extent (a KITTI drive, camera "
        "frame y down and z forward, in x-z; z-up data in x-y), the third axis over time "
        "below; xyz: a 3-D view (3-D inputs); the reference trajectory is drawn too, as given "
        "(default: %(default)s)",
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
    add_sync_arguments(p)
    add_time_window_arguments(p)
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
    check_time_window(args)
    options = EvaluateOptions(**{name: getattr(args, name) for name in SCORING_OPTIONS})
    scored = score_files(
        args.reference,
        args.estimate,
        options,
        degrees=args.degrees,
        ate=args.ate,
        n_to_align=args.n_to_align,
        drift=args.kitti_drift,
        axes=args.axes,
    )
    if args.plot:
        _check_plot_mode(args.plot_mode, scored)
    _write_outputs(args, scored)
    if not args.quiet:
        print(summary_text(scored, degrees=args.degrees))
    return 0


def _check_plot_mode(mode: str, scored: FileEvaluation) -> None:
    """A plane the estimate does not have (``xz`` of a planar run) is an option mistake, said
    before any output is written."""
    from relation_metric.errors import OptionError

    dim = scored.estimate.group.position_dim
    if dim == 2 and mode not in ("auto", "xy", "yx"):
        raise OptionError(
            f"{mode} needs a 3-D estimate; {scored.estimate.group.name} poses have x and y only "
            "(use auto, xy or yx)",
            option="--plot-mode",
        )


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

        fig = evaluation_figure(
            ev,
            scored.estimate,
            degrees=args.degrees,
            plot_mode=args.plot_mode,
            reference=scored.reference,
        )
        save_figure(fig, args.plot)


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
            if not isinstance(r, dict) or not isinstance(r.get(part), dict):
                continue  # e.g. the affine row: an affine map does not map orientations
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
        ("translation abs [m]", ev.translation.abs),
        ("translation sqr [m²]", ev.translation.sqr),
        (f"rotation abs [{unit}]", rot.abs),
        (f"rotation sqr [{unit}²]", rot.sqr),
    ]
    if ev.errors.mode == "metricevaluator":
        rows.append(("weighted (metricEvaluator)", ev.combined.abs))
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
    if "relation_axes" in result:
        text += "\nper axis (relation frame):\n" + _axes_text(result["relation_axes"])
    if "kitti_drift" in result:
        text += "\n" + _drift_text(result["kitti_drift"])
    if "ate" in result:
        text += "\n" + ate_text(result["ate"], degrees=degrees)
    return text


def _drift_text(drift: dict[str, object]) -> str:
    """The console lines of ``--kitti-drift``: the devkit's numbers and the per-length table."""
    rows = drift["per_length"]
    assert isinstance(rows, list)
    lines = [
        f"KITTI drift ({drift['segments']} segments on {drift['pairs']} synchronised poses): "
        f"translation {_num(drift['translation_percent'], '.4f')} %, rotation "
        f"{_num(drift['rotation_deg_per_m'], '.6f')} deg/m (mean over all segments; mean of "
        f"the per-length means {_num(drift['translation_percent_by_length'], '.4f')} %, "
        f"{_num(drift['rotation_deg_per_m_by_length'], '.6f')} deg/m)",
        "  length [m]  segments  translation [%]  rotation [deg/m]",
    ]
    for r in rows:
        t = _num(r["translation_percent"], ".4f")
        rot = _num(r["rotation_deg_per_m"], ".6f")
        lines.append(f"  {r['length_m']:>10.0f}  {r['count']:>8d}  {t:>15}  {rot:>16}")
    return "\n".join(lines)


def _num(value: object, spec: str) -> str:
    """A number with ``spec``, or ``-`` for none (a length without a segment)."""
    return "-" if value is None else format(value, spec)


def _axes_text(axes: dict[str, dict[str, float | int | None]]) -> str:
    """The ``--axes`` table: one row per axis, the statistics of :func:`stats_table`."""
    from relation_metric.stats import Summary

    def summary(d: dict[str, float | int | None]) -> Summary:
        nan = float("nan")
        return Summary(**{k: (nan if v is None else v) for k, v in d.items()})  # type: ignore[arg-type]

    labels = {"x": "|e_x| [m]", "y": "|e_y| [m]", "z": "|e_z| [m]", "in_plane": "in-plane [m]",
              "height": "height |e_z| [m]"}  # fmt: skip
    return stats_table([(labels[k], summary(v)) for k, v in axes.items()])
