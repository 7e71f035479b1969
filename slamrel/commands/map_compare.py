"""``slamrel map-compare``: score a landmark map against a reference with mesh relations."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

from slamrel.commands import options as opt
from slamrel.commands.common import (
    add_association_arguments,
    association_choice,
    association_file,
    check_outputs,
    errors_about,
    in_option_words,
    stats_table,
)

if TYPE_CHECKING:
    from landmark_graph.map_compare import MapComparison
    from landmark_graph.maps import LandmarkMap


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "map-compare",
        help="compare an estimated landmark map with a reference (Delaunay-mesh relations)",
    )
    p.add_argument("estimate", metavar="ESTIMATE_MAP", help="estimated landmark map (CSV)")
    p.add_argument("reference", metavar="REFERENCE_MAP", help="reference landmark map (CSV)")
    add_association_arguments(p)
    p.add_argument(
        "--cutoff",
        type=opt.length,
        default=1.0,
        help="OSPA/GOSPA cut-off c [m]: a landmark farther than c from its match counts as "
        "missed, and the automatic association pairs no landmarks farther apart "
        "(default: %(default)s)",
    )
    p.add_argument(
        "--order",
        type=opt.float_at_least(1.0),
        default=2.0,
        help="OSPA/GOSPA order p ≥ 1: the "
        "p-norm that averages the per-landmark distances (default: %(default)s)",
    )
    p.add_argument(
        "--thin-angle",
        type=opt.triangle_angle,
        default=5.0,
        metavar="DEG",
        help="flag triangles whose smallest angle is below DEG degrees (default: 5)",
    )
    p.add_argument(
        "--seed",
        type=opt.seed,
        default=0,
        help="seed of the automatic association (default: %(default)s)",
    )
    p.add_argument(
        "--trajectory",
        metavar="TRAJ",
        help="the poses the sensor was at (a trajectory file, or a SLAM result bundle "
        "directory: its groundtruth.csv and its sensor's reach): reference landmarks never "
        "within the sensor's reach of any of them are unobserved, not missed",
    )
    p.add_argument(
        "--max-range",
        type=opt.length,
        metavar="R",
        help="the sensor's reach [m] for --trajectory (default with a bundle: its "
        "sensor_model.max_range, else its largest measured range; required with a file)",
    )
    p.add_argument(
        "--fov",
        type=opt.positive_float,
        metavar="DEG",
        help="the sensor's full field of view [deg] for --trajectory, centred on the heading "
        "(default: a bundle's sensor_model.fov, else all around)",
    )
    p.add_argument("--json", metavar="F", help="write the results as JSON")
    p.add_argument(
        "--per-edge", metavar="F.csv", help="write the per-edge (mesh relation) errors as CSV"
    )
    p.add_argument(
        "--plot",
        type=opt.figure_file,
        metavar="F.png",
        help="write a figure (.png/.svg/.pdf); --review F.html writes an interactive page to "
        "check and correct the association",
    )
    p.add_argument(
        "--review",
        metavar="F.html",
        help="write the association review page (see 'slamrel review'): accept, reject or draw "
        "pairs in a browser, save the CSV, pass it back with --associate F.csv",
    )
    p.add_argument(
        "--write-association",
        metavar="F.csv",
        help="write the association used as 'estimate,reference' id pairs (edit it and pass "
        "it back with --associate F.csv to override the automatic result)",
    )
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from landmark_graph.map_compare import compare_maps
    from slamrel.formats.associations import write_association_csv
    from slamrel.formats.landmark_maps import read_map
    from slamrel.formats.text import write_text_atomic

    check_outputs(
        [args.json, args.per_edge, args.plot, args.write_association, args.review],
        [args.estimate, args.reference, association_file(args.associate)],
    )
    est = read_map(args.estimate)
    ref = read_map(args.reference)
    observable, reach = _reach(args, ref)
    assoc = association_choice(args.associate, est, ref)
    words = {
        'associate="auto"': "--associate auto",
        "an association of your own": "an association file",
        "on a review page": "on the page of --review (or slamrel review)",
        "as the association": "with --associate FILE",
    }
    with errors_about(args.estimate), in_option_words(words):
        res = compare_maps(
            est,
            ref,
            associate=assoc,
            cutoff=args.cutoff,
            order=args.order,
            seed=args.seed,
            thin_angle=np.deg2rad(args.thin_angle),
            align=args.align,
            allow_empty=True,  # no pair found: the page and the outputs, with 0 pairs said
            observable=observable,
            reach=reach,
        )
    out = res.as_dict()
    if args.json:
        write_text_atomic(args.json, json.dumps(out, indent=2, allow_nan=False) + "\n")
    if args.per_edge:
        _write_per_edge(args.per_edge, res, ref)
    if args.write_association:
        write_association_csv(args.write_association, res.association, est, ref)
    if args.plot:
        from slamrel.plots.maps import map_figure
        from slamrel.plots.relation_errors import save_figure

        save_figure(map_figure(res), Path(args.plot))
    if args.review:
        from slamrel.review.page import write_review

        names = (Path(args.estimate).name, Path(args.reference).name)
        write_review(
            args.review, est, ref, res.association, cutoff=args.cutoff, names=names,
            title=f"slamrel review — {names[0]} against {names[1]}",
        )  # fmt: skip
    if not args.quiet:
        _print_summary(args, res, out)
    return 0


def _reach(args: argparse.Namespace, ref: LandmarkMap) -> tuple[Any, Any]:
    """Which reference landmarks were ever within the sensor's reach of ``--trajectory``
    (``(None, None)`` without it): ``(observable (L,), SensorReach)``."""
    import math

    from relation_metric.errors import OptionError

    if args.trajectory is None:
        for name in ("max_range", "fov"):
            if getattr(args, name) is not None:
                raise OptionError(
                    "the reach needs the poses it is measured from; give --trajectory too",
                    option="--" + name.replace("_", "-"),
                )
        return None, None
    from landmark_graph.observability import SensorReach, within_reach

    if args.fov is not None and args.fov > 360.0:
        raise OptionError(f"expected a field of view in (0, 360], got {args.fov:g}", option="--fov")
    fov = None if args.fov is None else math.radians(args.fov)
    if Path(args.trajectory).is_dir():
        from slamrel.formats.bundle import read_bundle
        from slamrel.pipeline import sensor_reach

        b = read_bundle(args.trajectory, skip_invalid_measurements=True)
        if b.groundtruth is None:
            raise OptionError(
                f"the bundle {args.trajectory} has no groundtruth.csv to measure the reach "
                "from; give a trajectory file",
                option="--trajectory",
            )
        own = sensor_reach(b)
        if args.max_range is None and own is None:
            raise OptionError("the bundle states no reach; give --max-range", option="--trajectory")
        if args.max_range is not None:
            reach = SensorReach(args.max_range, fov, "declared")
        else:
            assert own is not None
            reach = SensorReach(own.max_range, fov if fov is not None else own.fov, own.source)
        poses = b.groundtruth.poses
    else:
        if args.max_range is None:
            raise OptionError(
                "a trajectory file states no sensor; give --max-range", option="--trajectory"
            )
        from slamrel.formats.trajectories import read_trajectory

        poses = read_trajectory(args.trajectory).trajectory.poses
        reach = SensorReach(args.max_range, fov, "declared")
    return within_reach(poses, ref.xy, reach), reach


def _write_per_edge(path: str, res: MapComparison, ref: LandmarkMap) -> None:
    """One CSV row per mesh edge: the two reference ids and the edge's three errors."""
    import numpy as np

    from slamrel.formats.text import NUMBER_FORMAT, write_text_atomic

    ids = ref.ids[res.association.reference_rows]
    e = res.mesh.edges
    rows = np.column_stack(
        (
            ids[e[:, 0]],
            ids[e[:, 1]],
            res.errors.edge_length,
            res.errors.edge_displacement_triangle,
            res.errors.edge_displacement_aligned,
        )
    )
    text = "landmark_i,landmark_j,length_error,displacement_triangle_frame,displacement_aligned\n"
    line = "%d,%d" + f",{NUMBER_FORMAT}" * 3 + "\n"
    text += line * rows.shape[0] % tuple(rows.ravel().tolist())
    write_text_atomic(path, text)


def _print_summary(args: argparse.Namespace, res: MapComparison, out: dict[str, Any]) -> None:
    """The association counts, the error table, mesh notes and OSPA/GOSPA on stdout."""
    import numpy as np

    from landmark_graph.map_compare import SOURCE_WORDS

    a = out["association"]
    print(
        f"matched {a['matched']}, missed {a['missed']}, spurious {a['spurious']}"
        + (f", unobserved {a['unobserved']}" if a["unobserved"] else "")
        + f" (associated {SOURCE_WORDS[res.association_source]}); "
        f"mesh {out['mesh']['edges']} edges, {out['mesh']['triangles']} triangles"
    )
    from relation_metric.evaluate import error_summaries

    table = [
        ("edge length abs [m]", error_summaries(res.errors.edge_length).abs),
        ("corner angle abs [rad]", error_summaries(res.errors.corner_angle.ravel()).abs),
        (
            "  excluding thin triangles",
            error_summaries(res.errors.corner_angle[~res.mesh.thin].ravel()).abs,
        ),
    ]
    print(stats_table(table))
    m = out["mesh"]
    if m["thin_triangles"] or m["duplicates"] or m["collinear"]:
        print(
            f"mesh: {m['thin_triangles']} thin triangles (< {args.thin_angle:g} deg), "
            f"{m['duplicates']} duplicate reference positions {m['duplicate_ids']}, "
            f"collinear: {m['collinear']}"
        )
    for note in res.choice.notes:  # the cautions are warnings (stderr)
        print(f"note: {note}")
    al = res.alignment
    print(
        f"alignment (reference = R(dθ) estimate + d): dx {al.dx:.4f} m, dy {al.dy:.4f} m, "
        f"dθ {np.degrees(al.dtheta):.4f}°, {al.pairs} pairs ({res.association_source}), "
        f"rms residual {al.rms_residual:.4f} m" + ("" if al.applied else "; not applied")
    )
    print(
        f"OSPA {res.ospa:.4f} m, GOSPA {res.gospa:.4f} m "
        f"(c = {res.cutoff}, p = {res.order}; {res.frame})"
    )
    if args.review:
        print(f"review the association: {args.review} (open it in a browser)")
    elif args.plot:
        print("to check and correct the association in a browser: --review F.html")
