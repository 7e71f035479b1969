"""``slamrel example``: write a small, seeded example to try ``slamrel evaluate`` on."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from slamrel.commands import options as opt
from slamrel.commands.common import add_force_argument, check_outputs

if TYPE_CHECKING:  # the library is imported where it is used: start-up stays light
    from relation_metric.trajectory import Trajectory


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "example",
        help="write a seeded example (reference, estimate, relations) to try evaluate on",
    )
    p.add_argument("-o", "--output", default="slamrel-example", metavar="DIR")
    p.add_argument("--seed", type=opt.seed, default=0)
    add_force_argument(p)
    p.add_argument("-q", "--quiet", action="store_true")
    p.set_defaults(func=run)


def example_world(seed: int = 0, n: int = 600, dt: float = 0.5) -> tuple[Trajectory, Trajectory]:
    """A reference figure-eight drive and a drifting estimate of it (seeded).

    The estimate chains the reference's relative motions with Gaussian noise
    (σ = 2 cm, 2 cm, 0.005 rad per step), i.e. dead reckoning with good odometry.
    """
    import numpy as np

    from relation_metric import se2
    from relation_metric.trajectory import Trajectory

    rng = np.random.default_rng(seed)
    s = np.linspace(0.0, 2.0 * np.pi, n)
    xy = np.column_stack((20.0 * np.sin(s), 10.0 * np.sin(2.0 * s)))
    d = np.gradient(xy, axis=0)
    theta = np.arctan2(d[:, 1], d[:, 0])
    ref = np.column_stack((xy, theta))
    steps = se2.between(ref[:-1], ref[1:])
    noisy = steps + rng.normal(0.0, [0.02, 0.02, 0.005], size=steps.shape)
    est = se2.cumulative_compose(noisy, start=ref[0])
    t = dt * np.arange(n)
    return Trajectory(t, ref), Trajectory(t, est)


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from relation_metric.formats import write_trajectory
    from relation_metric.outputs import staged_directory
    from relation_metric.relations import RelationSet, generate_relations, write_relations

    check_outputs([], [], dirs=[args.output], force=args.force)
    out = Path(args.output)
    reference, estimate = example_world(args.seed)
    local = generate_relations(reference, "consecutive")
    loops = generate_relations(reference, "loops", radius=2.0, min_separation_time=60.0)
    both = RelationSet(
        np.concatenate((local.first, loops.first)),
        np.concatenate((local.second, loops.second)),
        np.concatenate((local.delta, loops.delta)),
    )
    with staged_directory(out, kind="example", force=args.force) as tmp:
        write_trajectory(tmp / "reference.txt", reference, format="plain")
        write_trajectory(tmp / "estimate.txt", estimate, format="plain")
        write_relations(tmp / "reference.relations", both)
    if not args.quiet:
        print(
            f"wrote {out}/reference.txt, {out}/estimate.txt ({len(reference)} poses) and "
            f"{out}/reference.relations ({len(local)} consecutive + {len(loops)} loop relations)"
        )
    return 0
