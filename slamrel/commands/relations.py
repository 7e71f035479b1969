"""``slamrel relations generate``: select reference relations from a trajectory;
``slamrel relations align``: make them from a laser log (CARMEN, or a ROS bag's
``sensor_msgs/LaserScan`` topic) by scan alignment; ``slamrel relations from-graph``: from
the loop closures of an optimised pose graph."""

from __future__ import annotations

import argparse
import math
from typing import TYPE_CHECKING, Any

from slamrel.commands.common import (
    add_strategy_arguments,
    check_outputs,
    errors_about,
    input_files,
    relations_from_args,
)
from slamrel.constants import TRAJECTORY_FORMATS

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

    from slamrel.formats.laser import LaserScans
    from slamrel.scans.proposals import Proposals
    from slamrel.scans.relations import AlignOptions, ScanRelations

#: ``relations align --loop-growth``'s default [m per metre travelled]: chosen on the
#: corridor worlds 103 and 107, held out on 108–116 and the loop world's seeds 0–4
#: (benchmarks/README.md, "Defaults of relations align").
LOOP_GROWTH = 0.02
#: ``relations align --loop-min-overlap``'s default: chosen on corridor worlds 103 and
#: 107, held out on 111–116 and the loop world's seeds 0, 1, 3, 4 (docs/laser-relations.md,
#: "Loop pairs whose scans cannot overlap").
LOOP_MIN_OVERLAP = 0.3


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
    _register_align(rsub)
    _register_from_graph(rsub)


def _register_from_graph(rsub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """``relations from-graph``: Cartographer's ``autogenerate_ground_truth`` on g2o/TORO."""
    from slamrel.constants import GRAPH_MAX_ERROR_THETA as MAX_ERROR_THETA
    from slamrel.constants import GRAPH_MAX_ERROR_XY as MAX_ERROR_XY
    from slamrel.constants import GRAPH_MIN_TRAVEL as MIN_TRAVEL

    f = rsub.add_parser(
        "from-graph",
        help="make reference relations from an optimised pose graph's loop closures",
        description="Keep the loop closures (edges between non-consecutive poses) of an "
        "optimised g2o or TORO pose graph that agree with the graph's own vertices within "
        "outlier thresholds and span a least travelled distance (Cartographer's "
        "autogenerate_ground_truth), and write them as a Freiburg .relations file. The "
        "relations' times are the vertex ids (as the g2o trajectory reader's), or --times.",
    )
    f.add_argument("graph", metavar="GRAPH", help="optimised pose graph (.g2o, or TORO .graph)")
    f.add_argument("-o", "--output", required=True, metavar="OUT", help="output .relations")
    f.add_argument(
        "--min-travel",
        type=float,
        default=MIN_TRAVEL,
        help="least distance travelled along the graph's poses between the two ends of a "
        "loop closure [m] (Cartographer's min_covered_distance; default %(default)g)",
    )
    f.add_argument(
        "--max-error-xy",
        type=float,
        default=MAX_ERROR_XY,
        help="drop loop closures whose translation disagrees with the vertices by more than "
        "this [m] (outlier_threshold_meters; default %(default)g)",
    )
    f.add_argument(
        "--max-error-theta",
        type=float,
        default=MAX_ERROR_THETA,
        help="the same for the rotation [rad] (outlier_threshold_radians; default %(default)g)",
    )
    f.add_argument(
        "--times",
        metavar="FILE",
        help="timestamps of the pose vertices, one a line in increasing vertex-id order "
        "(default: the vertex id is the time)",
    )
    f.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")
    f.set_defaults(func=run_from_graph)


def _register_align(rsub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """``relations align``'s parser; its options in groups, one function each."""
    a = rsub.add_parser(
        "align",
        help="make reference relations from a laser log by scan alignment",
        description="Align pairs of laser scans of a CARMEN log or of a ROS bag's "
        "sensor_msgs/LaserScan topic (point-to-line ICP from an initial guess, a "
        "correlative search where the guess is poor) and write the relations of the laser's "
        "poses as a Freiburg .relations file, with a per-relation quality report (matched "
        "fraction, residual, degeneracy, flags) for review.",
    )
    _add_align_io_arguments(a)
    _add_align_guess_arguments(a)
    _add_align_pair_arguments(a)
    _add_align_search_arguments(a)
    a.add_argument(
        "--cycle-check",
        action="store_true",
        help="also test the unflagged relations against the short cycles they close with "
        "each other, and flag those their neighbours contradict ('contradicted')",
    )
    a.add_argument(
        "--adjust",
        action="store_true",
        help="fit poses to the unflagged relations (least squares over the graph they "
        "form, each weighted by its covariance) and write them re-read from the fitted "
        "poses: where they close cycles their independent alignment noise averages out; "
        "flagged relations are neither used nor changed",
    )
    a.add_argument(
        "--adjust-max-move",
        type=float,
        default=0.05,
        metavar="M",
        help="--adjust: a relation the fit would move farther than M [m] (or "
        "--adjust-max-move-angle) is left out of it and keeps its aligned value "
        "(default 0.05)",
    )
    a.add_argument(
        "--adjust-max-move-angle",
        type=float,
        default=0.02,
        metavar="RAD",
        help="--adjust: the same for the rotation [rad] (default 0.02)",
    )
    a.add_argument(
        "--time-tolerance",
        type=float,
        default=0.05,
        help="--at: largest gap between a relation time and its scan [s] (default 0.05)",
    )
    a.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")
    a.set_defaults(func=run_align)


def _add_align_io_arguments(a: argparse.ArgumentParser) -> None:
    """The laser log read, and the files written (relations, quality report, review page)."""
    a.add_argument(
        "log",
        metavar="LOG",
        help="CARMEN log with laser scans (.clf/.log), or a ROS bag's sensor_msgs/LaserScan "
        "topic BAG:TOPIC (needs the 'bags' extra; give --estimate for its poses)",
    )
    a.add_argument("-o", "--output", required=True, metavar="OUT", help="output .relations")
    a.add_argument(
        "--report",
        metavar="CSV",
        help="also write the per-relation quality report (CSV, one row a relation)",
    )
    a.add_argument(
        "--review",
        metavar="HTML",
        help="also write the review page (one self-contained file: overlay, accept/reject, "
        "nudge, re-align, save .relations and the review state)",
    )


def _add_align_guess_arguments(a: argparse.ArgumentParser) -> None:
    """The scans' poses, which give the alignments their initial guesses: the log's own,
    or an estimate's (a bag's scans have none)."""
    a.add_argument(
        "--record",
        help="laser record to read (FLASER, RLASER, ROBOTLASER1, ...; default: the only "
        "kind the log holds)",
    )
    a.add_argument(
        "--estimate",
        metavar="TRAJ",
        help="trajectory whose laser poses give the initial guesses (default: the log's own "
        "laser poses, i.e. its odometry). A bag's scans have no poses: there TRAJ is required "
        "and holds the robot's poses, e.g. BAG:/odom (nav_msgs/Odometry), interpolated at the "
        "scan stamps and composed with the laser's offset (see --base-frame)",
    )
    a.add_argument(
        "--base-frame",
        metavar="FRAME",
        help="bag LOG: the frame whose poses --estimate holds; the laser's pose in it is "
        "composed from the bag's tf_static (FRAME -> the scans' frame_id). Default: the "
        "estimate's child frame (an Odometry's child_frame_id, a tf chain's CHILD); without "
        "one, or without that static transform, the offset is zero, with a warning",
    )
    a.add_argument("--estimate-format", choices=TRAJECTORY_FORMATS, help="format of TRAJ")
    a.add_argument(
        "--chain-guesses",
        action="store_true",
        help="propose the pairs from, and guess by, the scans' own scan-matched odometry: "
        "keyframes of the poses above (the log's, or TRAJ's) linked by ICP, the other scans "
        "placed from them by the poses' motion (a drifting odometry finds its loop pairs; "
        "the reference leans on the poses only between neighbouring keyframes)",
    )
    a.add_argument(
        "--skip-invalid-poses",
        action="store_true",
        help="CARMEN logs only (FLASER, ROBOTLASER1, ODOM records): skip (and count) "
        "estimate pose records with non-finite values instead of refusing the file; other "
        "formats refuse them whatever this option",
    )


def _add_align_pair_arguments(a: argparse.ArgumentParser) -> None:
    """Which pairs of scans are aligned: a .relations file's, or keyframes (consecutive,
    and loops)."""
    which = a.add_mutually_exclusive_group()
    which.add_argument(
        "--at",
        metavar="RELATIONS",
        help="align the timestamp pairs of this .relations file (re-derive or audit it)",
    )
    which.add_argument(
        "--loops",
        action="store_true",
        help="add loop pairs (keyframes within --loop-radius, --loop-min-travel apart along "
        "the path) to the consecutive pairs",
    )
    a.add_argument(
        "--distance",
        type=float,
        default=0.5,
        help="keyframe spacing by travel [m] for consecutive and loop pairs (default 0.5)",
    )
    a.add_argument(
        "--angle",
        type=float,
        default=0.3,
        help="keyframe spacing by rotation [rad] (default 0.3)",
    )
    a.add_argument(
        "--keyframes",
        choices=("motion", "travel"),
        default="travel",
        help="travel: one every --distance of path length, as dense from drifting poses as "
        "from true ones; motion: a keyframe where the motion since the last one reaches "
        "--distance (each overshoot adds up: drifting poses keep fewer keyframes, and "
        "fewer loop pairs, than exact ones) (default: %(default)s)",
    )
    a.add_argument(
        "--loop-radius", type=float, default=1.0, help="loop pair radius [m] (default 1.0)"
    )
    a.add_argument(
        "--loop-min-travel",
        type=float,
        default=10.0,
        help="least travel between the two scans of a loop pair [m] (default 10)",
    )
    a.add_argument(
        "--loop-max-angle",
        type=float,
        default=180.0,
        metavar="DEG",
        help="largest heading difference of the two scans of a loop pair [deg], in (0, 180] "
        "(default: 180, any; scans seen from opposite headings alias most in corridors)",
    )
    a.add_argument(
        "--loop-growth",
        type=float,
        default=LOOP_GROWTH,
        metavar="M",
        help="loop candidates within --loop-radius + M per metre travelled between the two "
        "scans (the heading limit + 0.05 M rad/m: the poses' accumulated drift), aligned, "
        "then kept where the aligned motion lies within --loop-radius and --loop-max-angle; "
        "0: only the pairs the poses propose (default: %(default)s, a drifting odometry "
        "then finds the loop pairs the true poses would)",
    )
    a.add_argument(
        "--loop-min-overlap",
        type=float,
        default=LOOP_MIN_OVERLAP,
        metavar="F",
        help="leave out loop candidates whose two scans cannot share F of one scan's "
        "returns (inside the other's field of view and range, not behind its returns) at "
        "any relative pose within the guesses' uncertainty (0.3 m + M·D, 0.05 rad + "
        "0.05 M·D), and loop relations whose scans share less than F at the aligned pose; "
        "both counted in the summary; in [0, 1], 0: keep all (default: %(default)s)",
    )


def _add_align_search_arguments(a: argparse.ArgumentParser) -> None:
    """How each pair is aligned (the correlative search, the readings used) and when a
    relation is flagged for review."""
    a.add_argument(
        "--aligner",
        choices=("global", "icp"),
        default="global",
        help="global: a scan-matched chain, then distant pairs searched by branch and bound "
        "submap against submap over a window from the chain's drift, ambiguity flagged; "
        "icp: ICP from each pair's guess, a correlative search where it is lost (the aligner "
        "before issue 37) (default: %(default)s)",
    )
    a.add_argument(
        "--drift-xy",
        type=float,
        default=0.01,
        help="global: search window growth per metre travelled between the scans [m/m] "
        "(default 0.01; window 0.3 m + drift)",
    )
    a.add_argument(
        "--drift-theta",
        type=float,
        default=0.0005,
        help="global: rotation window growth [rad/m] (default 0.0005; window 0.05 rad + drift)",
    )
    a.add_argument(
        "--ambiguity",
        type=float,
        default=0.95,
        help="global: flag a relation whose second hypothesis (a distinct pose) scores at "
        "least this share of the best (default 0.95)",
    )
    a.add_argument(
        "--global-search",
        choices=("never", "flagged", "always"),
        default="flagged",
        help="when to run the correlative search around the guess: never, flagged (for "
        "pairs the first alignment leaves failed, with low overlap or a high residual), or "
        "always (default: %(default)s)",
    )
    a.add_argument(
        "--search-xy",
        type=float,
        default=1.5,
        help="half width of the correlative search in x and y [m] (default 1.5)",
    )
    a.add_argument(
        "--search-theta",
        type=float,
        default=0.5,
        help="half width of the correlative search in rotation [rad] (default 0.5)",
    )
    a.add_argument(
        "--max-correction",
        type=float,
        default=0.1,
        help="flag relations the alignment moved farther than this from their guess [m] "
        "(default 0.1; raise it when the guesses are known to be poor)",
    )
    a.add_argument(
        "--max-correction-angle",
        type=float,
        default=0.05,
        help="the same for the rotation [rad] (default 0.05)",
    )
    a.add_argument(
        "--max-range",
        type=float,
        help="ignore readings at or beyond this [m] (default: the scan's maximum range)",
    )


def run_generate(args: argparse.Namespace) -> int:
    from slamrel.evaluation import load_trajectory
    from slamrel.formats.relations import write_relations

    check_outputs([args.output], [args.reference])
    reference = load_trajectory(
        args.reference, args.format, planar=args.planar, times=args.times
    ).trajectory
    with errors_about(args.reference):
        rel = relations_from_args(reference, args)
    write_relations(args.output, rel)
    if not args.quiet:
        dim = "3-D" if reference.group.name == "SE3" else "2-D"
        print(
            f"{len(rel)} {args.strategy} relations from {len(reference)} {dim} poses "
            f"-> {args.output}"
        )
    return 0


def run_from_graph(args: argparse.Namespace) -> int:
    import numpy as np

    from relation_metric.errors import InputError, OptionError
    from relation_metric.relations import RelationSet
    from slamrel.backends.graph_relations import OUTLIER, SHORT, graph_relations
    from slamrel.formats.relations import write_relations

    if not args.min_travel >= 0:
        raise OptionError("--min-travel must be zero or positive")
    for name in ("max_error_xy", "max_error_theta"):
        if not getattr(args, name) > 0:
            raise OptionError(f"--{name.replace('_', '-')} must be positive")
    check_outputs([args.output], [args.graph, args.times])
    graph, ids = _read_pose_graph(args.graph)
    times = ids.astype(np.float64) if args.times is None else _vertex_times(args.times, ids.size)
    got = graph_relations(
        graph,
        min_travel=args.min_travel,
        max_error_xy=args.max_error_xy,
        max_error_theta=args.max_error_theta,
    )
    if got.first.size == 0:
        raise InputError(
            f"no loop closures: all {got.sequential} pose-pose edges join consecutive poses "
            "(in vertex-id order); relations are made from edges between non-consecutive poses",
            path=args.graph,
        )
    k = got.kept
    rel = RelationSet(times[got.first[k]], times[got.second[k]], got.delta[k], key="time")
    write_relations(args.output, rel)
    if not args.quiet:
        n = got.counts()
        base = "vertex ids" if args.times is None else args.times
        unused = f"; {graph.pl_k.size} pose-landmark edges not used" if graph.pl_k.size else ""
        print(
            f"{n['kept']} relations from {got.first.size} loop closures of {args.graph} "
            f"({got.sequential} sequential edges{unused}; times: {base}) -> {args.output}"
        )
        print(
            f"dropped {n[SHORT]} with less than {args.min_travel:g} m travelled, {n[OUTLIER]} "
            f"outliers (> {args.max_error_xy:g} m or > {args.max_error_theta:g} rad from the "
            "vertices)"
        )
    return 0


def _read_pose_graph(path: str) -> tuple[Any, Any]:
    """A g2o or TORO graph (its vertices the optimum) and its pose ids; iSAM text holds no
    vertices and is refused."""
    from relation_metric.errors import InputError
    from slamrel.formats.g2o import read_g2o_graph
    from slamrel.formats.isam import is_isam
    from slamrel.formats.text import read_source
    from slamrel.formats.toro import is_toro, read_toro_graph

    src = read_source(path)
    if is_isam(src):
        raise InputError(
            "iSAM text holds no vertex poses (no optimum to check the loop closures "
            "against); expected a g2o (VERTEX_SE2/EDGE_SE2) or TORO (VERTEX2/EDGE2) graph",
            path=path,
        )
    if is_toro(src):
        return read_toro_graph(path)
    graph, ids, _ = read_g2o_graph(path, source=src)
    return graph, ids


def _vertex_times(path: str, n: int) -> Any:
    """``--times``: one timestamp a pose vertex, in increasing vertex-id order."""
    import numpy as np

    from relation_metric.errors import InputError
    from slamrel.formats.text import read_numeric_table

    values, lines = read_numeric_table(path, columns=("t",), describe="a times file (one a line)")
    if values.shape[0] != n:
        raise InputError(
            f"{values.shape[0]} timestamps for the graph's {n} pose vertices; expected one a "
            "vertex, in increasing vertex-id order",
            path=path,
        )
    t = values[:, 0]
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size:  # a relation's two times would come out swapped or equal
        k = int(back[0]) + 1
        raise InputError(
            f"t = {float(t[k])!r} after t = {float(t[k - 1])!r}: expected increasing "
            "timestamps, one a pose vertex in increasing vertex-id order",
            path=path,
            line=lines(k),
        )
    return t


def run_align(args: argparse.Namespace) -> int:
    from slamrel.formats.laser import read_laser_scans
    from slamrel.formats.relations import write_relations
    from slamrel.scans.relations import align_scans, guesses_from_poses

    bag = _checked_align_options(args)
    check_outputs(
        [args.output, args.report, args.review], input_files([args.log, args.estimate, args.at])
    )
    scans = read_laser_scans(args.log, record=args.record)
    scans, poses, summary = _align_guesses(args, scans, bag)
    options = _align_options(args)
    if args.chain_guesses:
        from slamrel.scans.own_guesses import chain_guesses

        own = chain_guesses(
            scans,
            poses,
            distance=args.distance,
            angle=args.angle,
            options=options,
            global_options=_global_options(args),
        )
        poses = own.poses
        summary += f"; pairs and guesses from the scans' chain of {len(own.chain.nodes)} scans"
    prop, unseen = _align_pairs(args, scans, poses)
    if args.aligner == "global":
        from slamrel.scans.global_align import align_scans_global

        result, chain = align_scans_global(scans, prop, poses, options, _global_options(args))
        how = (
            f"{int((result.initialiser == 'search').sum())} searched by branch and bound "
            f"(chain of {len(chain.nodes)} scans, {chain.fallback} link(s) kept as given)"
        )
    else:
        result = align_scans(scans, prop, guesses_from_poses(poses, prop), options)
        how = (
            f"{int((result.initialiser == 'correlative').sum())} re-initialised by the "
            "correlative search"
        )
    if args.loops and args.loop_growth > 0:  # the loop rule on what the scans say
        from slamrel.scans.proposals import keep_within_reach

        candidates = len(result)
        result = keep_within_reach(
            result, radius=args.loop_radius, max_angle=math.radians(args.loop_max_angle)
        )
        how += f"; {candidates - len(result)} loop candidate(s) aligned beyond reach, left out"
    if args.loops and args.loop_min_overlap > 0:  # the overlap rule on the aligned motion
        from slamrel.scans.proposals import keep_overlapping

        result, apart = keep_overlapping(
            result, scans, min_overlap=args.loop_min_overlap, max_range=args.max_range
        )
        how += (
            f"; loop pairs whose scans share < {args.loop_min_overlap:g} of their returns "
            f"left out: {unseen} before alignment (at any pose within the guesses' "
            f"uncertainty), {apart} after (at the aligned pose)"
        )
    if args.cycle_check:
        from slamrel.scans.cycles import check_scan_relations, mark_contradicted

        check = check_scan_relations(result)
        result = mark_contradicted(result, check)
    if args.adjust:
        result, adjusted = _adjusted(args, result)
        how += f"; {adjusted}"
    write_relations(args.output, result.relation_set())
    _write_align_extras(args, scans, result, poses, options, bag)
    if not args.quiet:
        flagged = int(result.flagged.sum())
        failed = int(result.failed.sum())
        print(
            f"{len(result) - failed} relations from {len(scans)} {scans.record} scans "
            f"({summary}) -> {args.output}"
        )
        print(
            f"{flagged} flagged for review ({failed} failed: left out, listed in the report), {how}"
        )
        if args.cycle_check:
            print(
                f"cycle check: {check.count} contradicted by their cycles ({check.n_cycles} "
                f"cycles; {check.unchecked} relations in none)"
            )
    return 0


def _adjusted(args: argparse.Namespace, result: ScanRelations) -> tuple[ScanRelations, str]:
    """``--adjust``: the unflagged relations re-read from poses fitted to them
    (:func:`slamrel.backends.relation_adjust.adjust_relations`), and what was done (for the
    summary)."""
    from dataclasses import replace

    import numpy as np

    from slamrel.backends.relation_adjust import adjust_relations

    p = result.proposals.pairs
    cov = result.covariance
    finite = np.isfinite(cov).all(axis=(1, 2)) & np.isfinite(result.delta).all(axis=1)
    use = ~result.flagged & finite
    # a relation whose covariance is not positive definite cannot weigh in the fit
    use[use] = np.linalg.eigvalsh(0.5 * (cov[use] + np.swapaxes(cov[use], 1, 2))).min(1) > 0
    adj = adjust_relations(
        p[:, 0],
        p[:, 1],
        result.delta,
        result.covariance,
        use=use,
        max_move=args.adjust_max_move,
        max_move_angle=args.adjust_max_move_angle,
    )
    said = (
        f"adjusted: {int(adj.adjusted.sum())} relation(s) on cycles re-read from the fitted "
        f"poses (redundancy {adj.redundancy}), {int(adj.set_aside.sum())} left out of the fit "
        "(it would move them beyond --adjust-max-move)"
    )
    return replace(result, delta=adj.delta), said


def _global_options(args: argparse.Namespace) -> Any:
    """The guess-independent aligner's options from the command line."""
    from slamrel.scans.global_align import GlobalOptions

    return GlobalOptions(
        drift_xy=args.drift_xy, drift_theta=args.drift_theta, ambiguity=args.ambiguity
    )


def _checked_align_options(args: argparse.Namespace) -> bool:
    """Refuse option values ``relations align`` cannot use, before any file is read; whether
    LOG names a ROS bag (whose options differ from a CARMEN log's)."""
    from relation_metric.errors import OptionError
    from slamrel.formats.bags import names_bag

    names = ("distance", "angle", "loop_radius", "search_xy", "search_theta", "max_correction")
    for name in (*names, "max_correction_angle"):
        if not getattr(args, name) > 0:
            raise OptionError(f"--{name.replace('_', '-')} must be positive")
    if not (0 <= args.drift_xy <= 1 and 0 <= args.drift_theta <= 0.1):
        raise OptionError("--drift-xy must lie in [0, 1] and --drift-theta in [0, 0.1]")
    if not 0 < args.ambiguity <= 1:
        raise OptionError("--ambiguity must lie in (0, 1]")
    if args.max_range is not None and not args.max_range > 0:
        raise OptionError("--max-range must be positive")
    if not 0 < args.loop_max_angle <= 180:
        raise OptionError("--loop-max-angle must lie in (0, 180] degrees")
    if not 0 <= args.loop_growth <= 1:
        raise OptionError("--loop-growth must lie in [0, 1] m per metre")
    if not 0 <= args.loop_min_overlap <= 1:
        raise OptionError("--loop-min-overlap must lie in [0, 1]")
    if not (0 < args.adjust_max_move <= 10 and 0 < args.adjust_max_move_angle <= math.pi):
        raise OptionError(
            "--adjust-max-move must lie in (0, 10] m and --adjust-max-move-angle in (0, π] rad"
        )
    for name in ("loop_min_travel", "time_tolerance"):  # read only with --loops, --at
        if not getattr(args, name) >= 0:
            raise OptionError(f"--{name.replace('_', '-')} must be 0 or more")
    bag = names_bag(args.log)
    if bag:
        if args.record:
            raise OptionError("--record names a CARMEN laser record; a bag's laser is its topic")
        if not args.estimate:
            raise OptionError(
                f"{args.log}: a bag's laser scans carry no poses; give --estimate TRAJ (the "
                "robot's poses, e.g. BAG:/odom)"
            )
    elif args.base_frame:
        raise OptionError("--base-frame applies to a ROS bag LOG (BAG:TOPIC) only")
    return bag


def _align_guesses(
    args: argparse.Namespace, scans: LaserScans, bag: bool
) -> tuple[LaserScans, NDArray[np.float64], str]:
    """The scans (a bag's: those with a pose), the laser pose of each, which gives the
    alignments their initial guesses, and where the poses came from (for the summary): the
    bag's estimate, ``--estimate``, or the log's own laser poses."""
    import numpy as np

    from relation_metric.errors import OptionError
    from slamrel.scans.report import estimate_at_scans, within_span

    if bag:
        scans, poses, source = _bag_guesses(args, scans)
        summary = f"{scans.frame_id or 'laser'} poses from {source}"
    elif args.estimate:
        from slamrel.evaluation import load_trajectory

        est = load_trajectory(
            args.estimate,
            args.estimate_format,
            role="estimate",
            skip_invalid=args.skip_invalid_poses,
        ).trajectory
        _refuse_disjoint(
            args.estimate, scans, est.timestamps, within_span(scans.timestamps, est.timestamps)
        )
        poses, corrected = estimate_at_scans(scans, est.timestamps, est.poses)
        summary = f"guesses from {args.estimate}; {corrected} scan pose(s) odometry-corrected"
    else:
        summary = "guesses from the log's laser poses; 0 scan pose(s) odometry-corrected"
        poses = scans.laser_pose
    if not np.isfinite(poses).all():
        raise OptionError(
            f"{args.log} has scans without poses ({scans.record}); give --estimate TRAJ"
        )
    return scans, poses, summary


def _refuse_disjoint(
    estimate: str, scans: LaserScans, times: NDArray[np.float64], inside: NDArray[np.bool_]
) -> None:
    """Refuse an estimate (its pose ``times``) whose time span holds none of the scans
    (``inside``: which it holds): its poses would guess nothing, and any guess would be the
    log's own motion presented as the estimate's."""
    if inside.any():
        return
    from relation_metric.errors import InputError

    first, last = (float(times[0]), float(times[-1])) if times.size else (float("nan"),) * 2
    raise InputError(
        f"no scan lies within the estimate's time span ({first:.3f} … {last:.3f} s; the "
        f"scans: {scans.timestamps.min():.3f} … {scans.timestamps.max():.3f} s)",
        path=estimate,
    )


def _align_pairs(
    args: argparse.Namespace, scans: LaserScans, poses: NDArray[np.float64]
) -> tuple[Proposals, int]:
    """The pairs of scans to align: those of ``--at``'s relations, or consecutive keyframes
    (and, with ``--loops``, loop pairs, less those whose scans cannot overlap by
    ``--loop-min-overlap``); and how many loop pairs that left out."""
    from slamrel.formats.relations import read_relations
    from slamrel.scans.proposals import (
        LOOP_GROWTH_ANGLE,
        consecutive_pairs,
        drop_unseen_loops,
        loop_pairs,
        pairs_at_times,
    )

    if args.at:  # the given pairs, every one: never tested for overlap
        given = read_relations(args.at)
        at = pairs_at_times(
            scans.timestamps,
            given.first,
            given.second,
            tolerance=args.time_tolerance,
            path=args.at,
        )
        return at, 0
    prop = consecutive_pairs(
        poses,
        scans.timestamps,
        distance=args.distance,
        angle=args.angle,
        spacing=args.keyframes,
    )
    if args.loops:
        prop = prop + loop_pairs(
            poses,
            scans.timestamps,
            radius=args.loop_radius,
            min_travel=args.loop_min_travel,
            distance=args.distance,
            angle=args.angle,
            max_angle=math.radians(args.loop_max_angle),
            spacing=args.keyframes,
            growth=args.loop_growth,
            growth_angle=LOOP_GROWTH_ANGLE * args.loop_growth,
        )
        return drop_unseen_loops(
            prop,
            scans,
            poses,
            min_overlap=args.loop_min_overlap,
            growth=args.loop_growth,
            growth_angle=LOOP_GROWTH_ANGLE * args.loop_growth,
            # kept by their aligned motion (run_align): the truth lies within the radius
            radius=args.loop_radius if args.loop_growth > 0 else None,
            max_range=args.max_range,
        )
    return prop, 0


def _align_options(args: argparse.Namespace) -> AlignOptions:
    """The alignment's options (correlative search, readings, quality limits) from the
    command line."""
    from slamrel.scans.correlative import CorrelativeOptions
    from slamrel.scans.relations import AlignOptions, QualityLimits

    return AlignOptions(
        correlative=CorrelativeOptions(search_xy=args.search_xy, search_theta=args.search_theta),
        global_search=args.global_search,
        max_range=args.max_range,
        limits=QualityLimits(
            max_correction=args.max_correction, max_correction_angle=args.max_correction_angle
        ),
    )


def _write_align_extras(
    args: argparse.Namespace,
    scans: LaserScans,
    result: ScanRelations,
    poses: NDArray[np.float64],
    options: AlignOptions,
    bag: bool,
) -> None:
    """The outputs asked for besides the relations: ``--report`` and ``--review``."""
    from slamrel.formats.bags import split_bag_spec
    from slamrel.scans.report import format_report

    if args.report:
        from slamrel.outputs import write_text_atomic

        write_text_atomic(args.report, format_report(result))
    if args.review:
        from pathlib import Path

        from slamrel.review.scans import write_scan_review

        spec = split_bag_spec(args.log) if bag else None
        name = Path(args.log).name if spec is None else f"{Path(spec.path).name}:{spec.topic}"
        second = None  # the search's second hypotheses, where the global aligner found any
        if result.second is not None and result.second_ratio is not None:
            import numpy as np

            second = np.column_stack([result.second, result.second_ratio])
        write_scan_review(args.review, scans, result, poses, options, name=name, second=second)


def _bag_guesses(
    args: argparse.Namespace, scans: LaserScans
) -> tuple[LaserScans, NDArray[np.float64], str]:
    """A bag's scans with a pose (the others left out, counted), their laser poses from the
    estimate and the laser offset, and what the poses came from (for the summary)."""
    import warnings

    import numpy as np

    from slamrel.evaluation import load_trajectory
    from slamrel.formats.bags import bag_topic_frames, split_bag_spec
    from slamrel.formats.laser import BagScanWarning, bag_laser_offset
    from slamrel.scans.report import GUESS_GAP, interpolation_gaps, laser_poses_at_stamps

    est = load_trajectory(
        args.estimate,
        args.estimate_format,
        role="estimate",
        planar=True,
        skip_invalid=args.skip_invalid_poses,
    ).trajectory
    base = args.base_frame
    given = split_bag_spec(args.estimate)
    if base is None and given is not None:
        base = bag_topic_frames(given)[1] or None
    spec = split_bag_spec(args.log)
    assert spec is not None  # read_laser_scans refuses a bag without a topic
    laser = scans.frame_id
    offset: Any = None
    if base is None:
        why = f"{args.estimate} does not say which frame its poses are of"
    elif not laser:
        why = f"{args.log}: the scans have no frame_id"
    else:
        offset, text = bag_laser_offset(spec.path, base, laser)
        why = f"no static transform {base}->{laser} in {spec.path} ({text})"
    if offset is None:
        warnings.warn(
            f"{why}: the laser offset is taken as zero (the estimate's poses are the laser's); "
            "state the robot's frame with --base-frame",
            BagScanWarning,
            stacklevel=2,
        )
        offset, text = np.zeros(3), "laser offset zero"
    poses, inside = laser_poses_at_stamps(scans.timestamps, est, offset)
    _refuse_disjoint(args.estimate, scans, est.timestamps, inside)
    first, last = est.span()
    if not inside.all():
        out = int(np.count_nonzero(~inside))
        warnings.warn(
            f"{args.log}: {out} of {len(scans)} scans lie outside the time span of "
            f"{args.estimate} ({first:.3f} … {last:.3f} s, ± 0.1 s); left out (an estimate is "
            "not extrapolated)",
            BagScanWarning,
            stacklevel=2,
        )
        keep = np.flatnonzero(inside)
        scans, poses = scans.take(keep), poses[keep]
    gaps = interpolation_gaps(est.timestamps, scans.timestamps)
    wide = gaps > GUESS_GAP
    if wide.any():
        warnings.warn(
            f"{args.log}: {int(np.count_nonzero(wide))} of {len(scans)} scans fall in gaps of "
            f"{args.estimate} longer than {GUESS_GAP:g} s (the longest {float(gaps.max()):.3g} s); "
            "their guesses are interpolated across the gap (the alignment and its flags judge "
            "them)",
            BagScanWarning,
            stacklevel=2,
        )
    x, y, th = (float(v) for v in offset)
    source = (
        f"{args.estimate} at the scan stamps; offset [{x:.4g} {y:.4g} {th:.4g}] from {text}"
        if text != "laser offset zero"
        else f"{args.estimate} at the scan stamps; laser offset zero"
    )
    return scans, poses, source
