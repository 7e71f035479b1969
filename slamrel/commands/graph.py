"""``slamrel import isam`` and ``slamrel solve``: pose graphs with landmarks."""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

from relation_metric.errors import InputError
from slamrel.commands import options as opt
from slamrel.commands.common import add_force_argument, check_outputs, errors_about

if TYPE_CHECKING:  # the library is imported where it is used: start-up stays light
    import numpy as np

    from recovery.estimation.graph import PoseGraph


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
    i.add_argument("file", metavar="FILE")
    i.add_argument("-o", "--output", required=True, metavar="OUT.g2o")
    i.add_argument(
        "--noise",
        choices=("covariance", "sqrt-information"),
        default="covariance",
        help="what the noise numbers are "
        "(GTSAM's copy: covariance; original iSAM: sqrt-information)",
    )
    i.add_argument(
        "--bundle",
        metavar="DIR",
        help="also write the problem as an EKF-SLAM log bundle (for slamrel slam / recover)",
    )
    add_force_argument(i)
    i.add_argument("-q", "--quiet", action="store_true")
    i.set_defaults(func=run_import_isam)
    mr = isub.add_parser(
        "mrclam",
        help="UTIAS MRCLAM robot logs -> SLAM log bundle (velocity model, fitted noise)",
        description="One bundle per robot (--robot N, or all five into OUT/robotN): controls, "
        "landmark measurements with their subjects as known association, surveyed landmarks as "
        "the map, Vicon ground truth; noise fitted from the data (see fit_noise).",
    )
    mr.add_argument("directory", metavar="DIR")
    mr.add_argument(
        "--robot", type=opt.int_range(1, 5), default=None, help="1..5 (default: all five)"
    )
    mr.add_argument("-o", "--output", required=True, metavar="BUNDLE")
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
        "rest; default) or constant per control row (fitted sigma_v, sigma_omega)",
    )
    add_force_argument(mr)
    mr.add_argument("-q", "--quiet", action="store_true")
    mr.set_defaults(func=run_import_mrclam)

    s = sub.add_parser(
        "solve",
        help="full least squares on a pose graph with landmarks (g2o or iSAM text)",
        description="Levenberg-Marquardt from the file's initial guess: the whole graph "
        "first, given up when it stalls (a step removing less than half the cost while "
        "chi2/dof > 4); then on a problem grown in pose order, --batch poses first, the "
        "step multiplied by --growth each time, a step "
        "whose solution is far less consistent (chi2/dof) than the last undone and retried "
        "smaller (an incremental smoother's way to avoid the local minima a single batch "
        "solve from chained odometry falls into on long runs such as Victoria Park); writes "
        "trajectory.txt (t = pose index), landmarks.csv and solved.g2o into -o DIR.",
    )
    s.add_argument("graph", metavar="GRAPH")
    s.add_argument("-o", "--output", required=True, metavar="DIR")
    s.add_argument("--max-iterations", type=opt.positive_int, default=100, help="per sub-problem")
    s.add_argument(
        "--batch",
        type=opt.nonnegative_int,
        default=500,
        metavar="N",
        help="poses of the first sub-problem (default 500; 0: one batch solve of the whole graph)",
    )
    s.add_argument(
        "--growth",
        type=opt.float_at_least(1.0),
        default=2.0,
        metavar="F",
        help="factor on the poses added per sub-problem (default 2; 1: a fixed step of --batch)",
    )
    s.add_argument("--noise", choices=("covariance", "sqrt-information"), default="covariance")
    add_force_argument(s)
    s.add_argument("-q", "--quiet", action="store_true")
    s.set_defaults(func=run_solve)


def _load(path: str, noise: str) -> tuple[PoseGraph, np.ndarray, np.ndarray]:
    """The graph and its file's pose and landmark ids."""
    from recovery.graph_formats.g2o import read_g2o_graph
    from slamrel.importers.isam import read_isam

    head = Path(path).read_text(errors="replace")[:4096].split()
    if head and head[0] in ("ODOMETRY", "LANDMARK"):
        data = read_isam(path, noise=noise)  # type: ignore[arg-type]
        return data.graph, data.pose_ids, data.landmark_ids
    return read_g2o_graph(path)


def run_import_isam(args: argparse.Namespace) -> int:
    from recovery.graph_formats.g2o import write_g2o_graph
    from slamrel.importers.isam import read_isam

    check_outputs([args.output], [args.file], dirs=[args.bundle], force=args.force)
    data = read_isam(args.file, noise=args.noise)
    # the file's ids are kept: landmark names then agree with the --bundle log's map.csv
    write_g2o_graph(args.output, data.graph, pose_ids=data.pose_ids, landmark_ids=data.landmark_ids)
    if args.bundle:
        from recovery.bundle import write_bundle
        from slamrel.importers.isam import isam_log_bundle

        write_bundle(args.bundle, isam_log_bundle(data), force=args.force)
    g = data.graph
    if not args.quiet:
        print(
            f"{g.n_poses} poses, {g.n_landmarks} landmarks, {g.pp_i.size} pose-pose and "
            f"{g.pl_k.size} pose-landmark factors -> {args.output}"
        )
    return 0


def run_import_mrclam(args: argparse.Namespace) -> int:
    from recovery.bundle import write_bundle
    from relation_metric.outputs import staged_directory
    from slamrel.importers.mrclam import N_ROBOTS

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


def _mrclam_robot(args: argparse.Namespace, robot: int, out: Path):  # type: ignore[no-untyped-def]
    """The bundle of one MRCLAM robot (printing its summary unless ``--quiet``)."""
    from slamrel.importers.mrclam import mrclam_bundle

    with errors_about(args.directory):
        bundle = mrclam_bundle(
            args.directory,
            robot,
            calibrate=not args.no_calibrate,
            motion_noise=args.motion_noise,
        )
    if not args.quiet:
        print(
            f"robot {robot}: {bundle.controls.shape[0]} controls, "
            f"{bundle.measurements.shape[0]} landmark measurements -> {out}\n  "
            f"{bundle.description}"
        )
    return bundle


def run_solve(args: argparse.Namespace) -> int:
    from recovery.estimation.graph import solve_graph, solve_graph_incremental
    from recovery.graph_formats.g2o import write_g2o_graph
    from relation_metric.formats import write_trajectory
    from relation_metric.landmarks import write_landmark_csv
    from relation_metric.outputs import staged_directory
    from relation_metric.trajectory import Trajectory

    check_outputs([], [args.graph], dirs=[args.output], force=args.force)
    if not Path(args.graph).is_file():
        raise InputError("no such file", path=args.graph)
    graph, pose_ids, lm_ids = _load(args.graph, args.noise)
    with errors_about(args.graph):
        if args.batch == 0:
            sol = solve_graph(graph, max_iterations=args.max_iterations)
        else:
            sol = solve_graph_incremental(
                graph, batch=args.batch, growth=args.growth, max_iterations=args.max_iterations
            )
    out = Path(args.output)
    with staged_directory(out, kind="solve", force=args.force) as tmp:
        write_trajectory(tmp / "trajectory.txt", Trajectory.from_poses(sol.poses), format="plain")
        write_landmark_csv(tmp / "landmarks.csv", lm_ids, sol.landmarks)
        write_g2o_graph(
            tmp / "solved.g2o",
            graph,
            poses=sol.poses,
            landmarks=sol.landmarks,
            pose_ids=pose_ids,
            landmark_ids=lm_ids,
        )
    if not sol.converged:
        # a result all the same (the last iterate is written), said even with -q
        warnings.warn(
            f"{args.graph}: NOT converged after {sol.iterations} iterations (cost "
            f"{sol.cost[0]:.6g} -> {sol.cost[-1]:.6g}); {out}/ holds the last iterate; "
            "raise --max-iterations",
            UserWarning,
            stacklevel=2,
        )
    if not args.quiet:
        print(
            f"{'converged' if sol.converged else 'NOT converged'} after {sol.iterations} "
            f"iterations: cost {sol.cost[0]:.6g} -> {sol.cost[-1]:.6g}; wrote {out}/"
        )
    return 0
