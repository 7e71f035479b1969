"""Helpers shared by the sub-commands: argument groups, console tables."""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

from relation_metric.errors import InputError
from relation_metric.formats import TRAJECTORY_FORMATS, LoadedTrajectory, read_trajectory
from relation_metric.outputs import check_outputs as _check_outputs
from relation_metric.relations import STRATEGIES, RelationSet, generate_relations
from relation_metric.stats import Summary
from relation_metric.trajectory import Trajectory

__all__ = [
    "add_strategy_arguments",
    "relations_from_args",
    "stats_table",
    "check_outputs",
    "add_force_argument",
    "load_trajectory_arg",
]


def add_strategy_arguments(parser: argparse.ArgumentParser, *, default: str | None) -> None:
    """Options of relation generation from a reference trajectory."""
    g = parser.add_argument_group("relation generation (from a reference trajectory)")
    g.add_argument(
        "--strategy",
        choices=STRATEGIES,
        default=default,
        help="how to select relations (default: %(default)s)",
    )
    g.add_argument("--step", type=int, default=1, help="consecutive: pose k with k+STEP")
    g.add_argument("--distance", type=float, default=1.0, help="distance: metres of travel")
    g.add_argument("--radius", type=float, default=1.0, help="loops: max distance [m]")
    g.add_argument(
        "--min-separation-time",
        type=float,
        default=30.0,
        help="loops: min time between the two poses [s]",
    )
    g.add_argument(
        "--min-separation-distance",
        type=float,
        default=None,
        help="loops: or min travel between the two poses [m]",
    )
    g.add_argument("--count", type=int, default=1000, help="global/random: number of pairs")
    g.add_argument(
        "--min-distance",
        type=float,
        default=None,
        help="global: min distance between the poses [m] (default: extent/4)",
    )
    g.add_argument("--seed", type=int, default=0, help="global/random: seed")


def relations_from_args(reference: Trajectory, args: argparse.Namespace) -> RelationSet:
    """Generate relations from ``reference`` with the strategy options in ``args``."""
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
    )


def load_trajectory_arg(
    path: str, fmt: str | None, *, pose: str = "laser", skip_invalid: bool = False
) -> LoadedTrajectory:
    """Read a trajectory given on the command line; a bundle directory means its ground truth."""
    p = Path(path)
    if p.is_dir():
        gt = p / "groundtruth.csv"
        if not gt.is_file():
            raise InputError(
                "is a directory without groundtruth.csv; expected a trajectory file or a "
                "SLAM result bundle with ground truth",
                path=path,
            )
        return read_trajectory(gt, format="csv")
    if fmt is not None and fmt not in TRAJECTORY_FORMATS:
        raise InputError(f"unknown format {fmt!r}", path=path)
    return read_trajectory(path, format=fmt, pose=pose, skip_invalid=skip_invalid)  # type: ignore[arg-type]


def check_outputs(
    outputs: Sequence[str | None],
    inputs: Sequence[str | None],
    *,
    dirs: Sequence[str | None] = (),
    force: bool = False,
) -> None:
    """Check a command's file ``outputs`` and folder outputs ``dirs`` before any work.

    See :func:`relation_metric.outputs.check_outputs`: no output is an input, lies inside an
    input folder or (for a folder) contains an input; parents are writable; no two outputs
    share a path; an existing non-empty folder is replaced only with ``force`` and only when
    slamrel wrote it.
    """
    _check_outputs(outputs, dirs=dirs, inputs=inputs, force=force)


def add_force_argument(parser: argparse.ArgumentParser) -> None:
    """``--force``: replace an existing output folder that slamrel wrote."""
    parser.add_argument(
        "--force",
        action="store_true",
        help="replace an existing output folder (only one slamrel wrote; it is replaced whole)",
    )


def stats_table(rows: Sequence[tuple[str, Summary]]) -> str:
    """A fixed-width console table of summaries, one row per ``(label, Summary)``."""
    names = ("mean", "std", "min", "max", "median", "rmse", "count")
    width = max(len(label) for label, _ in rows) if rows else 10
    head = " " * width + "".join(f"{n:>12}" for n in names)
    lines = [head]
    for label, s in rows:
        vals = [s.mean, s.std, s.min, s.max, s.median, s.rmse]
        cells = "".join(f"{v:>12.6f}" for v in vals) + f"{s.count:>12d}"
        lines.append(f"{label:<{width}}{cells}")
    return "\n".join(lines)
