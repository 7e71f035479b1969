"""``slamrel nees``: the NEES over time of any filter's poses with covariances.

ESTIMATE holds the filter's poses and covariances (``tum-cov``, ``openvins``, ``se2-cov``
files or a ``PoseWithCovarianceStamped``/``Odometry`` bag topic:
:mod:`slamrel.formats.covariances`); REFERENCE the true trajectory (any trajectory slamrel
reads). Each estimate pose is matched to the reference pose nearest in time (within
``--max-time-diff``; unmatched ones are counted and left out); no alignment: the filter and
the truth must share a frame. The NEES is :func:`relation_metric.consistency.nees_over_time`.
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, Any

from relation_metric.constants import ERROR_FRAMES
from slamrel.commands import options as opt
from slamrel.constants import COVARIANCE_LAYOUTS, TRAJECTORY_FORMATS

if TYPE_CHECKING:  # the library is imported in run(): start-up stays light
    import numpy as np
    from numpy.typing import NDArray

    from relation_metric.consistency import NeesOverTime

HELP = "NEES over time of a filter's poses with covariances, against the truth"
DEFAULT_MAX_TIME_DIFF = 0.01
DEFAULT_PROBABILITY = 0.95


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = sub.add_parser(
        "nees",
        help=HELP,
        description=HELP
        + ". ESTIMATE: 'tum-cov' (TUM + the 21-value upper triangle of the 6x6 covariance over "
        "x y z rx ry rz), 'openvins' (ov_eval's 20 columns: TUM + orientation and position "
        "triangles), 'se2-cov' (t x y theta + xx xy xtheta yy ytheta thetatheta) or a bag topic "
        "BAG:TOPIC of PoseWithCovarianceStamped/Odometry. Prints the NEES statistics, the χ² "
        "band of one value and the fraction inside it, the mean and its interval (effective "
        "sample size). See docs/nees.md.",
    )
    p.add_argument("reference", metavar="REFERENCE", help="the true trajectory")
    p.add_argument("estimate", metavar="ESTIMATE", help="the filter's poses with covariances")
    p.add_argument(
        "--layout",
        choices=COVARIANCE_LAYOUTS,
        help="layout of ESTIMATE (default: bag for BAG:TOPIC, else told by its column count)",
    )
    p.add_argument("--reference-format", choices=TRAJECTORY_FORMATS, help="format of REFERENCE")
    p.add_argument(
        "--error-frame",
        choices=ERROR_FRAMES,
        help="the error the covariance is of: parent (p − p̂ and Log(R R̂ᵀ), fixed axes: ROS's "
        "PoseWithCovariance), body (R̂ᵀ(p − p̂) and Log(R̂ᵀ R)), openvins (p − p̂ and "
        "Log(R̂ᵀ R), ov_eval's) (default: openvins for the openvins layout, else parent)",
    )
    p.add_argument(
        "--max-time-diff",
        type=opt.nonnegative_float,
        default=DEFAULT_MAX_TIME_DIFF,
        metavar="S",
        help="nearest-pose tolerance between estimate and reference [s] (default %(default)s)",
    )
    p.add_argument(
        "--probability",
        type=_probability,
        default=DEFAULT_PROBABILITY,
        metavar="P",
        help="probability of the two-sided χ² bands (default %(default)s)",
    )
    p.add_argument("--json", metavar="FILE", help="write the statistics as JSON")
    p.add_argument(
        "--csv", metavar="FILE", help="write t, nees, position and orientation NEES per pose"
    )
    p.add_argument(
        "--plot",
        type=opt.figure_file,
        metavar="FILE",
        help="write the NEES over time with its band (.png/.svg/.pdf)",
    )
    p.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")
    p.set_defaults(func=run)


def _probability(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not 0 < v < 1:
        raise argparse.ArgumentTypeError(f"expected 0 < P < 1, got {text}")
    return v


def run(args: argparse.Namespace) -> int:
    """``slamrel nees REFERENCE ESTIMATE``."""
    import numpy as np

    from relation_metric.consistency import nees_over_time
    from relation_metric.errors import InputError
    from relation_metric.time_association import nearest_index
    from slamrel.commands.common import check_outputs, input_files
    from slamrel.evaluation import load_trajectory
    from slamrel.formats.covariances import DEFAULT_FRAME, read_pose_covariances

    check_outputs([args.json, args.csv, args.plot], input_files([args.reference, args.estimate]))
    est = read_pose_covariances(args.estimate, args.layout)
    planar = est.poses.shape[1] == 3
    ref = load_trajectory(
        args.reference, args.reference_format, role="reference", planar=planar
    ).trajectory
    ref_poses = ref.lifted().poses if not planar else ref.poses
    k = nearest_index(ref.timestamps, est.timestamps)
    ok = np.abs(ref.timestamps[k] - est.timestamps) <= args.max_time_diff
    matched = int(np.count_nonzero(ok))
    if matched == 0:
        raise InputError(
            f"no estimate pose lies within {args.max_time_diff} s of a reference pose "
            f"(estimate {est.timestamps[0]:.6f}..{est.timestamps[-1]:.6f} s, reference "
            f"{ref.timestamps[0]:.6f}..{ref.timestamps[-1]:.6f} s); expected common times "
            "(raise --max-time-diff?)",
            path=args.estimate,
        )
    frame = args.error_frame or DEFAULT_FRAME[est.layout]
    r = nees_over_time(
        est.timestamps[ok],
        est.poses[ok],
        ref_poses[k[ok]],
        est.covariances[ok],
        frame=frame,
        probability=args.probability,
    )
    unmatched = int(ok.size - matched)
    result = _result(args, r, est.layout, matched, unmatched, est.time_order.out_of_order)
    if args.json:
        from slamrel.formats.results import write_json

        write_json(args.json, result)
    if args.csv:
        from slamrel.formats.text import write_csv_table

        write_csv_table(
            args.csv,
            ["t", "nees", "position", "orientation"],
            [r.times, r.nees, r.position, r.orientation],
        )
    if args.plot:
        from slamrel.plots.relation_errors import save_figure
        from slamrel.plots.run import filter_nees_figure

        save_figure(filter_nees_figure(r), args.plot)
    if not args.quiet:
        print(_text(result))
    return 0


def _result(
    args: argparse.Namespace,
    r: NeesOverTime,
    layout: str,
    matched: int,
    unmatched: int,
    out_of_order: int,
) -> dict[str, Any]:
    """The JSON of ``--json`` (and what is printed)."""

    def stats(v: NDArray[np.float64]) -> dict[str, float]:
        import numpy as np

        return {
            "mean": float(np.mean(v)),
            "median": float(np.median(v)),
            "max": float(np.max(v)),
        }

    return {
        "estimate": args.estimate,
        "reference": args.reference,
        "layout": layout,
        "error_frame": r.frame,
        "dimension": "3-D" if r.dof == 6 else "2-D",
        "matched": matched,
        "unmatched": unmatched,
        "out_of_order": out_of_order,
        "max_time_diff_s": args.max_time_diff,
        "probability": r.probability,
        "nees": {
            **stats(r.nees),
            "dof": r.dof,
            "band": list(r.band),
            "inside": r.inside,
            "n_eff": r.n_eff,
            "mean_band": list(r.mean_band),
            "consistent": r.consistent,
        },
        "position": {
            **stats(r.position),
            "dof": r.position_dof,
            "band": list(r.part_band(r.position_dof)),
        },
        "orientation": {
            **stats(r.orientation),
            "dof": r.orientation_dof,
            "band": list(r.part_band(r.orientation_dof)),
        },
    }


def _text(res: dict[str, Any]) -> str:
    n = res["nees"]
    pct = round(100 * res["probability"], 6)
    verdict = "inside" if n["consistent"] else "OUTSIDE"
    lines = [
        f"NEES of {res['matched']} poses ({res['dimension']}, {res['layout']}, error frame "
        f"{res['error_frame']}); {res['unmatched']} estimate pose(s) without a reference pose "
        f"within {res['max_time_diff_s']} s left out",
        f"  pose ({n['dof']} dof): mean {n['mean']:.6g}, median {n['median']:.6g}, max "
        f"{n['max']:.6g}; {100 * n['inside']:.2f}% inside the {pct:g}% band "
        f"[{n['band'][0]:.6g}, {n['band'][1]:.6g}]",
        f"  mean {n['mean']:.6g} {verdict} its {pct:g}% interval [{n['mean_band'][0]:.6g}, "
        f"{n['mean_band'][1]:.6g}] (effective sample size {n['n_eff']:.1f})",
    ]
    for part in ("position", "orientation"):
        p = res[part]
        lines.append(
            f"  {part} ({p['dof']} dof): mean {p['mean']:.6g}, median {p['median']:.6g}, max "
            f"{p['max']:.6g}; band [{p['band'][0]:.6g}, {p['band'][1]:.6g}]"
        )
    return "\n".join(lines)
