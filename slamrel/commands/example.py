"""``slamrel example``: write a small, seeded example to try ``slamrel evaluate`` on."""

from __future__ import annotations

import argparse
from pathlib import Path

from slamrel.commands import options as opt
from slamrel.commands.common import add_force_argument, check_outputs


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "example",
        help="write a seeded example (reference, estimate, relations) to try evaluate on",
    )
    p.add_argument(
        "-o",
        "--output",
        default="slamrel-example",
        metavar="DIR",
        help="directory to write (default: %(default)s)",
    )
    p.add_argument(
        "--seed", type=opt.seed, default=0, help="seed of the example (default: %(default)s)"
    )
    add_force_argument(p)
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # the library is imported where it is used: start-up stays light
    from slamrel.formats.relations import write_relations
    from slamrel.formats.trajectories import write_trajectory
    from slamrel.outputs import staged_directory
    from slamrel.simulation.example import example_pair

    check_outputs([], [], dirs=[args.output], force=args.force)
    out = Path(args.output)
    ex = example_pair(args.seed)
    with staged_directory(out, kind="example", force=args.force) as tmp:
        write_trajectory(tmp / "reference.txt", ex.reference, format="plain")
        write_trajectory(tmp / "estimate.txt", ex.estimate, format="plain")
        write_relations(tmp / "reference.relations", ex.relations)
    if not args.quiet:
        print(
            f"wrote {out}/reference.txt, {out}/estimate.txt ({len(ex.reference)} poses) and "
            f"{out}/reference.relations ({ex.consecutive} consecutive + {ex.loops} loop relations)"
        )
    return 0
