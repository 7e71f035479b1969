"""``slamrel run``: the main job end to end, with a self-contained report."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from relation_metric.errors import InputError
from slamrel.commands import options as opt
from slamrel.commands.common import add_force_argument, add_recovery_arguments, check_outputs
from slamrel.constants import NOISE_NAMES, WORLDS


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "run",
        help="simulate, run EKF-SLAM, recover and score the trajectory, write a report",
        description="SOURCE is a SLAM result bundle directory (scored against its "
        "groundtruth.csv) or a built-in world (" + ", ".join(WORLDS) + "); default simple1.",
    )
    p.add_argument("source", nargs="?", default="simple1", metavar="SOURCE")
    p.add_argument("-o", "--output", default="slamrel-report", metavar="DIR")
    p.add_argument("--noise", choices=NOISE_NAMES, default="a")
    p.add_argument("--seed", type=opt.seed, default=0)
    p.add_argument(
        "--rate", type=opt.nonnegative_int, default=0, help="control steps per measurement step"
    )
    p.add_argument(
        "--corrupt", type=opt.fraction, default=0.0, help="fraction of associations corrupted"
    )
    p.add_argument("--noise-scale", type=opt.positive_float, default=1.0)
    add_force_argument(p)
    add_recovery_arguments(
        p,
        fail_help="exit 3 when the recovery diverges (the report is still written, with dead "
        "reckoning)",
    )
    p.add_argument("-q", "--quiet", action="store_true")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from slamrel.pipeline import read_run_input, run_pipeline, write_report

    if args.source not in WORLDS and not Path(args.source).is_dir():
        raise InputError(
            f"unknown SOURCE {args.source!r}; expected a SLAM result bundle directory or one of "
            f"{', '.join(WORLDS)}"
        )
    is_dir = Path(args.source).is_dir()
    check_outputs([], [args.source if is_dir else None], dirs=[args.output], force=args.force)
    start = time.perf_counter()
    result = run_pipeline(
        read_run_input(args.source) if is_dir else args.source,
        noise=args.noise, seed=args.seed, rate=args.rate,
        corrupt_fraction=args.corrupt, noise_scale=args.noise_scale,
        max_outlier_run=args.max_outlier_run or None, robust=args.robust,
        on_divergence="raise" if args.fail_on_divergence else "reenter",
    )  # fmt: skip
    html = write_report(result, args.output, force=args.force)
    if not args.quiet:
        print(f"slamrel run {result.name} ({time.perf_counter() - start:.1f} s)")
        print(f"{'estimate':16s}{'relations':>13s}{'trans mean [m]':>16s}{'rot mean [rad]':>16s}")
        for name, evs in result.evaluations.items():
            for set_name in ("consecutive", "loops", "global"):
                if set_name in evs:
                    ev = evs[set_name]
                    print(
                        f"{name:16s}{set_name:>13s}{ev.translation['abs'].mean:16.4f}{ev.rotation['abs'].mean:16.4f}"
                    )
        a = result.agreement
        if a is not None and a.stretches:
            print(
                f"map and log DISAGREE on {len(a.stretches)} stretch(es), "
                f"{100 * a.fraction_of_log:.1f}% of the log (see the report)"
            )
        print(f"report: {html}")
    if result.recovery_error is not None:
        raise InputError(
            f"no trajectory recovered ({result.recovery_error}); report with dead reckoning "
            f"written to {html}"
        )
    return 0
