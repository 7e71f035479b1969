"""``slamrel solve``: full least squares on a pose graph with landmarks."""

from __future__ import annotations

import argparse
import warnings
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
    import numpy as np

    from slamrel.backends.least_squares import PoseGraph


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
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
    s.add_argument("graph", metavar="GRAPH", help="g2o graph or iSAM text file")
    s.add_argument("-o", "--output", required=True, metavar="DIR", help="directory to write")
    s.add_argument(
        "--max-iterations",
        type=opt.positive_int,
        default=100,
        help="Levenberg-Marquardt iterations per sub-problem (default: %(default)s)",
    )
    s.add_argument(
        "--tolerance",
        type=opt.probability,
        default=1e-9,
        metavar="R",
        help="stop when an accepted step lowers the cost by less than this fraction of it "
        "(default 1e-9; GTSAM's LM default, relativeErrorTol, is 1e-5), or by less than "
        "1e-12 in all (chi2/2; a cost at the level of rounding has converged)",
    )
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
    add_noise_argument(s)
    add_force_argument(s)
    s.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")
    s.set_defaults(func=run_solve)


def _load(path: str, noise: str) -> tuple[PoseGraph, np.ndarray, np.ndarray]:
    """The graph and its file's pose and landmark ids."""
    from slamrel.formats.g2o import read_g2o_graph
    from slamrel.formats.isam import is_isam, read_isam
    from slamrel.formats.text import read_source

    # the reader of `import isam`, and its rules (comments, byte order mark, missing file,
    # a folder, no permission): the same file gets the same verdict from both commands
    src = read_source(path)
    if is_isam(src):
        with in_option_words(NOISE_WORDS):
            data = read_isam(path, noise=noise, source=src)  # type: ignore[arg-type]
        return data.graph, data.pose_ids, data.landmark_ids
    return read_g2o_graph(path, source=src)


def run_solve(args: argparse.Namespace) -> int:
    from relation_metric.trajectory import Trajectory
    from slamrel.backends.least_squares import solve_graph, solve_graph_incremental
    from slamrel.formats.g2o import write_g2o_graph
    from slamrel.formats.landmark_csv import write_landmark_csv
    from slamrel.formats.trajectories import write_trajectory
    from slamrel.outputs import staged_directory

    check_outputs([], [args.graph], dirs=[args.output], force=args.force)
    graph, pose_ids, lm_ids = _load(args.graph, args.noise)
    with errors_about(args.graph):
        if args.batch == 0:
            sol = solve_graph(graph, max_iterations=args.max_iterations, tolerance=args.tolerance)
        else:
            sol = solve_graph_incremental(
                graph,
                batch=args.batch,
                growth=args.growth,
                max_iterations=args.max_iterations,
                tolerance=args.tolerance,
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
            f"iterations: cost {sol.cost[0]:.6g} -> {sol.cost[-1]:.6g} "
            f"(sparse Cholesky: {sol.linear_solver}); wrote {out}/"
        )
        if sol.faster_solver == "cholmod":
            print(
                "note: this graph has much fill-in; CHOLMOD's supernodal Cholesky would solve "
                "it several times faster: install the optional `fast` extra (cvxopt, GPL-3.0)"
            )
    return 0
