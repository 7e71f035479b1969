"""The page of ``slamrel run``: its figures and sections, named, built from a ``RunResult``.

:func:`report_figures` draws the four figures (:class:`RunFigures`, one attribute each, the
map figure only with a map comparison); :func:`report_sections` writes the four sections
(:class:`RunSections`). Every number in a table is read from the same structures
``metrics.json`` is written from (:meth:`slamrel.pipeline.RunResult.metrics`), so the page
and the file cannot disagree. :func:`slamrel.pipeline.write_report` writes the folder.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from recovery.recover import DEFAULT_MAX_OUTLIER_RUN, NisStats
from relation_metric.consistency import OUTLIER_PROBABILITY
from slamrel.plots.maps import map_figure
from slamrel.plots.relation_errors import evaluation_figure
from slamrel.plots.run import (
    mark_stretches_time,
    mark_stretches_xy,
    nees_figure,
    trajectories_figure,
)
from slamrel.report.html import Figure, Section, Table, figure_png

if TYPE_CHECKING:
    from recovery.recover import Divergence
    from slamrel.pipeline import MapSummary, RunResult

__all__ = ["RunFigures", "RunSections", "report_figures", "report_sections"]


class RunFigures(NamedTuple):
    """The figures of the run report, in page (and ``figure_<k>.png``) order."""

    trajectories: Figure
    errors: Figure
    nees: Figure
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
    """Draw the report's figures (matplotlib, closed after rendering to PNG)."""
    truth = result.bundle.groundtruth
    assert truth is not None
    stretches = result.agreement.stretches if result.agreement is not None else ()
    lgt = result.bundle.landmarks_groundtruth
    trajectories = Figure(
        "Estimates against the ground truth, with the true landmarks and the SLAM map",
        figure_png(
            mark_stretches_xy(
                trajectories_figure(
                    truth,
                    result.estimates,
                    landmarks=lgt[1] if lgt else None,
                    mapped=result.bundle.map_xy,
                ),
                stretches,
                result.estimates.get("recovered"),
            )
        ),
    )
    main = result.main_estimate
    main_all = result.evaluations[main]["all"]
    errors = Figure(
        f"The {main} trajectory coloured by relation error (all relation sets), "
        "and the errors over time",
        figure_png(
            mark_stretches_time(
                evaluation_figure(main_all, result.estimates[main]), stretches, main_all
            )
        ),
    )
    nees = Figure(
        "NEES over time with the 95% χ² band (3 dof)",
        figure_png(
            nees_figure(
                truth.timestamps[1:],
                {k: v.values for k, v in result.nees.items()},
                {k: v.summary for k, v in result.nees.items()},
            )
        ),
    )
    return RunFigures(trajectories, errors, nees, _map_figure(result))


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
    return Figure(
        "The SLAM map against the true landmarks: the Delaunay mesh of the true "
        "landmarks, each edge coloured by its length error",
        figure_png(map_figure(result.map_comparison)),
    )


def report_sections(
    result: RunResult, figures: RunFigures, *, review: tuple[str, str] | None = None
) -> RunSections:
    """The report's sections; ``review``: the ``(href, text)`` link to ``review.html``."""
    summary = Section(
        f"slamrel run: {result.name}",
        paragraphs=[
            "Relation metric (Kümmerle et al. 2009): relative motions of each estimate "
            "against ground-truth relations, ε = 1/N Σ ‖δ_ij ⊖ δ*_ij‖².",
            *result.notes,
        ],
        tables=[_stats_table(result, "translation"), _stats_table(result, "rotation")],
        figures=[figures.trajectories, figures.errors],
    )
    frame = result.nees_frame
    unaligned = result.nees_truth_frame
    consistency = Section(
        "Consistency",
        paragraphs=[] if frame is None else [f"NEES frame: {frame.description}."],
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
                [
                    [
                        k,
                        v.summary.mean,
                        v.summary.band[0],
                        v.summary.band[1],
                        v.summary.inside,
                        unaligned[k].mean if k in unaligned else None,
                    ]
                    for k, v in result.nees.items()
                ],
            ),
            *_anchoring_table(result),
        ],
        figures=[figures.nees],
    )
    ms = result.map_summary
    map_section = None
    if ms is not None:
        map_section = _map_section(
            ms,
            [] if figures.map is None else [figures.map],
            [] if review is None else [review],
        )
    return RunSections(summary, consistency, _agreement_section(result), map_section)


def _stats_table(result: RunResult, part: str) -> Table:
    """Mean, std, max of the absolute and mean of the squared errors, per estimate and set."""
    rows = []
    for name, evs in result.evaluations.items():
        for set_name, ev in evs.items():
            s = getattr(ev, part)["abs"]
            q = getattr(ev, part)["sqr"]
            rows.append([name, set_name, s.mean, s.std, q.mean, s.max, s.count])
    u = "m" if part == "translation" else "rad"
    return Table(
        f"{part} relation error [{u}]",
        ["estimate", "relations", f"abs mean [{u}]", f"abs std [{u}]", f"sqr mean [{u}²]",
         f"abs max [{u}]", "count"],
        rows,
    )  # fmt: skip


_STRETCH_COLUMNS = [
    "t0", "t1", "duration", "measurements", "outlying", "NIS median", "NIS max", "re-entries",
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
    if st:
        rows = [
            [s.t0, s.t1, s.t1 - s.t0, s.measurements, s.outlying, s.nis_median, s.nis_max,
             s.reentries]
            for s in st[:50]
        ]  # fmt: skip
        tables.append(
            Table(
                "stretches where the map and the log disagree (times in s)", _STRETCH_COLUMNS, rows
            )
        )
    return Section("Map–log agreement", paragraphs=_agreement_paragraphs(a), tables=tables)


def _agreement_paragraphs(a: Divergence) -> list[str]:
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
    ns = a.nees_blowups or ()
    if ns:
        paragraphs.append(
            f"Against the ground truth, the recovered pose's NEES blows up {len(ns)} time(s): "
            f"runs of at least {a.max_outlier_run or DEFAULT_MAX_OUTLIER_RUN} poses beyond "
            f"its {100 * OUTLIER_PROBABILITY:g}% χ² bound (3 dof), shorter gaps merged — "
            "not the verdict's NEES excursions above the 95% band: "
            + ", ".join(f"[{b.t0:.6g}, {b.t1:.6g}] s" for b in ns[:10])
            + (" …" if len(ns) > 10 else "")
            + "."
        )
    if len(st) > 50:
        paragraphs.append(f"The first 50 of {len(st)} stretches are listed; all in metrics.json.")
    return paragraphs


_MAP_COUNTS = ("matched", "missed", "unobserved", "spurious")


def _map_section(m: MapSummary, figures: list[Figure], links: list[tuple[str, str]]) -> Section:
    """Relations of the landmark map (Delaunay mesh) and the association / set distances."""
    return Section(
        "Map",
        paragraphs=[
            "Relations of the landmark map: the Delaunay mesh over the true "
            "landmarks; per edge the length error, per triangle corner the angle "
            "error — local and independent of the map's frame.",
            f"Landmarks associated {m.association or 'by id'}; OSPA, GOSPA and the figure in "
            f"the frame: {m.frame or 'as given'}. True landmarks that never came within the "
            "sensor's reach of the true trajectory are unobserved, not missed; OSPA and GOSPA "
            "are computed without them"
            + (
                f" (on all true landmarks: OSPA {m.ospa_all:.3g} m, GOSPA {m.gospa_all:.3g} m)."
                if m.unobserved and m.ospa_all is not None and m.gospa_all is not None
                else "."
            ),
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
