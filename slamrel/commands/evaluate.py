"""``slamrel evaluate``: score an estimate with the relation metric.

The parser (built on every ``slamrel --help``: no numpy) takes its scoring defaults from
:class:`~slamrel.evaluation_options.EvaluateOptions`.
"""

from __future__ import annotations

import argparse

from relation_metric.constants import MODES
from slamrel.commands import options as opt
from slamrel.commands.common import add_strategy_arguments
from slamrel.constants import TRAJECTORY_FORMATS
from slamrel.evaluation_options import EvaluateOptions

#: The defaults of the scoring options, defined once (in EvaluateOptions).
DEFAULT = EvaluateOptions

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
    """Run the command (the library is imported here, not when the parser is built)."""
    from slamrel.commands.evaluate_run import run as run_evaluate

    return run_evaluate(args)
