"""``slamrel recover``: rebuild the trajectory of an EKF-SLAM run from its result bundle."""

from __future__ import annotations

import argparse
import io
import sys
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, NamedTuple

from recovery.constants import MAP_MODES, METHODS
from slamrel.commands import options as opt
from slamrel.commands.common import (
    add_recovery_arguments,
    check_outputs,
    errors_about,
    in_option_words,
)

if TYPE_CHECKING:
    from recovery.anchoring import NeesFrame
    from recovery.bundle import Bundle
    from recovery.results import Recovery
    from relation_metric.consistency import NeesBlowup, NeesSummary
    from slamrel.runs.nees import NeesCurve

# what recover writes: every one read back by evaluate's reader with the same poses and times
WRITABLE_FORMATS = ("plain", "tum", "csv", "carmen")

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
    p.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="TRAJ",
        help="recovered trajectory, in a format evaluate reads back with the same numbers: "
        "*.tum TUM, *.csv t,x,y,theta CSV, *.log/*.clf CARMEN, else plain 't x y theta' "
        "(not *.g2o: VERTEX_SE2 records have no timestamps)",
    )
    p.add_argument(
        "--format",
        choices=WRITABLE_FORMATS,
        help="trajectory format (default: from the extension of -o, else plain); must agree "
        "with an extension that names a format",
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
        "--skip-invalid-measurements",
        action="store_true",
        help="drop (and count) measurements with a range <= 0 or a non-finite range or "
        "bearing instead of refusing the bundle",
    )
    add_recovery_arguments(
        p, fail_help="exit 3 at the first such stretch instead of recovering and reporting it"
    )
    p.add_argument(
        "--robust-threshold",
        type=opt.positive_float,
        default=None,
        metavar="C",
        help="the M-estimator's threshold on the innovation's Mahalanobis distance, in units "
        "of the scale estimated from a plain pass (default: 3.717 = √χ²₂(0.999) redescending, "
        "1.5 huber and cauchy)",
    )
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar, no summary")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from recovery.recover import recover
    from recovery.steps import SNAP_TOLERANCE
    from relation_metric.timeorder import FILTER_TIME_TOLERANCE
    from slamrel.formats.bundle import SKIP_INVALID_OPTION, read_bundle
    from slamrel.formats.results import write_json
    from slamrel.formats.text import write_bytes_atomic
    from slamrel.formats.trajectories import write_trajectory

    fmt = output_format(args.output, args.format)
    check_outputs([args.output, args.covariances, args.report], [args.bundle])
    with in_option_words({SKIP_INVALID_OPTION: "--skip-invalid-measurements"}):
        bundle = read_bundle(
            args.bundle,
            skip_unknown_landmarks=args.skip_unknown_landmarks,
            skip_invalid_measurements=args.skip_invalid_measurements,
        )
    with errors_about(args.bundle):
        result = recover(
            bundle,
            method=args.method,
            gate=args.gate,
            map_mode=args.map_uncertainty,
            max_outlier_run=args.max_outlier_run or None,
            on_divergence="raise" if args.fail_on_divergence else "reenter",
            robust=args.robust,
            robust_threshold=args.robust_threshold,
            map_prior=args.map_prior,
            progress=not args.quiet and sys.stderr.isatty(),
        )
    with errors_about(args.bundle):  # before any output: a NEES it cannot form is an error
        truth = _against_truth(bundle, result)
    write_trajectory(args.output, result.trajectory, format=fmt)
    if args.covariances:
        buf = io.BytesIO()
        np.save(buf, np.asarray(result.covariances), allow_pickle=False)
        write_bytes_atomic(args.covariances, buf.getvalue())
    report = result.report()
    if truth is not None:  # the NEES of slamrel run, in the frame placed by the start pose
        divergence = report["divergence"]
        assert isinstance(divergence, dict)
        divergence["nees_stretches"] = [b.as_dict() for b in truth.blowups]
        after = {k: report.pop(k) for k in ("iterations", "robust", "batch") if k in report}
        report |= truth.as_dict() | after  # the keys in the order they always had
    report["gate"] = args.gate
    # rows put in time order under the filter-log rule (relation_metric.timeorder)
    report["reordered"] = dict(bundle.reordered)
    if bundle.snapped:  # measurement times snapped to a control/odometry time (float noise)
        report["snapped"] = bundle.snapped
    report |= (statements := _statements(bundle))
    report.setdefault("robust", None)
    if args.report:
        write_json(args.report, report)
    if not args.quiet:
        c = result.counts
        print(
            f"{args.method}: {len(result.trajectory)} poses -> {args.output}; measurements "
            f"{c.measurements}: used {c.used}, gated {c.gated} "
            f"({100 * c.gated_fraction:.1f}% of associated), unassociated "
            f"{c.unassociated}, outside the log {c.outside}, unknown landmark "
            f"{c.skipped_unknown}; map uncertainty: {result.map_mode}"
        )
        print(f"map prior: {result.map_prior} ({result.map_prior_reason})")
        dead = c.dead_reckoning()
        if dead is not None:
            print(f"note: {dead}")
        if statements:
            print("read and stated: " + "; ".join(f"{k} {v}" for k, v in statements.items()))
        moved = {name: n for name, n in bundle.reordered.items() if n}
        if moved:
            print(
                "put in time order (steps back of at most "
                f"{FILTER_TIME_TOLERANCE:g} s): "
                + ", ".join(f"{n} row(s) of {name}" for name, n in moved.items())
            )
        if bundle.snapped:
            print(
                f"snapped to a control/odometry time (within {SNAP_TOLERANCE:g} s): "
                f"{bundle.snapped} measurement time(s)"
            )
        if args.robust != "none":
            print(
                f"robust ({args.robust}): {c.downweighted} measurements down-weighted "
                f"({100 * c.downweighted_fraction:.1f}% of associated; weight lost "
                f"{100 * c.downweight_loss:.1f}%)"
            )
        print(divergence_summary_text(result, () if truth is None else truth.blowups))
        if c.gated_fraction > 0.05:
            print(
                "note: a large gated fraction is a finding about the map (wrong associations "
                "or an inconsistent map), not noise"
            )
        if truth is not None:
            _print_truth(truth)
    return 0


def _print_truth(truth: _TruthScores) -> None:
    """The summary's lines on the NEES against the bundle's ground truth."""
    if truth.curve is None:
        print(
            "note: no NEES: no recovered pose after the first lies at a ground-truth time "
            "(within 1 µs; is groundtruth.csv in the time base of the log?)"
        )
        return
    frame, mean = truth.frame, truth.curve.summary.mean
    print(f"mean pose NEES vs ground truth: {mean:.3f} (3 dof), {frame.description}")
    if frame.aligned and truth.unaligned is not None:
        print(f"  unaligned, in the truth frame: {truth.unaligned.mean:.3f}")


class _TruthScores(NamedTuple):
    """The recovered trajectory against the bundle's ground truth (``recover --report``)."""

    frame: NeesFrame
    curve: NeesCurve | None  # None: no recovered pose after the prior at a ground-truth time
    unaligned: NeesSummary | None
    blowups: list[NeesBlowup]

    def as_dict(self) -> dict[str, object]:
        """``nees`` (as ``metrics.json`` ``nees.recovered``), ``nees_frame`` and
        ``nees_truth_frame`` (``None`` where there is no NEES)."""
        return {
            "nees": None if self.curve is None else self.curve.summary.as_dict(),
            "nees_frame": self.frame.as_dict(),
            "nees_truth_frame": None if self.unaligned is None else self.unaligned.as_dict(),
        }


def _against_truth(bundle: Bundle, result: Recovery) -> _TruthScores | None:
    """The NEES of the recovery as ``slamrel run`` computes it (:mod:`slamrel.runs.nees`), in
    the frame placed by the start pose with the landmark fit by id reported beside it; ``None``
    without ground truth."""
    from slamrel.runs.nees import blowups, frame_by_id, recovery_nees

    if bundle.groundtruth is None:
        return None
    frame = frame_by_id(bundle)
    got = recovery_nees(bundle, result, frame)
    if got is None:
        return _TruthScores(frame, None, None, [])
    curve, unaligned = got
    return _TruthScores(frame, curve, unaligned, blowups(curve, result.divergence.max_outlier_run))


def output_format(path: str, fmt: str | None) -> str:
    """The trajectory format ``recover -o PATH [--format FMT]`` writes.

    The extension decides how every reader reads the file back
    (:data:`~slamrel.formats.trajectories.TRAJECTORY_EXTENSIONS`): ``--format`` must agree with
    an extension that names a format, and an extension whose format cannot hold a recovered
    trajectory (``.g2o``: no timestamps; ``.relations``) is refused. Either mistake is an
    :class:`~relation_metric.errors.OptionError` (exit 2), before any work.
    """
    from pathlib import Path

    from relation_metric.errors import OptionError
    from slamrel.formats.trajectories import RELATIONS_EXTENSIONS, TRAJECTORY_EXTENSIONS

    ext = Path(path).suffix.lower()
    named = TRAJECTORY_EXTENSIONS.get(ext)
    if ext in RELATIONS_EXTENSIONS:
        raise OptionError(
            f"a {ext} file holds relations between poses, not a trajectory; write *.txt, "
            "*.tum, *.csv or *.log",
            option="-o/--output",
        )
    if named is not None and named not in WRITABLE_FORMATS:
        raise OptionError(
            f"a {ext} file is read as {named} records, which have no timestamps (evaluate "
            "would take the pose index for the time); write *.txt, *.tum, *.csv or *.log",
            option="-o/--output",
        )
    if fmt is not None and named is not None and fmt != named:
        raise OptionError(
            f"--format {fmt} does not go with a {ext} file (read back as {named}); drop "
            f"--format or give the file another extension",
            option="-o/--output",
        )
    return fmt or named or "plain"


def divergence_summary_text(
    result: Recovery, nees_blowups: Sequence[NeesBlowup] = (), *, limit: int = 5
) -> str:
    """Console lines about the stretches where the map and the log disagree, and the NEES
    blow-ups against ground truth (no numpy reprs)."""
    from relation_metric.consistency import OUTLIER_PROBABILITY

    d = result.divergence
    nis = result.nis_stats
    nis_txt = (
        f"NIS mean {nis.mean:.3g} (2 expected), median {nis.median:.3g}, "
        f"{100 * (nis.fraction_beyond_95 or 0.0):.1f}% beyond the 95% bound"
        if nis.mean is not None and nis.median is not None
        else "no measurement reached the filter"
    )
    st = d.stretches
    ns = nees_blowups
    nees_txt = (
        f"\nNEES vs ground truth blows up (beyond its {100 * OUTLIER_PROBABILITY:g}% bound) "
        f"{len(ns)} time(s), the first over [{ns[0].t0:.3f}, {ns[0].t1:.3f}] s"
        if ns
        else ""
    )
    if not st:
        return f"map and log agree: no stretch of outlying innovations; {nis_txt}{nees_txt}"
    lines = [
        f"map and log DISAGREE on {len(st)} stretch(es), "
        f"{100 * d.fraction_of_log:.1f}% of the log "
        f"({100 * d.fraction_of_measurements:.1f}% of the measurements); "
        f"filter re-entered {d.event_count} time(s); {nis_txt}"
    ]
    for s in st[:limit]:
        lines.append(
            f"  [{s.t0:.3f}, {s.t1:.3f}] s: {s.outlying} of "
            f"{s.measurements} measurements outlying, median NIS "
            f"{s.nis_median:.3g}"
        )
    if len(st) > limit:
        lines.append(f"  ... {len(st) - limit} more in the --report JSON")
    if nees_txt:
        lines.append(nees_txt.strip())
    lines.append(
        "note: divergence is a finding about the map (or the models), not an error; the score "
        "of this trajectory includes these stretches (--fail-on-divergence to stop instead)"
    )
    return "\n".join(lines)


def _statements(bundle: Any) -> dict[str, object]:
    """What the reader counted and the bundle states beyond the defaults, for the report
    (docs/bundle.md): wrapped bearings, skipped invalid readings, measurements not used as
    stated (unprocessed, initialising), the time unit, the sensor noise's source."""
    out: dict[str, object] = {}
    if bundle.wrapped_bearings:  # bearings outside [-pi, pi) wrapped by the reader
        out["wrapped_bearings"] = bundle.wrapped_bearings
    if bundle.skipped_invalid:  # range <= 0 or non-finite, dropped by the reader
        out["skipped_invalid"] = bundle.skipped_invalid
    if bundle.measurement_unprocessed is not None and bundle.measurement_unprocessed.any():
        out["unprocessed"] = int(bundle.measurement_unprocessed.sum())
    if bundle.initialisation != "updates":
        out["initialising"] = int(bundle.initialising().sum())
    if bundle.time != "seconds":
        out["time"] = bundle.time
    if bundle.sensor.noise != "assumed":
        out["sensor_noise"] = bundle.sensor.noise
    return out
