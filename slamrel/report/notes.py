"""The prose of the run report: the notes under its summary (``metrics.json`` ``notes``).

Sentences about what a run computed — what was recovered and from what, the frame of the
NEES, the map comparison's association and frame — written from the typed results the
pipeline composes (:func:`slamrel.pipeline.score_bundle` calls these and stores the notes in
:attr:`slamrel.runs.result.RunResult.notes`).
"""

from __future__ import annotations

import numpy as np

from landmark_graph.map_compare import SOURCE_WORDS, MapComparison
from recovery.anchoring import NeesFrame
from recovery.models import MotionModel, SensorModel
from recovery.odometry_bias import epoch_spacing
from recovery.results import Recovery
from relation_metric.consistency import NeesSummary
from slamrel.report.verdict import expected_downweight_loss
from slamrel.runs.nees import NeesCurve

__all__ = [
    "map_notes",
    "nees_notes",
    "no_truth_notes",
    "persisting_notes",
    "recovery_notes",
    "run_notes",
]


def run_notes(
    rec: Recovery | None, rec_error: str | None, method: str, *, has_online: bool
) -> list[str]:
    """The report's notes: what was recovered (or why nothing), and what the online estimate is."""
    if rec is None:
        notes = [
            f"No trajectory was recovered: {rec_error}. The report scores dead "
            "reckoning" + (" and the online estimate." if has_online else ".")
        ]
    else:
        notes = recovery_notes(rec, method)
    if has_online:
        notes.append(
            "The online estimate is the EKF-SLAM filter's own pose; it is shown for validation "
            "only (a filter-based SLAM system keeps no trajectory)."
        )
    return notes


def recovery_notes(rec: Recovery, method: str) -> list[str]:
    """The report's notes on the recovery: what it is, its measurements, robust weights and
    stretches of disagreement."""
    counts = rec.counts
    notes = [
        f"The recovered trajectory is EKF localisation in the SLAM run's final map with its "
        f"data associations and models, then smoothed ({method}); it scores the final map, "
        "not the estimate the filter had online.",
        f"Recovery used {counts.used} of {counts.measurements} measurements; "
        f"{counts.gated} were gated ({100 * counts.gated_fraction:.1f}%), "
        f"{counts.unassociated} were unassociated. A large gated fraction is a finding "
        "about the map, not noise.",
        f"Map prior: {rec.map_prior}, {rec.map_prior_reason}.",
    ]
    dead = counts.dead_reckoning()
    if dead is not None:
        notes.append(dead[0].upper() + dead[1:] + ".")
    if counts.downweighted:
        notes.append(
            f"The robust update down-weighted {counts.downweighted} measurements "
            f"({100 * counts.downweighted_fraction:.1f}%, weight lost "
            f"{100 * counts.downweight_loss:.1f}%)"
            + (
                f"; consistent innovations would lose "
                f"{100 * expected_downweight_loss(rec.robust.threshold):.1f}% (a robust update "
                "always down-weights some perfectly Gaussian ones): a loss well above that is a "
                "finding about the map."
                if rec.robust is not None and rec.robust.kind == "redescending"
                else "; a large loss is a finding about the map."
            )
        )
    d = rec.divergence
    if d.stretches:
        notes.append(
            f"The map and the log DISAGREE on {len(d.stretches)} stretch(es) covering "
            f"{100 * d.fraction_of_log:.1f}% of the log (runs of innovations beyond the "
            f"χ² bound {d.outlier_bound:.2f}; mean NIS {rec.nis_stats.mean:.3g}, 2 "
            "expected). Divergence is a finding: the recovery was re-entered after each run "
            "and went on; the score includes these stretches (see the section below)."
        )
    return notes


def persisting_notes(sensor: SensorModel, motion: MotionModel) -> list[str]:
    """The report's note on the persisting errors a bundle states, which the recovery carries
    as states (:mod:`recovery.persisting`, :mod:`recovery.odometry_bias`); none when none."""
    parts = []
    pe = sensor.persisting
    if pe is not None:
        text = (
            f"the measurements' (a Gauss–Markov bias per landmark track: range σ "
            f"{pe.sigma_range:.3g} m, τ {pe.time_constant_range:.3g} s; bearing σ "
            f"{pe.sigma_bearing:.3g} rad, τ {pe.time_constant_bearing:.3g} s"
        )
        if pe.common is not None:
            c = pe.common
            text += (
                f"; one common to every landmark: range σ {c.sigma_range:.3g} m, τ "
                f"{c.time_constant_range:.3g} s; bearing σ {c.sigma_bearing:.3g} rad, τ "
                f"{c.time_constant_bearing:.3g} s"
            )
        parts.append(text + ")")
    mp = motion.persisting
    if mp is not None:
        parts.append(
            f"the odometry's (a Gauss–Markov speed scale σ {mp.sigma_scale:.3g}, τ "
            f"{mp.time_constant_scale:.3g} s, and turn per metre σ {mp.sigma_turn:.3g} rad/m, "
            f"τ {mp.time_constant_turn:.3g} s, on top of the stated white noise; epochs "
            "without measurements are added so that the recovery holds them over at most "
            f"{epoch_spacing((mp.time_constant_scale, mp.time_constant_turn)):.3g} s)"
        )
    if not parts:
        return []
    return [
        "The bundle states errors that persist, which the recovery carries in its state "
        "(sensor_model.persisting, motion_model.persisting): " + "; and ".join(parts) + "."
    ]


def nees_notes(
    frame: NeesFrame,
    nees: dict[str, NeesCurve],
    unaligned: dict[str, NeesSummary],
    *,
    online_without_covariances: bool = False,
) -> list[str]:
    """The report's notes on the NEES: its frame, the anchoring, and a missing online NEES
    (``online_without_covariances``: the run has an online estimate without covariances)."""
    notes = []
    a, m = frame.anchoring, frame.map_anchoring
    if nees:
        text = f"NEES is computed in the {frame.description}"
        if a is not None:
            text += (
                f": the map frame sits at dx = {a.dx:.3g} m, dy = {a.dy:.3g} m, "
                f"dθ = {np.degrees(a.dtheta):.3g}° in the truth frame; unplaced, the NEES "
                "mean is " + ", ".join(f"{unaligned[k].mean:.3g} ({k})" for k in nees)
            )
        if m is not None:
            text += (
                f"; the map's landmarks sit dx = {m.dx:.3g} m, dy = {m.dy:.3g} m, "
                f"dθ = {np.degrees(m.dtheta):.3g}° off the true ones ({m.landmarks} landmarks, "
                f"rms residual {m.rms_residual:.3g} m): a map error, part of its uncertainty"
            )
        notes.append(text + ".")
    if online_without_covariances:
        notes.append(
            "The online estimate has no covariances (online.csv without the columns "
            "cxx,cxy,cxt,cyy,cyt,ctt): there is no online NEES."
        )
    return notes


def no_truth_notes(*, relations: bool, online: bool) -> list[str]:
    """The report's notes for a bundle without ground truth: what is judged without it and
    what is not (``relations``: reference relations were given; ``online``: the online
    estimate was compared with the recovered one)."""
    notes = [
        "The bundle has no ground truth (groundtruth.csv): nothing is scored on relations drawn "
        "from it and there is no NEES. What needs no truth is all here: the recovered "
        "trajectory, where the map and the log disagree (the innovations' NIS), the robust "
        "weights' loss"
        + (", the online estimate against the recovered one" if online else "")
        + ". The figures draw every estimate as estimated, in the SLAM map's frame."
    ]
    if relations:
        notes.append(
            "Every estimate is scored on the reference relations given (--relations) as "
            "slamrel evaluate scores them; their accuracy is that of the relations."
        )
    if online:
        notes.append(
            "Online against recovered: the online estimate scored on relations drawn from the "
            "recovered trajectory — how far the two estimates differ, not the error of either."
        )
    return notes


def map_notes(mc: MapComparison, *, reference: str = "the true landmarks") -> list[str]:
    """The report's notes on the map comparison: association, frame, unobserved landmarks
    (``reference``: what the map is compared with, in words)."""
    al = mc.alignment
    how = SOURCE_WORDS[mc.association_source]
    text = (
        f"The map is compared with {reference} associated {how} "
        f"({mc.association.estimate_rows.size} pairs); OSPA, GOSPA and the map figure are in "
        f"the frame: {mc.frame}"
    )
    if al.pairs:
        text += (
            f" (dx = {al.dx:.3g} m, dy = {al.dy:.3g} m, dθ = {np.degrees(al.dtheta):.3g}°, "
            f"rms residual {al.rms_residual:.3g} m)"
        )
    notes = [text + "; the mesh errors do not depend on the frame."]
    if mc.mesh_gap is not None:
        notes.append(mc.mesh_gap[0].upper() + mc.mesh_gap[1:] + ".")
    notes += [n[0].upper() + n[1:] + "." for n in mc.notes]
    if mc.reach is not None:
        u = mc.unobserved.size
        text = f"OSPA and GOSPA are computed on {mc.observable_set}" + (
            "; the bundle declares no sensor reach, so the largest range it measured stands in"
            if mc.reach.source != "declared"
            else ""
        )
        if u:
            text += (
                f"; {u} true landmark(s) never came within reach and count as unobserved, not "
                f"missed (on all true landmarks OSPA {mc.ospa_all:.3g} m, GOSPA "
                f"{mc.gospa_all:.3g} m)"
            )
        notes.append(text + ".")
    return notes
