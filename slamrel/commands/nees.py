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
    p.add_argument(
        "estimates",
        nargs="+",
        metavar="ESTIMATE",
        help="the filter's poses with covariances; several: Monte Carlo runs against one truth, "
        "their NEES averaged at the times every run has (the band then for R runs)",
    )
    p.add_argument(
        "--layout",
        choices=COVARIANCE_LAYOUTS,
        help="layout of ESTIMATE (default: bag for BAG:TOPIC, else told by its column count)",
    )
    p.add_argument(
        "--reference-format",
        choices=TRAJECTORY_FORMATS,
        help="format of REFERENCE (default: recognised)",
    )
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
    """``slamrel nees REFERENCE ESTIMATE...``."""
    import numpy as np

    from relation_metric.consistency import nees_over_time
    from relation_metric.errors import InputError
    from slamrel.commands.common import check_outputs, input_files
    from slamrel.evaluation import load_trajectory
    from slamrel.formats.covariances import DEFAULT_FRAME, read_pose_covariances

    check_outputs([args.json, args.csv, args.plot], input_files([args.reference, *args.estimates]))
    runs = [read_pose_covariances(path, args.layout) for path in args.estimates]
    layouts = {e.layout for e in runs}
    widths = {e.poses.shape[1] for e in runs}
    if len(layouts) > 1 or len(widths) > 1:
        raise InputError(
            f"the runs differ in layout ({', '.join(sorted(layouts))}); expected runs of one "
            "filter in one layout",
            path=args.estimates[0],
        )
    planar = widths == {3}
    ref = load_trajectory(
        args.reference, args.reference_format, role="reference", planar=planar
    ).trajectory
    ref_poses = ref.poses if planar else ref.lifted().poses
    times, rows, truth, used = _common_times(
        ref.timestamps, [e.timestamps for e in runs], args.max_time_diff
    )
    if times.size == 0:
        e = runs[0]
        raise InputError(
            f"no estimate time lies within {args.max_time_diff} s of a reference pose"
            + (" in every run" if len(runs) > 1 else "")
            + f" (estimate {e.timestamps[0]:.6f}..{e.timestamps[-1]:.6f} s, reference "
            f"{ref.timestamps[0]:.6f}..{ref.timestamps[-1]:.6f} s); expected common times "
            "(raise --max-time-diff?)",
            path=args.estimates[0],
        )
    frame = args.error_frame or DEFAULT_FRAME[runs[0].layout]
    r = nees_over_time(
        times,
        np.stack([e.poses[i] for e, i in zip(runs, rows)]),
        np.stack([ref_poses[j] for j in truth]),
        np.stack([e.covariances[i] for e, i in zip(runs, rows)]),
        frame=frame,
        probability=args.probability,
    )
    left_out = [int(e.timestamps.size - u) for e, u in zip(runs, used)]
    result = _result(args, r, runs[0].layout, left_out, [e.time_order.out_of_order for e in runs])
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


def _common_times(
    reference: NDArray[np.float64], runs: list[NDArray[np.float64]], tol: float
) -> tuple[NDArray[np.float64], list[NDArray[np.intp]], list[NDArray[np.intp]], list[int]]:
    """The times every run has a pose at, each within ``tol`` of a reference pose.

    The times are the first run's estimate times with a reference pose within ``tol``; a
    later run takes its pose nearest each (within ``tol``), and a time some run lacks is left
    out. Returns the times (N,), per run the row of each time in the run and the reference
    row nearest that row's own time, and per run the number of its rows used.
    """
    import numpy as np

    from relation_metric.time_association import nearest_index

    def near(
        base: NDArray[np.float64], t: NDArray[np.float64]
    ) -> tuple[NDArray[np.intp], NDArray[np.bool_]]:
        k = nearest_index(base, t)
        return k, np.abs(base[k] - t) <= tol

    _, keep = near(reference, runs[0])
    rows = []
    for t in runs:
        i, close = near(t, runs[0])  # the run's pose nearest each time of run 0
        _, has_ref = near(reference, t[i])
        keep &= close & has_ref
        rows.append(i)
    rows = [i[keep] for i in rows]
    truth = [nearest_index(reference, t[i]) for t, i in zip(runs, rows)]
    return runs[0][keep], rows, truth, [int(np.unique(i).size) for i in rows]


def _result(
    args: argparse.Namespace,
    r: NeesOverTime,
    layout: str,
    left_out: list[int],
    out_of_order: list[int],
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
        "estimates": list(args.estimates),
        "reference": args.reference,
        "layout": layout,
        "error_frame": r.frame,
        "dimension": "3-D" if r.dof == 6 else "2-D",
        "runs": r.runs,
        "matched": int(r.times.size),
        "left_out": left_out,
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
    runs = f" × {res['runs']} runs (averaged at each time)" if res["runs"] > 1 else ""
    left = ", ".join(str(v) for v in res["left_out"])
    lines = [
        f"NEES of {res['matched']} poses{runs} ({res['dimension']}, {res['layout']}, error "
        f"frame {res['error_frame']}); left out (no reference pose within "
        f"{res['max_time_diff_s']} s{', or a time another run lacks' if runs else ''}): {left}",
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
