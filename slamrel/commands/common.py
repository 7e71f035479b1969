"""Helpers shared by the sub-commands: argument groups, console tables."""

from __future__ import annotations

import argparse
import os
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from types import SimpleNamespace
from typing import TYPE_CHECKING, Literal

from landmark_graph.constants import ASSOCIATE_MODES, DEFAULT_ASSOCIATE
from recovery.constants import (
    DEFAULT_MAP_PRIOR,
    DEFAULT_MAX_OUTLIER_RUN,
    DEFAULT_ROBUST,
    MAP_PRIOR_CHOICES,
    ROBUST,
)
from relation_metric.constants import STRATEGIES
from relation_metric.errors import InputError, OptionError, SlamrelError
from slamrel.commands import options as opt
from slamrel.constants import EVALUATE_DEFAULTS, PAIRS_FROM

if TYPE_CHECKING:  # the library is imported where it is used: start-up stays light
    from landmark_graph.landmark_association import Association
    from landmark_graph.maps import LandmarkMap
    from relation_metric.relations import RelationSet
    from relation_metric.stats import Summary
    from relation_metric.trajectory import Trajectory

__all__ = [
    "errors_about",
    "in_option_words",
    "add_strategy_arguments",
    "relations_from_args",
    "stats_table",
    "check_outputs",
    "input_files",
    "add_force_argument",
    "add_noise_argument",
    "add_association_arguments",
    "association_file",
    "association_choice",
]


@contextmanager
def errors_about(path: str | os.PathLike[str]) -> Iterator[None]:
    """Name ``path`` in errors raised inside the block that name no file themselves.

    Library code that works on arrays (a solver, a filter, a map comparison) cannot know
    which file its input came from; the command does. Errors that already carry a path are
    passed on unchanged; :class:`~relation_metric.errors.DivergenceError` and other
    :class:`SlamrelError` become an :class:`InputError` about ``path`` (exit 3 either way).
    """
    try:
        yield
    except InputError as exc:
        if exc.path is not None:
            raise
        raise type(exc)(exc.message, path=path, line=exc.line) from None
    except SlamrelError as exc:
        raise InputError(str(exc), path=path) from None


@contextmanager
def in_option_words(words: Mapping[str, str]) -> Iterator[None]:
    """Say the library's parameters in the command's options, in errors and warnings.

    See :func:`slamrel.evaluation.in_option_words` (imported when used: start-up stays light).
    """
    from slamrel.evaluation import in_option_words as say_in_option_words

    with say_in_option_words(words):
        yield


def add_strategy_arguments(parser: argparse.ArgumentParser, *, default: str | None) -> None:
    """Options of relation generation from a reference trajectory.

    Their defaults are :data:`slamrel.constants.EVALUATE_DEFAULTS` (those of
    :class:`~slamrel.evaluation_options.EvaluateOptions`)
    (``default`` is the strategy's).
    """
    d = SimpleNamespace(**EVALUATE_DEFAULTS)
    g = parser.add_argument_group("relation generation (from a reference trajectory)")
    g.add_argument(
        "--strategy",
        choices=STRATEGIES,
        default=default,
        help="how to select relations from a reference trajectory (default: consecutive): "
        "consecutive (pose k with k+STEP), "
        "distance (each pose with the first pose DISTANCE metres of travel further), time "
        "(each pose with the pose nearest SECONDS later: TUM's RPE by seconds), loops, "
        "global, random, all-pairs",
    )
    g.add_argument(
        "--step",
        type=opt.positive_int,
        default=d.step,
        help="consecutive: pose k with k+STEP (default: %(default)s)",
    )
    g.add_argument(
        "--distance",
        type=opt.positive_float,
        default=d.distance,
        help="distance: metres of travel (default: %(default)s)",
    )
    g.add_argument(
        "--radius",
        type=opt.positive_float,
        default=d.radius,
        help="loops: max distance [m] (default: %(default)s)",
    )
    g.add_argument(
        "--min-separation-time",
        type=opt.nonnegative_float,
        default=d.min_separation_time,
        help="loops: min time between the two poses [s] (default: %(default)s)",
    )
    g.add_argument(
        "--min-separation-distance",
        type=opt.nonnegative_float,
        default=d.min_separation_distance,
        help="loops: or min travel between the two poses [m]",
    )
    g.add_argument(
        "--count",
        type=opt.count,
        default=d.count,
        help="global/random: number of pairs (default: %(default)s)",
    )
    g.add_argument(
        "--min-distance",
        type=opt.nonnegative_float,
        default=d.min_distance,
        help="global: min distance between the poses [m] (default: extent/4)",
    )
    g.add_argument(
        "--seconds",
        type=opt.positive_float,
        default=d.seconds,
        metavar="S",
        help="time: seconds between the two poses (default %(default)s)",
    )
    g.add_argument(
        "--seed", type=opt.seed, default=d.seed, help="global/random: seed (default: %(default)s)"
    )
    g.add_argument(
        "--chained",
        action="store_true",
        default=d.chained,
        help="consecutive/distance: one chain of relations from pose 0, each starting where "
        "the previous ended (evo's RPE pairs) instead of one relation from every pose",
    )


def add_tolerance_argument(parser: argparse.ArgumentParser) -> None:
    """``--max-time-diff``: the nearest-pose tolerance (``evaluate``, ``batch``)."""
    parser.add_argument(
        "--max-time-diff",
        type=opt.nonnegative_float,
        default=EVALUATE_DEFAULTS["max_time_diff"],
        metavar="S",
        help="nearest-pose tolerance [s] (default %(default)s)",
    )


def add_sync_arguments(parser: argparse.ArgumentParser) -> None:
    """``--sync`` and ``--pairs-from``: evo's pose-by-pose association and where the pose
    pairs are chosen (``evaluate``, ``batch``)."""
    parser.add_argument(
        "--sync",
        action="store_true",
        help="associate reference and estimate pose by pose first, as evo does (nearest time "
        "within --max-time-diff; use 0.01 for evo's default t_max_diff), then generate the "
        "relations on the matched poses (needs a reference trajectory)",
    )
    parser.add_argument(
        "--pairs-from",
        choices=PAIRS_FROM,
        default=EVALUATE_DEFAULTS["pairs_from"],
        help="with --sync: choose the relations' pose pairs on the reference (slamrel's "
        "default, the relation metric's reference relations) or on the estimate (evo's "
        "default; its --pairs_from_reference is 'reference'); default: %(default)s",
    )


def add_time_window_arguments(parser: argparse.ArgumentParser) -> None:
    """``--t-offset``, ``--t-start``, ``--t-end`` (``evaluate``, ``batch``)."""
    d = SimpleNamespace(**EVALUATE_DEFAULTS)
    parser.add_argument(
        "--t-offset",
        type=opt.finite_float,
        default=d.t_offset,
        metavar="S",
        help="add S seconds to every ESTIMATE timestamp first (evo's --t_offset; "
        "default %(default)s)",
    )
    parser.add_argument(
        "--t-start",
        type=opt.finite_float,
        default=d.t_start,
        metavar="T",
        help="keep only poses (and relations) at times >= T [s], on both trajectories, after "
        "--t-offset (evo's --t_start; default: no bound)",
    )
    parser.add_argument(
        "--t-end",
        type=opt.finite_float,
        default=d.t_end,
        metavar="T",
        help="... and at times <= T [s] (evo's --t_end; default: no bound)",
    )


def check_time_window(args: argparse.Namespace) -> None:
    """``--t-end`` before ``--t-start`` is an option mistake (exit 2)."""
    if args.t_start is not None and args.t_end is not None and args.t_end < args.t_start:
        from relation_metric.errors import OptionError

        raise OptionError(f"{args.t_end} is before --t-start {args.t_start}", option="--t-end")


def relations_from_args(
    reference: Trajectory, args: argparse.Namespace, *, key: Literal["time", "index"] = "time"
) -> RelationSet:
    """Generate relations from ``reference`` with the strategy options in ``args``."""
    from relation_metric.relations import generate_relations
    from slamrel.constants import STRATEGY_OPTION_WORDS

    with in_option_words(STRATEGY_OPTION_WORDS):
        return generate_relations(
            reference,
            args.strategy,
            step=args.step,
            distance=args.distance,
            radius=args.radius,
            min_separation_time=args.min_separation_time,
            min_separation_distance=args.min_separation_distance,
            count=args.count,
            min_distance=args.min_distance,
            seed=args.seed,
            chained=getattr(args, "chained", False),
            seconds=getattr(args, "seconds", EVALUATE_DEFAULTS["seconds"]),
            key=key,
        )


def input_files(paths: Sequence[str | None]) -> list[str | None]:
    """The files behind input arguments: a bag topic ``BAG:TOPIC``'s bag, so no output replaces
    it (:func:`check_outputs`)."""
    from slamrel.formats.bags import split_bag_spec

    out: list[str | None] = []
    for p in paths:
        spec = None if p is None else split_bag_spec(p)
        out.append(p if spec is None else spec.path)
    return out


def check_outputs(
    outputs: Sequence[str | None],
    inputs: Sequence[str | None],
    *,
    dirs: Sequence[str | None] = (),
    force: bool = False,
) -> None:
    """Check a command's file ``outputs`` and folder outputs ``dirs`` before any work.

    See :func:`slamrel.outputs.check_outputs`: no output is an input, lies inside an
    input folder or (for a folder) contains an input; parents are writable; no two outputs
    share a path; an existing non-empty folder is replaced only with ``force`` and only when
    slamrel wrote it.

    The folder outputs are then claimed for this process (:func:`slamrel.outputs.claim_outputs`,
    released when the command ends): another slamrel writing one of them right now is
    refused, or with ``force`` waited for; the checks are repeated once the claims are held.
    """
    from slamrel.outputs import check_outputs as _check_outputs
    from slamrel.outputs import claim_outputs

    _check_outputs(outputs, dirs=dirs, inputs=inputs, force=force)
    if any(d is not None for d in dirs):
        claim_outputs(dirs, wait=force)
        _check_outputs(outputs, dirs=dirs, inputs=inputs, force=force)


def add_recovery_arguments(parser: argparse.ArgumentParser, *, fail_help: str) -> None:
    """``--max-outlier-run``, ``--fail-on-divergence`` (help: ``fail_help``), ``--robust`` and
    ``--map-prior``: the recovery's options, shared by ``recover`` and ``run``."""
    parser.add_argument(
        "--max-outlier-run",
        type=opt.nonnegative_int,
        default=DEFAULT_MAX_OUTLIER_RUN,
        metavar="N",
        help="after N consecutive outlying innovations the map and the log disagree: the "
        "stretch is reported and the filter re-entered by inflating its pose covariance "
        "(0: never re-enter; default: %(default)s)",
    )
    parser.add_argument("--fail-on-divergence", action="store_true", help=fail_help)
    parser.add_argument(
        "--robust",
        choices=(*(r for r in ROBUST if r), "none"),
        default=DEFAULT_ROBUST,
        help="M-estimator weights on outlying innovations (smoother and batch use the same "
        "weights; the down-weighted fraction is reported; none: the plain EKF; "
        "default: %(default)s)",
    )
    parser.add_argument(
        "--map-prior",
        choices=MAP_PRIOR_CHOICES,
        default=DEFAULT_MAP_PRIOR,
        help="where the map's error comes from: independent of the log (surveyed), or "
        "deconditioned (made from this log: its covariance already holds the log's "
        "information; smoother and batch); auto: deconditioned when bundle.json states "
        "map_source log and the method allows, else independent (default: %(default)s)",
    )


def add_association_arguments(parser: argparse.ArgumentParser, *, align: bool = True) -> None:
    """``--associate id-or-auto|id|auto|FILE`` (and, with ``align``, ``--no-align``): how a
    landmark map is paired with its reference, shared by ``map-compare``, ``run`` and
    ``review`` (:func:`landmark_graph.map_compare.choose_association`)."""
    modes = "|".join(ASSOCIATE_MODES)
    parser.add_argument(
        "--associate",
        default=DEFAULT_ASSOCIATE,
        metavar=f"{modes}|FILE",
        help="landmark association: id-or-auto (by id when more than half of the landmarks "
        "shared by id lie within the cut-off c of each other after the alignment, else "
        "automatic), id, auto (rigid alignment and optimal assignment within c) or an "
        "'estimate,reference' CSV (default: %(default)s)",
    )
    if align:
        parser.add_argument(
            "--no-align",
            dest="align",
            action="store_false",
            help="compare the maps as given; by default the estimate is moved onto the "
            "reference by the SE(2) least-squares fit on the associated pairs first (OSPA, "
            "GOSPA, figures), whatever --associate is",
        )


def association_file(value: str) -> str | None:
    """The association file ``--associate`` names, or ``None`` for a mode."""
    return None if value in ASSOCIATE_MODES else value


def association_choice(value: str, est: LandmarkMap, ref: LandmarkMap) -> str | Association:
    """``--associate``'s value for :func:`~landmark_graph.map_compare.compare_maps`: the mode,
    or the association read from the file it names."""
    if association_file(value) is None:
        return value
    from slamrel.formats.associations import read_association_csv

    return read_association_csv(value, est, ref)


#: The iSAM reader's parameter in ``import isam``'s and ``solve``'s option words.
NOISE_WORDS = {
    "pass noise='covariance'": "pass --noise covariance",
    "pass noise='sqrt-information'": "pass --noise sqrt-information",
}


def add_noise_argument(parser: argparse.ArgumentParser) -> None:
    """``--noise sqrt-information|covariance``: what an iSAM file's noise numbers are, shared
    by ``import isam`` and ``solve`` (:func:`slamrel.formats.isam.read_isam`)."""
    parser.add_argument(
        "--noise",
        choices=("sqrt-information", "covariance"),
        default="sqrt-information",
        help="iSAM text only: what the numbers after each ODOMETRY/LANDMARK measurement are. "
        "sqrt-information (default, iSAM's own definition): the upper triangle, row-first, "
        "of the square-root information matrix R (R^T R = inverse covariance; 100 means a "
        "0.01 standard deviation); covariance: the upper triangle of the covariance (the "
        "copy of Victoria Park shipped with GTSAM). A warning says when the numbers look "
        "like the other convention",
    )


def add_force_argument(parser: argparse.ArgumentParser) -> None:
    """``--force``: replace an existing output folder that slamrel wrote."""
    parser.add_argument(
        "--force",
        action="store_true",
        help="replace an existing output folder (only one slamrel wrote; it is replaced whole)",
    )


#: ``--iterations``: Gauss–Newton iterations of each EKF-SLAM update (1: the plain EKF).
MAX_ITERATIONS = 50


def add_iterations_argument(parser: argparse.ArgumentParser, *, where: str = "") -> None:
    """``--iterations N``: the reference EKF-SLAM's iterated update
    (:func:`slamrel.backends.ekf_slam.ekf_slam`)."""
    from slamrel.commands.options import int_range

    parser.add_argument(
        "--iterations",
        type=int_range(1, MAX_ITERATIONS),
        default=1,
        metavar="N",
        help="Gauss-Newton iterations of each EKF-SLAM update: 1 is the plain EKF; above 1 "
        "each measurement is relinearised at the damped iterate of its pose-landmark problem "
        f"(the iterated EKF; not with --jacobians fej){where} (default: %(default)s)",
    )


def check_iterations(args: argparse.Namespace) -> None:
    """``--iterations`` above 1 with ``--jacobians fej`` (fixed Jacobians): an option mistake."""
    if args.iterations > 1 and args.jacobians == "fej":
        raise OptionError(
            "--jacobians fej fixes every Jacobian at its first estimate, so there is nothing "
            "to iterate: use --iterations 1, or --jacobians oc or standard",
            option="--iterations",
        )


def stats_table(rows: Sequence[tuple[str, Summary]]) -> str:
    """A fixed-width console table of summaries, one row per ``(label, Summary)``."""
    from relation_metric.stats import STAT_NAMES as names  # here: start-up stays light

    width = max(len(label) for label, _ in rows) if rows else 10
    head = " " * width + "".join(f"{n:>12}" for n in names)
    lines = [head]
    for label, s in rows:
        vals = [s.mean, s.std, s.min, s.max, s.median, s.rmse]
        cells = "".join(f"{v:>12.6f}" for v in vals) + f"{s.count:>12d}"
        lines.append(f"{label:<{width}}{cells}")
    return "\n".join(lines)


def check_rate(world: str, rate: int) -> None:
    """``--rate`` within what world ``world`` is built with (``OptionError``, exit 2, before
    any work: an option mistake, not an input one)."""
    from slamrel.simulation.worlds import MAX_CONTROL_ROWS, max_rate

    most = max_rate(world)
    if most is not None and rate > most:
        raise OptionError(
            f"{rate} control steps per measurement step on {world} is above the limit of "
            f"{MAX_CONTROL_ROWS} control rows (the world, its bundle and the filter grow with "
            f"them); expected at most {most}",
            option="--rate",
        )
