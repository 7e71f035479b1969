"""``slamrel relations generate``: select reference relations from a trajectory."""

from __future__ import annotations

import argparse

from slamrel.commands.common import (
    add_strategy_arguments,
    check_outputs,
    relations_from_args,
)
from slamrel.constants import TRAJECTORY_FORMATS


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser("relations", help="work with relation sets")
    rsub = p.add_subparsers(dest="relations_command", metavar="ACTION")
    rsub.required = True
    g = rsub.add_parser(
        "generate",
        help="generate reference relations from a reference trajectory",
        description="Select relations from a reference trajectory (Kümmerle et al. 2009) "
        "and write them as a Freiburg .relations file.",
    )
    g.add_argument("reference", metavar="REFERENCE", help="reference trajectory or bundle")
    g.add_argument("--format", choices=TRAJECTORY_FORMATS, help="format of REFERENCE")
    g.add_argument("-o", "--output", required=True, metavar="OUT", help="output .relations file")
    g.add_argument(
        "--planar",
        action="store_true",
        help="project a 3-D reference onto the plane (warns what z/roll/pitch is discarded)",
    )
    g.add_argument("--times", metavar="FILE", help="KITTI: timestamps, one a line")
    g.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")
    add_strategy_arguments(g, default="consecutive")
    g.set_defaults(func=run_generate)


def run_generate(args: argparse.Namespace) -> int:
    from slamrel.evaluation import load_trajectory
    from slamrel.formats.relations import write_relations

    check_outputs([args.output], [args.reference])
    reference = load_trajectory(
        args.reference, args.format, planar=args.planar, times=args.times
    ).trajectory
    rel = relations_from_args(reference, args)
    write_relations(args.output, rel)
    if not args.quiet:
        dim = "3-D" if reference.group.name == "SE3" else "2-D"
        print(
            f"{len(rel)} {args.strategy} relations from {len(reference)} {dim} poses "
            f"-> {args.output}"
        )
    return 0
