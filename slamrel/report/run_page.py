"""The page of ``slamrel run``: its figures and sections, named, built from a ``RunResult``.

:func:`report_figures` draws the four figures (:class:`RunFigures`, one attribute each, the
map figure only with a map comparison); :func:`report_sections` writes the four sections
(:class:`RunSections`). Every number in a table is read from the same structures
``metrics.json`` is written from (:meth:`slamrel.runs.result.RunResult.metrics`), so the page
and the file cannot disagree. :func:`slamrel.pipeline.write_report` writes the folder.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np

from recovery.ekf import DEFAULT_MAX_OUTLIER_RUN
from recovery.results import Divergence, NisStats
from relation_metric.consistency import OUTLIER_PROBABILITY, NeesBlowup
from relation_metric.evaluate import Evaluation, pose_errors
from relation_metric.trajectory import Trajectory
from slamrel.plots.legend_words import hidden_share, legend_words
from slamrel.plots.maps import map_figure
from slamrel.plots.run import (
    TIMELINE_LEGEND,
    SetPanel,
    TimeSpan,
    mark_stretches_time,
    mark_stretches_xy,
    nees_figure,
    relation_sets_figure,
    trajectories_figure,
)
from slamrel.report.html import Figure, Section, Table, figure_png, format_intervals
from slamrel.runs.result import MapSummary, RunResult

__all__ = ["RunFigures", "RunSections", "report_figures", "report_sections"]


class RunFigures(NamedTuple):
    """The figures of the run report, in page (and ``figure_<k>.png``) order (without ground
    truth no ``errors`` nor ``nees``)."""

    trajectories: Figure
    errors: Figure | None
    nees: Figure | None
    map: Figure | None = None

    def in_order(self) -> list[Figure]:
        """The figures present, numbered 1, 2, … in the report folder."""
        return [f for f in self if f is not None]


class RunSections(NamedTuple):
    """The sections of the run report, in page order (``map`` only with a map comparison)."""

    summary: Section
    consistency: Section
    agreement: Section
    map: Section | None = None

    def in_order(self) -> list[Section]:
        return [s for s in self if s is not None]


def report_figures(result: RunResult) -> RunFigures:
    """Draw the report's figures (matplotlib, closed after rendering to PNG).

    One time axis throughout: seconds since the run's start (:attr:`RunResult.time_base`);
    trajectories and the map in the ground truth's frame (:attr:`RunResult.display_frames`,
    said in the captions). Without ground truth the estimates and the map are drawn as
    estimated, in the SLAM map's frame, and there is no figure of the errors against it nor
    of the NEES.
    """
    truth = result.bundle.groundtruth
    stretches = result.agreement.stretches if result.agreement is not None else ()
    frames = result.display_frames
    drawn = {
        k: Trajectory(est.timestamps, frames[k].apply(est.poses))
        for k, est in result.estimates.items()
    }
    lgt = result.bundle.landmarks_groundtruth if truth is not None else None
    map_xy = result.bundle.map_xy
    fig = mark_stretches_xy(
        trajectories_figure(
            truth,
            drawn,
            labels={k: f"{k} ({frames[k].short})" for k in drawn if frames[k].short},
            landmarks=lgt[1] if lgt else None,
            mapped=frames["map"].apply(map_xy) if map_xy.size else None,
        ),
        stretches,
        drawn.get("recovered"),
    )
    trajectories = Figure(_trajectories_caption(result, fig), figure_png(fig))
    return RunFigures(
        trajectories,
        _errors_figure(result, drawn, stretches)
        if result.evaluations or result.reference is not None
        else None,
        _nees_figure(result, stretches) if truth is not None else None,
        _map_figure(result),
    )


def _trajectories_caption(result: RunResult, fig: Any) -> str:
    """Figure 1's caption: each drawn thing named in the words of its legend handle
    (:func:`slamrel.plots.legend_words.legend_words`), and how much of each line lies hidden
    under a line drawn above it (:func:`slamrel.plots.legend_words.hidden_share`)."""
    fig.canvas.draw()  # the final layout: the hidden shares are measured in display pixels
    ax = fig.axes[0]
    words = legend_words(ax)
    lines = {ln.get_label(): ln for ln in ax.get_lines()}
    labels = {k: f"{k} ({f.short})" if f.short else k for k, f in result.display_frames.items()}
    names = [k for k in result.estimates if labels[k] in words]
    est = "; ".join(f"{k} {words[labels[k]]}" for k in names)
    truth = result.bundle.groundtruth is not None
    parts = [
        f"Estimates ({est})"
        + (f" against the ground truth ({words['ground truth']}, beneath them)" if truth else "")
    ]
    for label, what in (("true landmarks", "the true landmarks"), ("SLAM map", "the SLAM map")):
        if label in words:
            parts.append(f"{what} ({words[label]})")
    text = ", ".join(parts[:-1]) + " and " + parts[-1] if len(parts) > 1 else parts[0]
    if truth:
        text += f", in the ground truth's frame: {_frames_text(result)}."
    else:
        text += (
            " as estimated, in the SLAM map's frame: the bundle has no ground truth, so "
            "nothing is aligned and no line is the truth."
        )
    if "map/log disagree" in words:
        text += (
            f" {words['map/log disagree'].capitalize()}: recovered poses where the map and the "
            "log disagree."
        )
    # what lies under what: the reference under each estimate, each estimate under the main
    pairs = [("ground truth", k) for k in names if truth] + [(k, names[0]) for k in names[1:]]
    hidden = [
        f"{under} under {over} "
        f"{100 * hidden_share(lines[labels.get(under, under)], lines[labels[over]]):.0f} %"
        for under, over in pairs
    ]
    if hidden:
        text += (
            " Share of a line's points drawn under another's line width (hidden where the "
            "two agree to within it): " + ", ".join(hidden) + "."
        )
    return text


def _frames_text(result: RunResult) -> str:
    """How each estimate and the map are drawn, estimates sharing a frame named together."""
    by: dict[str, list[str]] = {}
    for name, frame in result.display_frames.items():
        by.setdefault(frame.description, []).append("the SLAM map" if name == "map" else name)
    return "; ".join(f"{' and '.join(names)} {how}" for how, names in by.items())


def _errors_figure(
    result: RunResult, drawn: dict[str, Trajectory], stretches: Sequence[TimeSpan]
) -> Figure:
    """The main estimate's relation errors over time and, one panel per relation set, where
    along the trajectory they are: the sets drawn from the ground truth, or without it the
    reference relations given (``--relations``), one panel."""
    main = result.main_estimate
    tb = result.time_base
    evs: Mapping[str, Evaluation | None]
    if result.evaluations:
        evs = result.evaluations[main]
        sets = result.evaluations[main].sets
        names = [(r.name, r.absent) for r in result.relation_sets] or [(k, "") for k in sets]
    else:
        assert result.reference is not None
        evs = {"reference": result.reference.scores.get(main)}
        names = [("reference", "")]
    est = drawn[main]
    panels = []
    for name, absent in names:
        ev = evs.get(name)
        if ev is None:
            panels.append(SetPanel(name, *_EMPTY, high=0.0, absent=absent or "not generated"))
            continue
        valid = ev.valid
        pe = pose_errors(ev, len(est))
        panels.append(
            SetPanel(
                name,
                tb.since_start(0.5 * (ev.relations.first + ev.relations.second)[valid]),
                ev.errors.translation[valid],
                ev.errors.rotation[valid],
                est.poses[pe.index, :2],
                pe.mean,
                high=pe.quantile(COLOUR_QUANTILE),
                high_label=f"p{100 * COLOUR_QUANTILE:g}",
                unassociated=int((~valid).sum()),
            )
        )
    truth = result.bundle.groundtruth
    fig = relation_sets_figure(
        panels, est.poses[:, :2], reference=None if truth is None else truth.positions,
        span=(0.0, tb.duration),
    )  # fmt: skip
    fig = mark_stretches_time(fig, stretches, t0=tb.t0, axes=(0, 1), legend=TIMELINE_LEGEND)
    where = (
        f"{result.display_frames[main].description}, the ground truth in grey beneath"
        if truth is not None
        else "as estimated (no ground truth)"
    )
    panels_are = "one panel per relation set"
    if not result.evaluations and result.reference is not None:
        panels_are = f"one panel for the reference relations given ({result.reference.source})"
    return Figure(
        f"Where the {main} trajectory is wrong, {panels_are}: each pose a "
        "relation of the set ends at, coloured by the mean translational error of the set's "
        "relations ending there, on the set's own scale from 0 to its 95th percentile "
        f"(stated under each panel; larger errors in the top colour); the estimate {where}. Above: "
        "every scored relation's translational and rotational error at its mid-time, in "
        "seconds since the run's start, by set"
        + ("; shaded: stretches where the map and the log disagree." if stretches else "."),
        figure_png(fig),
    )


#: The top of each relation set's colour scale: this quantile of its per-pose errors.
COLOUR_QUANTILE = 0.95
_EMPTY = (np.empty(0), np.empty(0), np.empty(0), np.empty((0, 2)), np.empty(0))


#: The NEES figure's name of the recovered NEES in the map's frame (the verdict's).
PLACED_CURVE = "recovered, map's frame"


def _nees_figure(result: RunResult, stretches: Sequence[TimeSpan]) -> Figure:
    """NEES of each estimate at its own times (the poses where it exists), over the run."""
    tb = result.time_base
    curves = {k: v for k, v in result.nees.items() if v.times is not None}
    placed = result.nees_placement
    if placed is not None and placed.curve.times is not None:  # the one the verdict judges
        curves[PLACED_CURVE] = placed.curve
    times = {k: tb.since_start(v.times) for k, v in curves.items()}  # type: ignore[arg-type]
    span = (0.0, tb.duration)
    fig = nees_figure(
        times, {k: v.values for k, v in curves.items()},
        {k: v.summary for k, v in curves.items()}, span=span,
    )  # fmt: skip
    fig = mark_stretches_time(fig, stretches, t0=tb.t0)
    lo, hi = fig.axes[0].get_xlim()
    covered = (
        [float(t.min()) for t in times.values() if t.size],
        [float(t.max()) for t in times.values() if t.size],
    )
    data = {"x-min": float(lo), "x-max": float(hi), "run-duration": tb.duration}
    if covered[0]:
        data |= {"data-min": min(covered[0]), "data-max": max(covered[1])}
    where = ", ".join(
        f"{k} at its {t.size} poses where the NEES exists"
        + (f" ({format_intervals([(t.min(), t.max())])[0]})" if t.size else "")
        for k, t in times.items()
    )
    frame = result.nees_frame
    return Figure(
        f"NEES over time with the 95% χ² band (3 dof), in seconds since the run's start "
        f"(the run: {format_intervals([span])[0]}): {where or 'no estimate has a NEES'}"
        + ("" if frame is None else f"; computed in the {frame.description}")
        + ("; shaded: stretches where the map and the log disagree." if stretches else "."),
        figure_png(fig),
        data,
    )


def _anchoring_table(result: RunResult) -> list[Table]:
    """The frame placement (by the start pose) and the map's anchoring error (landmark fit)."""
    frame = result.nees_frame
    if frame is None:
        return []
    rows = []
    if frame.anchoring is not None:
        a = frame.anchoring
        rows.append(["map frame in the truth frame (start pose)", a.dx, a.dy,
                     float(np.degrees(a.dtheta)), "", ""])  # fmt: skip
    m = frame.map_anchoring
    if m is not None:
        rows.append([f"the map's landmarks off the truth ({m.association})", m.dx, m.dy,
                     float(np.degrees(m.dtheta)), m.landmarks, m.rms_residual])  # fmt: skip
    if not rows:
        return []
    return [
        Table(
            "Anchoring (truth ← map): the frame the NEES is computed in, and how far the map "
            "sits off the true landmarks (a map error, not applied)",
            ["what", "dx [m]", "dy [m]", "dθ [deg]", "landmarks", "rms residual [m]"],
            rows,
        )
    ]


def _map_figure(result: RunResult) -> Figure | None:
    if result.map_comparison is None:
        return None
    frame = (result.map or {}).get("ospa", {}).get("frame", "")
    return Figure(
        f"The SLAM map against {_map_reference(result)}: their Delaunay mesh, each edge "
        "coloured by its length error" + (f"; the SLAM map drawn {frame}" if frame else ""),
        figure_png(map_figure(result.map_comparison)),
    )


def report_sections(
    result: RunResult, figures: RunFigures, *, review: tuple[str, str] | None = None
) -> RunSections:
    """The report's sections; ``review``: the ``(href, text)`` link to ``review.html``."""
    tb = result.time_base
    truth = result.has_truth
    summary = Section(
        f"slamrel run: {result.name}",
        paragraphs=[
            *(
                [
                    "Relation metric (Kümmerle et al. 2009): relative motions of each estimate "
                    + (
                        "against ground-truth relations"
                        if truth
                        else "against the reference "
                        "relations given (the bundle has no ground truth)"
                    )
                    + ", ε = 1/N Σ ‖δ_ij ⊖ δ*_ij‖²."
                ]
                if truth or result.reference is not None
                else []
            ),  # fmt: skip
            f"Times on this page are seconds since the run's start (the first time of its "
            f"log, {tb.t0:.3f} s on the log's own clock); the run lasts {tb.duration:.1f} s.",
            *_relation_set_paragraphs(result),
            *result.notes,
        ],
        tables=[
            *_relation_sets_table(result),
            *(
                [_stats_table(result, "translation"), _stats_table(result, "rotation")]
                if truth
                else []
            ),
            *_reference_tables(result),
        ],
        figures=[f for f in (figures.trajectories, figures.errors) if f is not None],
    )
    consistency = _consistency_section(result, figures)
    ms = result.map_summary
    map_section = None
    if ms is not None:
        map_section = _map_section(
            ms,
            [] if figures.map is None else [figures.map],
            [] if review is None else [review],
            reference=_map_reference(result),
            reach=result.bundle.groundtruth is not None,
        )
    return RunSections(summary, consistency, _agreement_section(result), map_section)


def _consistency_section(result: RunResult, figures: RunFigures) -> Section:
    """The NEES of each estimate with covariances (needs ground truth) and its frame."""
    if not result.has_truth:
        return Section(
            "Consistency",
            paragraphs=[
                "No NEES: it compares each estimate with the ground truth, which the bundle "
                "does not have. The map–log agreement below (the innovations' NIS) is the "
                "consistency check that needs no truth."
            ],
        )
    frame = result.nees_frame
    unaligned = result.nees_truth_frame
    paragraphs = [] if frame is None else [f"NEES frame: {frame.description}."]
    rows = [
        [
            k,
            v.summary.mean,
            v.summary.band[0],
            v.summary.band[1],
            v.summary.inside,
            unaligned[k].mean if k in unaligned else None,
        ]
        for k, v in result.nees.items()
    ]
    placed = result.nees_placement
    if placed is not None:
        sp, n = placed.placement.split, placed.curve.summary
        rows.append(["recovered, in the map's frame", n.mean, n.band[0], n.band[1], n.inside, None])
        paragraphs.append(
            "In the map's frame: each recovered pose conditioned on the map's placement — the "
            f"rigid motion of the whole map against the true landmarks ({sp.dx:.3g} m, "
            f"{sp.dy:.3g} m, {np.degrees(sp.dtheta):.3g}°; NEES "
            f"{'—' if sp.nees_rigid is None else f'{sp.nees_rigid:.3g}'} for 3 dof, on "
            f"{placed.placement.landmarks} landmarks), which the poses inherit and "
            "no relation sees. The verdict's recovered consistency judges this NEES (the "
            "table's last row); the row 'recovered' is the absolute one (recovery.placement, "
            "docs/verdict.md)."
        )
    return Section(
        "Consistency",
        paragraphs=paragraphs,
        tables=[
            Table(
                "NEES (3 dof) of the pose estimates",
                [
                    "estimate",
                    "mean",
                    "band low",
                    "band high",
                    "fraction inside",
                    "mean in the truth frame (unaligned)",
                ],
                rows,
            ),
            *_anchoring_table(result),
        ],
        figures=[] if figures.nees is None else [figures.nees],
    )


def _reference_tables(result: RunResult) -> list[Table]:
    """Each estimate on the reference relations given, and, without ground truth, the
    online estimate against the recovered one."""
    tables = []
    ref = result.reference
    if ref is not None:
        rows = [
            [name, int(ev.valid.sum()), int((~ev.valid).sum()), ev.translation.abs.mean,
             ev.translation.abs.std, ev.rotation.abs.mean, ev.rotation.abs.std]
            for name, ev in ref.scores.items()
        ]  # fmt: skip
        tables.append(
            Table(
                f"relation error on the reference relations ({ref.source}, {ref.relations} "
                "relations; scored as slamrel evaluate scores them)",
                [
                    "estimate",
                    "scored",
                    "unassociated",
                    "trans abs mean [m]",
                    "trans abs std [m]",
                    "rot abs mean [rad]",
                    "rot abs std [rad]",
                ],
                rows,
            )  # fmt: skip
        )
    diff = result.online_vs_recovered
    if diff is not None:
        tables.append(
            Table(
                "online against recovered: the online estimate on relations drawn from the "
                "recovered trajectory (their difference, not an error)",
                [
                    "relations",
                    "count",
                    "trans abs mean [m]",
                    "trans abs max [m]",
                    "rot abs mean [rad]",
                    "rot abs max [rad]",
                ],
                [
                    [
                        k,
                        ev.translation.abs.count,
                        ev.translation.abs.mean,
                        ev.translation.abs.max,
                        ev.rotation.abs.mean,
                        ev.rotation.abs.max,
                    ]
                    for k, ev in diff.items()
                ],
            )  # fmt: skip
        )
    return tables


def _relation_set_paragraphs(result: RunResult) -> list[str]:
    """What the relation sets are, and why a set is absent."""
    if not result.relation_sets:
        return []
    absent = [r for r in result.relation_sets if r.absent]
    return [
        "The relations are generated from the ground truth in three sets (the table below): "
        "consecutive relations see local errors, loop and global relations see the breakage "
        "that local ones cannot. A relation is scored when the estimate has a pose within "
        "0.1 s of both of its ends (or can be interpolated over a gap of at most 1 s); the "
        "rest are unassociated and left out of every number.",
        *(f"No {r.name} relations: {r.absent}." for r in absent),
    ]


def _relation_sets_table(result: RunResult) -> list[Table]:
    """Per relation set: the rule, relations generated, scored and unassociated."""
    if not result.relation_sets:
        return []
    main = result.main_estimate
    evs = result.evaluations[main]
    rows = []
    for r in result.relation_sets:
        ev = evs.get(r.name)
        scored = None if ev is None else int(ev.valid.sum())
        unassociated = None if ev is None else int((~ev.valid).sum())
        rows.append([r.name, r.rule, r.generated, scored, unassociated, r.absent or None])
    return [
        Table(
            f"relation sets (from the ground truth; scored for the {main} estimate)",
            ["set", "rule", "generated", "scored", "unassociated", "absent because"],
            rows,
        )
    ]


def _stats_table(result: RunResult, part: str) -> Table:
    """Mean, std, max of the absolute and mean of the squared errors, per estimate and set."""
    rows = []
    for name, evs in result.evaluations.items():
        for set_name, ev in evs.items():
            s = getattr(ev, part).abs
            q = getattr(ev, part).sqr
            rows.append([name, set_name, s.mean, s.std, q.mean, s.max, s.count])
    u = "m" if part == "translation" else "rad"
    return Table(
        f"{part} relation error [{u}]",
        ["estimate", "relations", f"abs mean [{u}]", f"abs std [{u}]", f"sqr mean [{u}²]",
         f"abs max [{u}]", "count"],
        rows,
    )  # fmt: skip


_STRETCH_COLUMNS = [
    "interval (since the run's start)", "duration [s]", "measurements", "outlying",
    "NIS median", "NIS max", "re-entries",
]  # fmt: skip


def _agreement_section(result: RunResult) -> Section:
    """Where the map and the log disagree (stretches, NIS), or why nothing was recovered."""
    rec = result.recovery_result
    if rec is None:
        return Section(
            "Map–log agreement",
            paragraphs=[f"No trajectory was recovered: {result.recovery_error}"],
        )
    a, nis = rec.divergence, rec.nis_stats
    st = a.stretches
    tables = [
        Table(
            "NIS of the recovery's innovations (2 dof)",
            ["measurements", "mean", "median", "expected mean", "beyond 95%", "beyond bound"],
            [
                [
                    nis.count,
                    nis.mean,
                    nis.median,
                    NisStats.EXPECTED_MEAN,
                    nis.fraction_beyond_95,
                    nis.fraction_beyond_bound,
                ]
            ],
        ),  # fmt: skip
    ]
    tb = result.time_base
    if st:
        shown = st[:50]
        when = format_intervals([(s.t0 - tb.t0, s.t1 - tb.t0) for s in shown])
        rows = [
            [w, s.t1 - s.t0, s.measurements, s.outlying, s.nis_median, s.nis_max, s.reentries]
            for w, s in zip(when, shown)
        ]
        tables.append(Table("stretches where the map and the log disagree", _STRETCH_COLUMNS, rows))
    paragraphs = _agreement_paragraphs(a, result.nees_blowups or (), tb.t0)
    return Section("Map–log agreement", paragraphs=paragraphs, tables=tables)


def _agreement_paragraphs(a: Divergence, ns: Sequence[NeesBlowup], t0: float) -> list[str]:
    """The rule and the counts, and the NEES blow-ups ``ns``; ``t0``: the run's start
    (intervals are printed since it)."""
    st = a.stretches
    paragraphs = [
        "EKF localisation in the final map checks every innovation against its covariance: "
        f"a stretch is a run of at least {a.max_outlier_run or 'the default number of'} "
        f"consecutive innovations with NIS beyond the χ² bound {a.outlier_bound:.2f}"
        " (2 dof). Divergence is a finding about the map (or the models), not an error: "
        "the filter was re-entered after each run (its pose covariance inflated) and went on, "
        "and the scores above include these stretches.",
        f"Rule: {a.rule}.",
        (
            f"{len(st)} stretch(es), {100 * a.fraction_of_log:.1f}% of the log, "
            f"{100 * a.fraction_of_measurements:.1f}% of the measurements."
            if st
            else "The map and the log agree: no stretch of outlying innovations."
        ),
    ]
    if ns:
        paragraphs.append(
            f"Against the ground truth, the recovered pose's NEES blows up {len(ns)} time(s): "
            f"runs of at least {a.max_outlier_run or DEFAULT_MAX_OUTLIER_RUN} poses beyond "
            f"its {100 * OUTLIER_PROBABILITY:g}% χ² bound (3 dof), shorter gaps merged — "
            "not the verdict's NEES excursions above the 95% band; in seconds since the run's "
            "start: "
            + ", ".join(format_intervals([(b.t0 - t0, b.t1 - t0) for b in ns[:10]]))
            + (f", … ({len(ns)} in all; every one in metrics.json)" if len(ns) > 10 else "")
            + "."
        )
    if len(st) > 50:
        paragraphs.append(f"The first 50 of {len(st)} stretches are listed; all in metrics.json.")
    return paragraphs


_MAP_COUNTS = ("matched", "missed", "unobserved", "spurious")


def _map_reference(result: RunResult) -> str:
    """What the SLAM map is compared with, in words: the bundle's true landmarks or the
    ``--reference-map`` (given only when the bundle has no true landmarks)."""
    if result.bundle.landmarks_groundtruth is not None:
        return "the true landmarks"
    return "the reference map's landmarks (--reference-map)"


def _map_section(
    m: MapSummary,
    figures: list[Figure],
    links: list[tuple[str, str]],
    *,
    reference: str = "the true landmarks",
    reach: bool = True,
) -> Section:
    """Relations of the landmark map (Delaunay mesh) and the association / set distances.

    ``reference``: what the map is compared with, in words; ``reach``: whether there is a
    true trajectory to tell unobserved landmarks by (without one, every landmark of the
    reference the map lacks is missed, and the section says so).
    """
    if reach:
        unseen = (
            f"{reference[0].upper() + reference[1:]} that never came within the sensor's reach "
            "of the true trajectory are unobserved, not missed; OSPA and GOSPA are computed "
            "without them"
            + (
                f" (on all of them: OSPA {m.ospa_all:.3g} m, GOSPA {m.gospa_all:.3g} m)."
                if m.unobserved and m.ospa_all is not None and m.gospa_all is not None
                else "."
            )
        )
    else:
        unseen = (
            "Without ground truth there is no true trajectory to measure the sensor's reach "
            f"from, so no landmark is told unobserved: every landmark of {reference} the SLAM "
            "map lacks counts as missed, also one the robot never came near, and OSPA and "
            "GOSPA are computed on all of them."
        )
    return Section(
        "Map",
        paragraphs=[
            f"Relations of the landmark map: the Delaunay mesh over {reference}; per edge the "
            "length error, per triangle corner the angle error — local and independent of the "
            "map's frame.",
            f"Landmarks associated {m.association or 'by id'}; OSPA, GOSPA and the figure in "
            f"the frame: {m.frame or 'as given'}. " + unseen,
        ],
        tables=[
            Table(
                "landmark-map relation errors",
                ["relation", "abs mean", "abs std", "abs max", "count"],
                [
                    [what, s.mean, s.std, s.max, s.count]
                    for what, s in (("edge length [m]", m.edge), ("corner angle [rad]", m.corner))
                ],
            ),
            Table(
                "association and set distances",
                [*_MAP_COUNTS, "OSPA [m]", "GOSPA [m]", "c [m]", "p"],
                [[*(getattr(m, k) for k in _MAP_COUNTS), m.ospa, m.gospa, m.cutoff, m.order]],
            ),
        ],
        figures=figures,
        links=links,
    )
