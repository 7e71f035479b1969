"""``slamrel recover``: rebuild the trajectory of an EKF-SLAM run from its result bundle."""

from __future__ import annotations

import argparse
import io
import sys

from relation_metric.errors import InputError
from slamrel.commands import options as opt
from slamrel.commands.choices import MAP_MODES, METHODS
from slamrel.commands.common import check_outputs, errors_about

HELP = "recover the trajectory of an EKF-SLAM run by localisation in its final map"


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "recover",
        help=HELP,
        description=HELP + " (Burgard et al. 2009), then smooth it or refine it as a batch. "
        "BUNDLE is a SLAM result bundle directory (format slamrel-bundle/1).",
    )
    p.add_argument("bundle", metavar="BUNDLE", help="SLAM result bundle directory")
    p.add_argument("--method", choices=METHODS, default="smoother", help="(default: smoother)")
    p.add_argument("-o", "--output", required=True, metavar="TRAJ", help="recovered trajectory")
    p.add_argument(
        "--format",
        choices=("plain", "tum"),
        help="trajectory format (default: tum for *.tum, else plain 't x y theta')",
    )
    p.add_argument("--covariances", metavar="F", help="write per-pose covariances (N,3,3) .npy")
    p.add_argument("--report", metavar="F", help="write counts, NEES and settings as JSON")
    p.add_argument(
        "--gate",
        type=opt.probability,
        metavar="P",
        help="χ² probability of the innovation gate (default: no gate; gated measurements "
        "are counted and reported)",
    )
    p.add_argument(
        "--map-uncertainty",
        choices=MAP_MODES,
        default="joint",
        help="joint: Schmidt update with map_covariance.npy when present; marginal: "
        "per-landmark covariances; ignore: exact map (default: joint)",
    )
    p.add_argument(
        "--skip-unknown-landmarks",
        action="store_true",
        help="drop (and count) measurements whose landmark is not in map.csv",
    )
    p.add_argument(
        "--max-outlier-run",
        type=opt.nonnegative_int,
        default=100,
        metavar="N",
        help="stop as diverged after N consecutive outlying innovations (0: never)",
    )
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar, no summary")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from recovery.bundle import read_bundle
    from recovery.recover import recover
    from relation_metric.formats import write_trajectory
    from relation_metric.results import write_json
    from relation_metric.textio import write_bytes_atomic
    from relation_metric.timeorder import FILTER_TIME_TOLERANCE

    check_outputs([args.output, args.covariances, args.report], [args.bundle])
    fmt = args.format or ("tum" if args.output.lower().endswith(".tum") else "plain")
    if args.gate is not None and not 0.0 < args.gate < 1.0:
        raise InputError(f"--gate must be a probability in (0, 1), got {args.gate}")
    bundle = read_bundle(args.bundle, skip_unknown_landmarks=args.skip_unknown_landmarks)
    with errors_about(args.bundle):
        result = recover(
            bundle,
            method=args.method,
            gate=args.gate,
            map_mode=args.map_uncertainty,
            max_outlier_run=args.max_outlier_run or None,
            progress=not args.quiet and sys.stderr.isatty(),
        )
    write_trajectory(args.output, result.trajectory, format=fmt)
    if args.covariances:
        buf = io.BytesIO()
        np.save(buf, np.asarray(result.covariances), allow_pickle=False)
        write_bytes_atomic(args.covariances, buf.getvalue())
    report = result.report()
    report["gate"] = args.gate
    # rows put in time order under the filter-log rule (relation_metric.timeorder)
    report["reordered"] = dict(bundle.reordered)
    if args.report:
        write_json(args.report, report)
    if not args.quiet:
        c = result.counts
        print(
            f"{args.method}: {len(result.trajectory)} poses -> {args.output}; measurements "
            f"{c['measurements']}: used {c['used']}, gated {c['gated']} "
            f"({100 * c['gated_fraction']:.1f}% of associated), unassociated "
            f"{c['unassociated']}, outside the log {c['outside']}, unknown landmark "
            f"{c['skipped_unknown']}; map uncertainty: {result.map_mode}"
        )
        moved = {name: n for name, n in bundle.reordered.items() if n}
        if moved:
            print(
                "put in time order (steps back of at most "
                f"{FILTER_TIME_TOLERANCE:g} s): "
                + ", ".join(f"{n} row(s) of {name}" for name, n in moved.items())
            )
        if c["gated_fraction"] > 0.05:
            print(
                "note: a large gated fraction is a finding about the map (wrong associations "
                "or an inconsistent map), not noise"
            )
        if result.nees is not None and "nees" in report:
            print(f"mean pose NEES vs ground truth: {report['nees']['mean']:.3f} (3 dof)")  # type: ignore[index]
    return 0
