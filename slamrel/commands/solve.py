"""``slamrel solve``: least squares or TORO on a pose graph, full or pose-only.

``--method lm`` (default): Levenberg–Marquardt on the whole graph (poses and landmarks).
``--method toro``: TORO (:mod:`slamrel.backends.toro_optimiser`) on a pose graph.
``--pose-only m1|m2``: a landmark graph is first turned into Hu et al.'s pose-only graph
(:func:`slamrel.backends.pose_only.pose_only_from_landmark_graph`), which ``--method``
then optimises; the landmarks are fitted to the resulting poses.
"""

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

    from slamrel.backends.graph import PoseGraph
    from slamrel.backends.least_squares import GraphSolution
    from slamrel.backends.pose_only import LandmarkLog


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    s = sub.add_parser(
        "solve",
        help="least squares or TORO on a pose graph, full or pose-only (g2o, TORO or iSAM text)",
        description="--method lm (default): Levenberg-Marquardt from the file's initial "
        "guess: the whole graph "
        "first, given up when it stalls (a step removing less than half the cost while "
        "chi2/dof > 4); then on a problem grown in pose order, --batch poses first, the "
        "step multiplied by --growth each time, a step "
        "whose solution is far less consistent (chi2/dof) than the last undone and retried "
        "smaller (an incremental smoother's way to avoid the local minima a single batch "
        "solve from chained odometry falls into on long runs such as Victoria Park). "
        "--method toro: TORO (Grisetti et al. 2007) on a pose graph, --toro-iterations "
        "passes. --pose-only m1|m2: a landmark graph becomes the pose-only graph of Hu et "
        "al. (Method 1: adjacent poses; Method 2: pose pairs sharing >= --min-common "
        "landmarks) plus its odometry, optimised by --method; the landmarks are then fitted "
        "to the poses. Writes trajectory.txt (t = pose index), landmarks.csv and solved.g2o "
        "(the graph optimised, at its solution) into -o DIR.",
    )
    s.add_argument("graph", metavar="GRAPH", help="g2o graph or iSAM text file")
    s.add_argument("-o", "--output", required=True, metavar="DIR", help="directory to write")
    _add_lm_arguments(s)
    _add_method_arguments(s)
    _add_toro_arguments(s)
    add_noise_argument(s)
    add_force_argument(s)
    s.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")
    s.set_defaults(func=run_solve)


def _add_lm_arguments(s: argparse.ArgumentParser) -> None:
    """``--method lm``'s stopping rule and its incremental schedule of sub-problems."""
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


def _add_method_arguments(s: argparse.ArgumentParser) -> None:
    """Which optimiser, on the graph as it is or on Hu et al.'s pose-only graph of it."""
    s.add_argument(
        "--method",
        choices=("lm", "toro"),
        default="lm",
        help="lm (default): Levenberg-Marquardt least squares; toro: TORO's stochastic "
        "gradient descent on a tree parameterisation (pose graphs only)",
    )
    s.add_argument(
        "--pose-only",
        choices=("none", "m1", "m2"),
        default="none",
        help="none (default): optimise the graph as it is; m1/m2: extract Hu et al.'s "
        "Method 1/2 relative-pose constraints from a landmark graph first",
    )
    s.add_argument(
        "--min-common",
        type=opt.int_range(2, 1000),
        default=5,
        metavar="K",
        help="Method 2: pose pairs sharing at least K landmarks (default 5, the paper's)",
    )


def _add_toro_arguments(s: argparse.ArgumentParser) -> None:
    """``--method toro``'s passes, spanning tree, visiting order and update rules."""
    s.add_argument(
        "--toro-iterations",
        type=opt.nonnegative_int,
        default=100,
        metavar="N",
        help="--method toro: passes over all constraints (default 100)",
    )
    s.add_argument(
        "--toro-tree",
        choices=("incremental", "breadth-first"),
        default="incremental",
        help="--method toro: incremental (default, TORO's: each pose below its lowest-index "
        "earlier neighbour) or breadth-first spanning tree",
    )
    s.add_argument(
        "--toro-order",
        choices=("depth", "input"),
        default="depth",
        help="--method toro: visit constraints by tree depth of their top pose (depth, the "
        "paper's) or in input order (default: %(default)s)",
    )
    s.add_argument(
        "--toro-rules",
        choices=("toro", "papers"),
        default="toro",
        help="--method toro: the step, weights and one constraint per pose pair of "
        "OpenSLAM's toro as measured on it (toro), or the update as the papers state it "
        "(papers) (default: %(default)s)",
    )


def _load(path: str, noise: str) -> tuple[PoseGraph, np.ndarray, np.ndarray]:
    """The graph and its file's pose and landmark ids."""
    import numpy as np

    from slamrel.formats.g2o import read_g2o_graph
    from slamrel.formats.isam import is_isam, read_isam
    from slamrel.formats.text import read_source
    from slamrel.formats.toro import is_toro, read_toro_graph

    # the reader of `import isam`, and its rules (comments, byte order mark, missing file,
    # a folder, no permission): the same file gets the same verdict from both commands
    src = read_source(path)
    if is_isam(src):
        with in_option_words(NOISE_WORDS):
            data = read_isam(path, noise=noise, source=src)  # type: ignore[arg-type]
        return data.graph, data.pose_ids, data.landmark_ids
    if is_toro(src):
        graph, ids = read_toro_graph(path)
        return graph, ids, np.empty(0, np.int64)
    return read_g2o_graph(path, source=src)


def run_solve(args: argparse.Namespace) -> int:
    import numpy as np

    from slamrel.backends.pose_only import landmarks_given_poses

    check_outputs([], [args.graph], dirs=[args.output], force=args.force)
    graph, pose_ids, lm_ids = _load(args.graph, args.noise)
    notes: list[str] = []
    sol = None
    with errors_about(args.graph):
        from slamrel.backends.least_squares import check_connected

        check_connected(graph, pose_ids=pose_ids, landmark_ids=lm_ids)  # named by file ids
        problem, log = _problem(args, graph, notes)
        if args.method == "toro":
            poses, landmarks, summary = _solve_toro(args, problem, notes)
        else:
            sol = _solve_lm(args, problem)
            poses, landmarks = np.asarray(sol.poses), np.asarray(sol.landmarks)
            summary = (
                f"{'converged' if sol.converged else 'NOT converged'} after {sol.iterations} "
                f"iterations: cost {sol.cost[0]:.6g} -> {sol.cost[-1]:.6g} "
                f"(sparse Cholesky: {sol.linear_solver})"
            )
        if log is not None:
            fitted, _, fitted_ids = landmarks_given_poses(log, poses)
            landmarks = np.zeros((graph.n_landmarks, 2))
            landmarks[fitted_ids] = fitted
    out = Path(args.output)
    _write_solution(args, problem, poses, landmarks, log, pose_ids, lm_ids)
    if sol is not None and not sol.converged:  # TORO runs a fixed number of passes
        # a result all the same (the last iterate is written), said even with -q
        warnings.warn(
            f"{args.graph}: NOT converged after {sol.iterations} iterations (cost "
            f"{sol.cost[0]:.6g} -> {sol.cost[-1]:.6g}); {out}/ holds the last iterate; "
            "raise --max-iterations",
            UserWarning,
            stacklevel=2,
        )
    if not args.quiet:
        for note in notes:
            print(note)
        print(f"{summary}; wrote {out}/")
        if sol is not None and sol.faster_solver == "cholmod":
            print(
                "note: this graph has much fill-in; CHOLMOD's supernodal Cholesky would "
                "factorise it faster than the core back-ends: install the optional `fast` "
                "extra (cvxopt, GPL-3.0)"
            )
    return 0


def _problem(
    args: argparse.Namespace, graph: PoseGraph, notes: list[str]
) -> tuple[PoseGraph, LandmarkLog | None]:
    """The graph to optimise: ``graph`` itself, or with ``--pose-only`` its pose-only graph
    and the landmark observations the landmarks are fitted from afterwards (its
    constraints counted in ``notes``)."""
    from relation_metric.errors import InputError
    from slamrel.backends.pose_only import pose_only_from_landmark_graph

    if args.pose_only == "none":
        return graph, None
    if graph.pl_k.size == 0:
        raise InputError(
            f"--pose-only {args.pose_only} extracts constraints from landmark "
            "observations, and this graph has none (a pose graph: drop --pose-only)"
        )
    po = pose_only_from_landmark_graph(
        graph, method=1 if args.pose_only == "m1" else 2, min_common=args.min_common
    )
    notes.append(
        f"pose-only {args.pose_only.upper()}: {po.constraints.pairs.shape[0]} pair "
        f"constraints from {graph.pl_k.size} observations, {graph.n_poses - 1} "
        f"odometry steps, {po.kept} other pose-pose factors kept"
    )
    return po.graph, po.log


def _solve_toro(
    args: argparse.Namespace, problem: PoseGraph, notes: list[str]
) -> tuple[np.ndarray, np.ndarray, str]:
    """TORO on a pose graph: its poses, the graph's landmarks (none) and the summary line
    (the constraints it left out noted in ``notes``)."""
    import numpy as np

    from relation_metric.errors import InputError
    from slamrel.backends.toro_optimiser import toro_optimize

    if problem.pl_k.size:
        raise InputError(
            f"TORO optimises pose graphs; this graph has {problem.pl_k.size} "
            "pose-landmark factors (--pose-only m1|m2 extracts a pose graph from them)"
        )
    tree = toro_optimize(
        problem,
        iterations=args.toro_iterations,
        tree=args.toro_tree,
        order=args.toro_order,
        rules=args.toro_rules,
    )
    if tree.dropped:
        notes.append(
            f"TORO used one constraint per pose pair, the first: {tree.dropped} later "
            "parallel constraints were left out of the steps (the cost counts them)"
        )
    summary = (
        f"TORO: {tree.iterations} iterations ({args.toro_tree} tree, mean path "
        f"{tree.mean_path_length:.3g} poses, {args.toro_order} order, "
        f"{args.toro_rules} rules): cost "
        f"{tree.cost[0]:.6g} -> {tree.cost[-1]:.6g}"
    )
    return np.asarray(tree.poses), np.asarray(problem.landmarks), summary


def _solve_lm(args: argparse.Namespace, problem: PoseGraph) -> GraphSolution:
    """Levenberg-Marquardt on ``problem``: one batch solve (``--batch 0``) or incremental."""
    from slamrel.backends.least_squares import solve_graph, solve_graph_incremental

    if args.batch == 0:
        return solve_graph(problem, max_iterations=args.max_iterations, tolerance=args.tolerance)
    return solve_graph_incremental(
        problem,
        batch=args.batch,
        growth=args.growth,
        max_iterations=args.max_iterations,
        tolerance=args.tolerance,
    )


def _write_solution(
    args: argparse.Namespace,
    problem: PoseGraph,
    poses: np.ndarray,
    landmarks: np.ndarray,
    log: LandmarkLog | None,
    pose_ids: np.ndarray,
    lm_ids: np.ndarray,
) -> None:
    """trajectory.txt, landmarks.csv and solved.g2o (``problem``'s factors at the solution;
    a pose-only problem's without landmarks) into ``-o DIR``, all or none."""
    import numpy as np

    from relation_metric.trajectory import Trajectory
    from slamrel.backends.graph import PoseGraph
    from slamrel.formats.g2o import write_g2o_graph
    from slamrel.formats.landmark_csv import write_landmark_csv
    from slamrel.formats.trajectories import write_trajectory
    from slamrel.outputs import staged_directory

    written = PoseGraph(
        poses, np.asarray(landmarks).reshape(-1, 2) if log is None else np.empty((0, 2)),
        problem.pp_i, problem.pp_j, problem.pp_z, problem.pp_info,
        problem.pl_k, problem.pl_l, problem.pl_z, problem.pl_info,
    )  # fmt: skip
    with staged_directory(Path(args.output), kind="solve", force=args.force) as tmp:
        write_trajectory(tmp / "trajectory.txt", Trajectory.from_poses(poses), format="plain")
        write_landmark_csv(tmp / "landmarks.csv", lm_ids, landmarks)
        write_g2o_graph(
            tmp / "solved.g2o",
            written,
            pose_ids=pose_ids,
            landmark_ids=lm_ids if log is None else np.empty(0, np.int64),
        )
