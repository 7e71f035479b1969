"""``slamrel simulate`` and ``slamrel slam``: simulated worlds and the reference EKF-SLAM."""

from __future__ import annotations

import argparse
from pathlib import Path

from slamrel.commands import options as opt
from slamrel.commands.common import (
    add_force_argument,
    add_iterations_argument,
    check_iterations,
    check_outputs,
    check_rate,
    errors_about,
    in_option_words,
)
from slamrel.constants import NOISE_HELP, NOISE_NAMES, WORLDS


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    s = sub.add_parser(
        "simulate",
        help="write a simulated world (Hu et al.) as a bundle: log, true map, ground truth",
    )
    s.add_argument("world", choices=WORLDS, metavar="WORLD", help=", ".join(WORLDS))
    s.add_argument("--noise", choices=NOISE_NAMES, default="a", help=NOISE_HELP)
    s.add_argument(
        "--seed", type=opt.seed, default=0, help="seed of the simulation (default: %(default)s)"
    )
    s.add_argument(
        "--rate",
        type=opt.nonnegative_int,
        default=0,
        help="control steps per measurement step (0: odometry; default: %(default)s)",
    )
    s.add_argument("-o", "--output", required=True, metavar="BUNDLE", help="bundle to write")
    add_force_argument(s)
    s.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")
    s.set_defaults(func=run_simulate)

    m = sub.add_parser(
        "slam",
        help="run the reference EKF-SLAM on a bundle's log and write the SLAM result bundle",
    )
    m.add_argument("bundle", metavar="LOG_BUNDLE", help="a log bundle (slamrel simulate)")
    m.add_argument("-o", "--output", required=True, metavar="BUNDLE", help="bundle to write")
    m.add_argument(
        "--association",
        choices=("known", "nn"),
        default="known",
        help="data association: known (the simulation's landmark ids) or nn (nearest "
        "neighbour in Mahalanobis distance) (default: %(default)s)",
    )
    m.add_argument(
        "--corrupt",
        type=opt.fraction,
        default=0.0,
        metavar="F",
        help="fraction of associations to corrupt on purpose (default: %(default)s)",
    )
    m.add_argument(
        "--noise-scale",
        type=opt.noise_scale,
        default=1.0,
        help="factor on the noise the filter assumes (default: %(default)s)",
    )
    m.add_argument(
        "--outlier-gate",
        type=opt.probability,
        default=None,
        metavar="P",
        help="χ² probability of a validation gate on known-association updates "
        "(default: no gate); rejected measurements are counted",
    )
    m.add_argument(
        "--jacobians",
        choices=("standard", "fej", "oc"),
        default="standard",
        help="where the EKF-SLAM evaluates its Jacobians: standard (the latest estimates), fej "
        "(first estimates, Huang et al. 2008) or oc (observability-constrained: the heading "
        "columns at points that keep the rotation unobservable, the rest at the latest "
        "estimates); fej and oc keep the unobservable directions, so the filter does not "
        "become overconfident (known associations) (default: %(default)s)",
    )
    add_iterations_argument(m)
    m.add_argument(
        "--seed", type=opt.seed, default=0, help="seed of the corruption (default: %(default)s)"
    )
    m.add_argument(
        "--store-online",
        action="store_true",
        help="also write online.csv, the filter's pose estimates and their covariances "
        "(validation only)",
    )
    add_force_argument(m)
    m.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")
    m.set_defaults(func=run_slam)


def run_simulate(args: argparse.Namespace) -> int:
    from slamrel.formats.bundle import write_bundle
    from slamrel.simulation.bundles import world_bundle
    from slamrel.simulation.worlds import make_world

    check_rate(args.world, args.rate)
    check_outputs([], [], dirs=[args.output], force=args.force)
    world = make_world(args.world, noise=args.noise, seed=args.seed, rate=args.rate)
    write_bundle(args.output, world_bundle(world), force=args.force)
    if not args.quiet:
        print(
            f"{args.world}/{args.noise} seed {args.seed}: {len(world.truth)} poses, "
            f"{world.observations.t.size} measurements, {world.landmarks.shape[0]} landmarks "
            f"-> {args.output}"
        )
    return 0


def run_slam(args: argparse.Namespace) -> int:
    from slamrel.backends.ekf_slam import ekf_slam_bundle
    from slamrel.formats.bundle import read_bundle, write_bundle, write_online

    check_iterations(args)
    check_outputs([], [args.bundle], dirs=[args.output], force=args.force)
    bundle = read_bundle(args.bundle)
    words = {"association='nn'": "--association nn"}
    with errors_about(args.bundle), in_option_words(words):
        out, res = ekf_slam_bundle(
            bundle,
            association=args.association,
            corrupt_fraction=args.corrupt,
            noise_scale=args.noise_scale,
            outlier_gate=args.outlier_gate,
            seed=args.seed,
            jacobians=args.jacobians,
            iterations=args.iterations,
        )

    def online(folder: Path) -> None:
        write_online(folder / "online.csv", res.online, res.online_covariance)

    write_bundle(args.output, out, force=args.force, extra=online if args.store_online else None)
    if not args.quiet:
        rejected = int((res.association < 0).sum())
        print(
            f"EKF-SLAM: {res.landmark_ids.size} landmarks, {res.association.size - rejected} "
            f"measurements associated, {rejected} rejected, {int(res.wrong_association.sum())} "
            f"known-wrong associations -> {args.output}"
        )
    return 0
