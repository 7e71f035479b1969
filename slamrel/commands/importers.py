"""``slamrel import isam`` and ``slamrel import mrclam``: public datasets → graphs and bundles."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from slamrel.commands import options as opt
from slamrel.commands.common import (
    NOISE_WORDS,
    add_force_argument,
    add_noise_argument,
    check_outputs,
    errors_about,
    in_option_words,
)

if TYPE_CHECKING:  # the library is imported where it is used: start-up stays light
    from recovery.bundle import Bundle


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    imp = sub.add_parser("import", help="import public datasets")
    isub = imp.add_subparsers(dest="import_command", metavar="FORMAT")
    isub.required = True
    i = isub.add_parser(
        "isam",
        help="iSAM/GTSAM text (ODOMETRY, LANDMARK) -> g2o graph",
        description="Read an iSAM/GTSAM planar text file (e.g. Victoria Park) and write it as "
        "a g2o graph whose vertices are the odometry initial guess.",
    )
    i.add_argument("file", metavar="FILE", help="iSAM/GTSAM planar text file")
    i.add_argument("-o", "--output", required=True, metavar="OUT.g2o", help="g2o file to write")
    add_noise_argument(i)
    i.add_argument(
        "--bundle",
        metavar="DIR",
        help="also write the problem as an EKF-SLAM log bundle (for slamrel slam / recover)",
    )
    add_force_argument(i)
    i.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")
    i.set_defaults(func=run_import_isam)
    mr = isub.add_parser(
        "mrclam",
        help="UTIAS MRCLAM robot logs -> SLAM log bundle (velocity model, fitted noise)",
        description="One bundle per robot (--robot N, or all five into OUT/robotN): controls, "
        "landmark measurements with their subjects as known association, surveyed landmarks as "
        "the map, Vicon ground truth; noise fitted from the data: the "
        "odometry's travel and turn over 1 s windows (--motion-window) against the ground "
        "truth's (sigma^2 = Var(window error) / mean(sum dt^2)), each range and bearing "
        "against the one predicted from the interpolated ground truth and the surveyed "
        "landmark: their white part, the part that persists along each landmark's track and "
        "across landmarks (--no-persisting: white only), the share of gross errors (the "
        "residuals beyond the 99.9% bound of the fitted sigma, less the 0.1% a Gaussian puts "
        "there); with --motion-noise speed also the odometry's persisting speed-scale and "
        "turn-per-metre error (--no-persisting: white only).",
    )
    mr.add_argument("directory", metavar="DIR", help="an extracted MRCLAM dataset directory")
    mr.add_argument(
        "--robot", type=opt.int_range(1, 5), default=None, help="1..5 (default: all five)"
    )
    mr.add_argument("-o", "--output", required=True, metavar="BUNDLE", help="bundle to write")
    mr.add_argument(
        "--no-calibrate",
        action="store_true",
        help="keep the raw odometry commands (default: delay and scales fitted against Vicon)",
    )
    mr.add_argument(
        "--motion-noise",
        choices=("speed", "constant"),
        default="speed",
        help="velocity-model noise growing with the commanded speeds (fitted alpha, zero at "
        "rest) or constant per control row (fitted sigma_v, sigma_omega) (default: %(default)s)",
    )
    mr.add_argument(
        "--decorrelate",
        type=opt.float_at_least(0.0),
        default=0.0,
        metavar="SECONDS",
        help="the data's errors persist over seconds: fit the motion noise over SECONDS windows "
        "and keep one sighting per landmark every SECONDS (the rest counted, left out), so "
        "white-noise models fit them (0: off; dataset 7: 5; default: %(default)s)",
    )
    mr.add_argument(
        "--motion-window",
        type=opt.float_at_least(0.1),
        default=1.0,
        metavar="SECONDS",
        help="fit the motion noise over windows of SECONDS (the odometry's errors persist: "
        "over 1 s and 10 s windows dataset 7's alpha1 is 3.5 and 16.6; with --persisting, "
        "the default, their persisting part is stated as motion_model.persisting and taken "
        "out of the fitted alpha) (default: %(default)s; --decorrelate sets it too)",
    )
    mr.add_argument(
        "--persisting",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="state the range-bearing errors' persistence in the bundle (sensor_model."
        "persisting: a Gauss-Markov bias per landmark track and one common to every landmark, "
        "sigma and time constant fitted against the ground truth), which the recovery then "
        "models, and with --motion-noise speed the odometry's (motion_model.persisting: a "
        "Gauss-Markov speed-scale and turn-per-metre error fitted to the autocovariance of the "
        "1 s windows' errors at lags of 1-30 windows; the model's alpha is then the fitted "
        "alpha less that error's share of it); --no-persisting: white range-bearing and "
        "motion noise, as before 2026-12-06 (default: on)",
    )
    add_force_argument(mr)
    mr.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")
    mr.set_defaults(func=run_import_mrclam)


def run_import_isam(args: argparse.Namespace) -> int:
    from slamrel.formats.g2o import write_g2o_graph
    from slamrel.formats.isam import read_isam

    check_outputs([args.output], [args.file], dirs=[args.bundle], force=args.force)
    with in_option_words(NOISE_WORDS):
        data = read_isam(args.file, noise=args.noise)
    log = None
    if args.bundle:  # built before anything is written: a file that cannot be one writes nothing
        from slamrel.formats.isam import isam_log_bundle

        with errors_about(args.file):
            log = isam_log_bundle(data)
    # the file's ids are kept: landmark names then agree with the --bundle log's map.csv
    write_g2o_graph(args.output, data.graph, pose_ids=data.pose_ids, landmark_ids=data.landmark_ids)
    if log is not None:
        from slamrel.formats.bundle import write_bundle

        write_bundle(args.bundle, log, force=args.force)
    g = data.graph
    if not args.quiet:
        print(
            f"{g.n_poses} poses, {g.n_landmarks} landmarks, {g.pp_i.size} pose-pose and "
            f"{g.pl_k.size} pose-landmark factors -> {args.output}"
        )
    return 0


def run_import_mrclam(args: argparse.Namespace) -> int:
    from slamrel.formats.bundle import write_bundle
    from slamrel.importers.mrclam import N_ROBOTS
    from slamrel.outputs import staged_directory

    check_outputs([], [args.directory], dirs=[args.output], force=args.force)
    if args.robot is not None:
        bundle = _mrclam_robot(args, args.robot, Path(args.output))
        write_bundle(args.output, bundle, force=args.force)
        return 0
    # all five robots: OUT/robot1..robot5 built together and swapped in as one folder
    with staged_directory(args.output, kind="mrclam-import", force=args.force) as tmp:
        for robot in range(1, N_ROBOTS + 1):
            bundle = _mrclam_robot(args, robot, Path(args.output) / f"robot{robot}")
            write_bundle(tmp / f"robot{robot}", bundle)
    return 0


def _mrclam_robot(args: argparse.Namespace, robot: int, out: Path) -> Bundle:
    """The bundle of one MRCLAM robot (printing its summary unless ``--quiet``)."""
    from slamrel.importers.mrclam import mrclam_bundle

    with errors_about(args.directory):
        bundle = mrclam_bundle(
            args.directory,
            robot,
            calibrate=not args.no_calibrate,
            motion_noise=args.motion_noise,
            decorrelate=args.decorrelate,
            persisting=args.persisting,
            window=args.motion_window,
        )
    if not args.quiet:
        assert bundle.controls is not None  # MRCLAM bundles use the velocity model
        print(
            f"robot {robot}: {bundle.controls.shape[0]} controls, "
            f"{bundle.measurements.shape[0]} landmark measurements -> {out}\n  "
            f"{bundle.description}"
        )
    return bundle
