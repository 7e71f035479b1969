"""``slamrel ape`` and ``slamrel rpe``: evo's ``evo_ape``/``evo_rpe`` command lines, evo's numbers.

The parsers take evo's words and defaults (``tum|kitti|euroc|bag|bag2 REF EST``, ``-a``,
``-s``, ``--align_origin``, ``-r``, ``--delta``, ``--t_max_diff``, ...); the work is
:func:`slamrel.evo_metrics.evo_files` (imported in :func:`run`: ``slamrel --help`` stays
light). The output is evo's: the title, then the statistics by name.
"""

from __future__ import annotations

import argparse

from relation_metric.constants import DELTA_UNITS, PLANES, POSE_RELATIONS
from slamrel.commands import options as opt

#: The one-line help of each command.
HELP = {
    "ape": "absolute pose error as evo_ape computes it (evo's options and defaults)",
    "rpe": "relative pose error as evo_rpe computes it (evo's options and defaults)",
}

EPILOG = """\
Differences from evo (said where they happen): by default a reference pose that repeats an
earlier pose's timestamp is dropped with a warning, and an estimate with two different
poses at one timestamp is refused (evo keeps both); --duplicate_stamps keep reads such
files as evo does. Compare the numbers with 'slamrel evaluate', slamrel's own richer
command (relation sets, significance, drift)."""


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    for metric in ("ape", "rpe"):
        p = sub.add_parser(
            metric,
            help=HELP[metric],
            description=HELP[metric][0].upper() + HELP[metric][1:] + ". Pick the input kind:",
            epilog=EPILOG,
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        kinds = p.add_subparsers(dest="evo_kind", metavar="KIND")
        kinds.required = True
        _kind_parsers(kinds, metric)


def _kind_parsers(kinds: argparse._SubParsersAction, metric: str) -> None:  # type: ignore[type-arg]
    """``tum``, ``kitti``, ``euroc``, ``bag``, ``bag2``: the files, then the shared options."""
    what = {
        "tum": "TUM trajectory files (t x y z qx qy qz qw)",
        "kitti": "KITTI pose files (3x4 [R | t] a line; paired pose by pose)",
        "euroc": "an EuRoC ground-truth CSV and a TUM estimate",
        "bag": "two topics of a ROS 1 bag",
        "bag2": "two topics of a ROS 2 bag (sqlite3 or MCAP)",
    }
    for kind, text in what.items():
        p = kinds.add_parser(kind, help=text, description=f"{metric.upper()} of {text}.")
        if kind in ("bag", "bag2"):
            p.add_argument("reference", metavar="BAG", help="the ROS bag")
            p.add_argument("ref_topic", metavar="REF_TOPIC", help="reference trajectory topic")
            p.add_argument("est_topic", metavar="EST_TOPIC", help="estimated trajectory topic")
        else:
            ref = (
                "ground truth CSV (state_groundtruth_estimate0/data.csv)"
                if kind == "euroc"
                else ("reference trajectory file")
            )
            p.add_argument("reference", metavar="REF", help=ref)
            p.add_argument("estimate", metavar="EST", help="estimated trajectory file")
        _algorithm_arguments(p, metric)
        if metric == "rpe":
            _delta_arguments(p)
        if kind != "kitti":
            _time_arguments(p)
            p.add_argument(
                "--duplicate_stamps",
                choices=("keep", "first", "refuse"),
                default="refuse",
                help="poses that share a timestamp: keep all (as evo), keep the first of each, "
                "or refuse two different estimate poses at one time (the reference keeps its "
                "first); counted and said (default: %(default)s)",
            )
        _output_arguments(p)
        p.set_defaults(func=run, evo_metric=metric)


def _algorithm_arguments(p: argparse.ArgumentParser, metric: str) -> None:
    """``-r``, the alignments and the projection."""
    p.add_argument(
        "-r",
        "--pose_relation",
        choices=POSE_RELATIONS,
        default="trans_part",
        help=f"pose relation on which the {metric.upper()} is based (default: %(default)s)",
    )
    align = p.add_mutually_exclusive_group()
    align.add_argument(
        "-a",
        "--align",
        action="store_true",
        help="alignment with Umeyama's method (no scale) (default: off)",
    )
    align.add_argument(
        "--align_origin",
        action="store_true",
        help="align the trajectory origin to the origin of the reference trajectory (default: off)",
    )
    p.add_argument(
        "-s",
        "--correct_scale",
        action="store_true",
        help="correct scale with Umeyama's method (-as: with the alignment) (default: off)",
    )
    p.add_argument(
        "--n_to_align",
        type=int,
        default=-1,
        metavar="N",
        help="the number of poses to use for Umeyama alignment, counted from the start "
        "(default: %(default)s, all)",
    )
    p.add_argument(
        "--project_to_plane",
        choices=PLANES,
        help="project the trajectories to 2D in this plane, after the alignment (KITTI's "
        "camera frame: xz) (default: none)",
    )


def _delta_arguments(p: argparse.ArgumentParser) -> None:
    """evo_rpe's pose pairs."""
    p.add_argument(
        "-d",
        "--delta",
        type=opt.nonnegative_float,
        default=1.0,
        help="delta between relative poses (default: %(default)s)",
    )
    p.add_argument(
        "-t",
        "--delta_tol",
        type=opt.nonnegative_float,
        default=0.1,
        help="relative delta tolerance for --all_pairs with -u m, d or r (default: %(default)s)",
    )
    p.add_argument(
        "-u",
        "--delta_unit",
        choices=DELTA_UNITS,
        default="f",
        help="unit of delta: f (frames), d (deg), r (rad), m (meters) (default: %(default)s)",
    )
    p.add_argument(
        "--all_pairs",
        action="store_true",
        help="use all pairs instead of consecutive pairs (default: off: consecutive pairs)",
    )
    p.add_argument(
        "--pairs_from_reference",
        action="store_true",
        help="determine the pose pairs from the reference trajectory (default: off: from the "
        "estimate)",
    )


def _time_arguments(p: argparse.ArgumentParser) -> None:
    """The time association (trajectories with timestamps: not KITTI)."""
    p.add_argument(
        "--t_max_diff",
        type=opt.nonnegative_float,
        default=0.01,
        metavar="S",
        help="maximum timestamp difference for data association [s] (default: %(default)s)",
    )
    p.add_argument(
        "--t_offset",
        type=opt.finite_float,
        default=0.0,
        metavar="S",
        help="constant timestamp offset added to the estimate's times for the association [s] "
        "(default: %(default)s)",
    )
    p.add_argument(
        "--t_start",
        type=opt.finite_float,
        metavar="T",
        help="only use reference poses with timestamps >= T, cut before the association, as "
        "evo (default: none)",
    )
    p.add_argument(
        "--t_end",
        type=opt.finite_float,
        metavar="T",
        help="only use reference poses with timestamps <= T (default: none)",
    )


def _output_arguments(p: argparse.ArgumentParser) -> None:
    """``--save_results`` and the usability options evo has."""
    p.add_argument(
        "--save_results",
        metavar="FILE.zip",
        help="write the result as evo's result zip (evo_res reads it) (default: none)",
    )
    p.add_argument(
        "-p",
        "--plot",
        action="store_true",
        help="show the plot: the errors over time and the trajectories coloured by error "
        "(default: off)",
    )
    p.add_argument(
        "--save_plot",
        metavar="FILE",
        help="write the plot to FILE (.png, .pdf or .svg; no window) (default: none)",
    )
    p.add_argument(
        "--plot_mode",
        choices=("xy", "xz", "yx", "yz", "zx", "zy"),
        default="xy",
        help="the plane the trajectories are drawn in (default: %(default)s)",
    )
    p.add_argument("--silent", action="store_true", help="don't print any output (default: off)")
    p.add_argument(
        "--no_warnings",
        action="store_true",
        help="accepted for evo's command lines; slamrel never asks for a confirmation "
        "(default: off)",
    )


def run(args: argparse.Namespace) -> int:
    """``slamrel ape|rpe KIND ...``: outputs checked, the files scored, printed as evo does."""
    from slamrel.commands.common import check_outputs
    from slamrel.evo_metrics import EvoOptions, evo_files
    from slamrel.formats.results import write_evo_result

    check_outputs(
        [args.save_results, args.save_plot], [args.reference, getattr(args, "estimate", None)]
    )
    fields = {
        k: getattr(args, k)
        for k in EvoOptions.__dataclass_fields__
        if k not in ("metric", "kind") and hasattr(args, k)
    }
    fields.setdefault("estimate", args.reference)  # bags: one bag holds both topics
    result = evo_files(EvoOptions(metric=args.evo_metric, kind=args.evo_kind, **fields))
    if args.save_results:
        write_evo_result(
            args.save_results,
            result.info,
            result.errors,
            result.timestamps,
            result.seconds_from_start,
        )
    if not args.silent:
        print(result.pretty())
    if args.save_plot or args.plot:
        _plots(args, result)
    return 0


def _plots(args: argparse.Namespace, result: object) -> None:
    """``--save_plot`` (written atomically, Agg) and ``--plot`` (a window, the user's backend)."""
    from slamrel.plots.pose_errors import pose_error_figure

    if args.save_plot:
        from slamrel.plots.relation_errors import save_figure

        save_figure(pose_error_figure(result, args.plot_mode), args.save_plot)
    if args.plot:
        import matplotlib.pyplot as plt

        pose_error_figure(result, args.plot_mode, plt)
        plt.show()
