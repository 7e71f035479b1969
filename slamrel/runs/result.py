"""The result of one ``slamrel run`` (:class:`RunResult`) and the parts the report reads.

Built by :func:`slamrel.pipeline.score_bundle`; read by the page (:mod:`slamrel.report.run_page`),
the verdict (:mod:`slamrel.report.verdict`) and ``metrics.json`` (:meth:`RunResult.metrics`),
so the page and the file are written from the same numbers.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from landmark_graph.map_compare import SOURCE_WORDS, MapComparison
from recovery.anchoring import NeesFrame
from recovery.bundle import Bundle
from recovery.clock_offset import ClockOffset
from recovery.results import Divergence, Recovery
from relation_metric.alignment import Alignment, umeyama
from relation_metric.consistency import NeesBlowup, NeesSummary
from relation_metric.errors import SlamrelError
from relation_metric.evaluate import Evaluation, error_summaries
from relation_metric.stats import Summary
from relation_metric.trajectory import Trajectory
from slamrel.runs.nees import NeesCurve, PlacementNees, blowups, truth_at
from slamrel.runs.time_base import TimeBase

__all__ = [
    "DisplayFrame",
    "MapSummary",
    "ReferenceScores",
    "RelationSetRule",
    "RunResult",
    "SetEvaluations",
]


class SetEvaluations(Mapping[str, Evaluation]):
    """One estimate's scores: :attr:`all` (every relation set merged) and one
    :class:`~relation_metric.evaluate.Evaluation` per relation set.

    A read-only mapping from set name to evaluation, ``"all"`` first and then the sets in the
    order they were merged (the order of the per-relation CSV's ``set`` column), for the
    tables that walk them; ``scores.all`` and ``scores["loops"]`` name one.
    """

    def __init__(self, all: Evaluation, sets: Mapping[str, Evaluation]) -> None:
        if "all" in sets:
            raise ValueError('"all" names the merged sets; a relation set cannot take it')
        self._by_name: dict[str, Evaluation] = {"all": all, **sets}

    @property
    def all(self) -> Evaluation:
        """The evaluation of every relation set merged."""
        return self._by_name["all"]

    @property
    def sets(self) -> tuple[str, ...]:
        """The relation sets' names, in merge order (``"all"`` not included)."""
        return tuple(self._by_name)[1:]

    def __getitem__(self, name: str) -> Evaluation:
        return self._by_name[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._by_name)

    def __len__(self) -> int:
        return len(self._by_name)

    def __repr__(self) -> str:
        return f"SetEvaluations(sets={self.sets!r})"


@dataclass(frozen=True)
class RelationSetRule:
    """How one relation set of :func:`default_relations` was made, and how many it got.

    Attributes
    ----------
    name : str
        ``"consecutive"``, ``"loops"`` or ``"global"``.
    rule : str
        The rule in words, with its parameters (e.g. "pairs of poses within 1 m, at least
        20 s apart, at most 5000 (a seeded subset)").
    candidates : int
        Pairs the rule found, before any subset was taken.
    generated : int
        Relations in the set (0: the set is absent).
    absent : str
        Why the set is absent (empty when it is not).
    parameters : dict of str → float
        The parameters the rule was run with (``metrics.json`` ``relation_sets``).
    """

    name: str
    rule: str
    candidates: int
    generated: int
    absent: str = ""
    parameters: dict[str, float] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "rule": self.rule,
            "candidates": self.candidates,
            "generated": self.generated,
            "absent": self.absent or None,
            "parameters": dict(self.parameters),
        }


@dataclass(frozen=True)
class ReferenceScores:
    """Every estimate scored on reference relations the user gave (``slamrel run
    --relations``), as ``slamrel evaluate RELATIONS ESTIMATE`` scores them.

    Attributes
    ----------
    source : str
        Where the relations came from (the file).
    relations : int
        Relations in the file (after the drops ``slamrel evaluate`` makes).
    scores : dict of name → Evaluation
        Per estimate (``recovered``, ``dead_reckoning``, ``online``), at its own times.
    """

    source: str
    relations: int
    scores: dict[str, Evaluation]

    def as_dict(self) -> dict[str, Any]:
        """``metrics.json`` ``reference_relations``."""
        return {
            "source": self.source,
            "relations": self.relations,
            "estimates": {k: ev.as_dict() for k, ev in self.scores.items()},
        }


@dataclass(frozen=True)
class DisplayFrame:
    """How an estimate (or the SLAM map) is drawn over the ground truth in the figures.

    Attributes
    ----------
    alignment : Alignment
        Applied to its poses (or points) before drawing.
    description : str
        The alignment in words, with its numbers (for the captions).
    short : str
        A few words of it (for a legend), e.g. ``"landmark fit"``.
    """

    alignment: Alignment
    description: str
    short: str = ""

    def apply(self, poses: ArrayLike) -> NDArray[np.float64]:
        """Poses ``(N, 3)`` (or points ``(N, 2)``) in the drawing frame."""
        p = np.asarray(poses, dtype=np.float64)
        if p.shape[-1] == 2:
            return self.alignment.apply(np.column_stack((p, np.zeros(len(p)))))[:, :2]
        return self.alignment.apply(p)


@dataclass(frozen=True)
class MapSummary:
    """The numbers of a landmark-map comparison that the report's map section and the verdict
    show, read once from the :class:`~landmark_graph.map_compare.MapComparison`.

    Attributes
    ----------
    edge : Summary
        Absolute edge-length errors of the Delaunay mesh [m] (``metrics.json``
        ``map.translation.abs``).
    corner : Summary
        Absolute corner-angle errors of its triangles [rad] (``map.rotation.abs``).
    matched, missed, spurious : int
        Associated landmark pairs; true landmarks within the sensor's reach without a
        partner, SLAM landmarks without a partner.
    ospa, gospa : float
        OSPA and GOSPA distances [m] of the SLAM map, moved onto the true landmarks by the fit
        on the pairs, and the observable true landmarks (``map.ospa.value``).
    cutoff : float
        Their cut-off ``c`` [m] (the association's).
    order : float
        Their order ``p``.
    unobserved : int
        True landmarks never within the sensor's reach of the true trajectory (neither
        matched nor missed).
    ospa_all, gospa_all : float or None
        The same on all true landmarks (``map.ospa.all_landmarks``).
    frame : str
        The frame of OSPA/GOSPA in words (``map.ospa.frame``).
    association : str
        How the pairs were found, in words (``"by id"``, ``"automatically"``, ``"from a file"``).
    """

    edge: Summary
    corner: Summary
    matched: int
    missed: int
    spurious: int
    ospa: float
    gospa: float
    cutoff: float
    order: float
    unobserved: int = 0
    ospa_all: float | None = None
    gospa_all: float | None = None
    frame: str = ""
    association: str = ""

    @classmethod
    def of(cls, mc: MapComparison) -> MapSummary:
        a = mc.association
        return cls(
            edge=error_summaries(mc.errors.edge_length).abs,
            corner=error_summaries(mc.errors.corner_angle.ravel()).abs,
            matched=int(a.estimate_rows.size),
            missed=int(mc.missed.size),
            spurious=int(a.spurious.size),
            ospa=mc.ospa,
            gospa=mc.gospa,
            cutoff=mc.cutoff,
            order=mc.order,
            unobserved=int(mc.unobserved.size),
            ospa_all=mc.ospa_all,
            gospa_all=mc.gospa_all,
            frame=mc.frame,
            association=SOURCE_WORDS[mc.association_source],
        )


@dataclass(frozen=True)
class RunResult:
    """Everything ``slamrel run`` computed.

    Attributes
    ----------
    name : str
    bundle : Bundle
        The SLAM result bundle (map, covariance, associations, log, ground truth).
    estimates : dict of name → Trajectory
        ``"recovered"`` (when a recovery ran), ``"dead_reckoning"``, ``"online"``.
    evaluations : dict of name → SetEvaluations
        Per estimate, its scores by relation set; also as :attr:`recovered`, :attr:`online`
        and :attr:`dead_reckoning`.
    nees : dict of name → NeesCurve
        In the frame ``nees_frame`` (the map frame anchored to the truth on the landmarks,
        when it can be).
    recovery_result : Recovery or None
        The recovery (``None`` when it failed: see ``recovery_error``).
    map_comparison : MapComparison or None
        The landmark-map comparison, when the bundle has the true landmarks.
    notes : list of str
    recovery_error : str or None
        Why no trajectory was recovered (``--fail-on-divergence``, or numerically impossible
        input); the report then scores dead reckoning (and the online estimate).
    nees_frame : NeesFrame or None
        The frame of ``nees`` (:mod:`recovery.anchoring`): its description, the anchoring.
    nees_truth_frame : dict of name → NeesSummary
        The same NEES with the poses compared with the ground truth as they are (unaligned).
    nees_placement : PlacementNees or None
        The recovered NEES with each pose conditioned on the map's placement (its rigid
        motion, which no relation sees: :mod:`recovery.placement`); the verdict's recovered
        consistency judges it. ``None`` where it is not defined (no true landmarks, the
        filter, a map without uncertainty).
    relation_sets : tuple of RelationSetRule
        How each relation set was made (:func:`default_relations`), absent sets included.
    reference : ReferenceScores or None
        The estimates scored on reference relations the user gave (with truth or without).
    online_vs_recovered : SetEvaluations or None
        Without ground truth: the online estimate scored on relations drawn from the
        recovered trajectory (their difference, not an error of either).
    clock_offset : ClockOffset or None
        The measurements' time offset against the motion (:mod:`recovery.clock_offset`),
        searched only where the map–log lamp is not green (``None`` elsewhere).

    Without ground truth (``bundle.groundtruth`` ``None``, :attr:`has_truth`) ``estimates``
    are the whole trajectories at their own times, ``evaluations``, ``nees`` and
    ``nees_truth_frame`` are empty and ``nees_frame`` is ``None``.

    Derived (computed once, on first use): ``recovery``, ``divergence`` and ``map``, the JSON
    of the recovery, of where the map and the log disagree and of the map comparison
    (``metrics.json``); ``agreement``, the recovery's :class:`~recovery.results.Divergence`;
    ``nees_blowups``, the recovered NEES's blow-ups; ``map_summary``, the
    :class:`MapSummary`; ``time_base``, the report's :class:`TimeBase`; ``display_frames``,
    how the figures draw each estimate and the map over the ground truth
    (:class:`DisplayFrame`).
    """

    name: str
    bundle: Bundle
    estimates: dict[str, Trajectory]
    evaluations: dict[str, SetEvaluations]
    nees: dict[str, NeesCurve]
    recovery_result: Recovery | None
    map_comparison: MapComparison | None = None
    notes: list[str] = field(default_factory=list)
    recovery_error: str | None = None
    nees_frame: NeesFrame | None = None
    nees_truth_frame: dict[str, NeesSummary] = field(default_factory=dict)
    nees_placement: PlacementNees | None = None
    relation_sets: tuple[RelationSetRule, ...] = ()
    reference: ReferenceScores | None = None
    online_vs_recovered: SetEvaluations | None = None
    clock_offset: ClockOffset | None = None

    @property
    def has_truth(self) -> bool:
        """Whether the bundle has a ground-truth trajectory (``groundtruth.csv``)."""
        return self.bundle.groundtruth is not None

    @cached_property
    def time_base(self) -> TimeBase:
        """The report's time axis: seconds since the start of the run's log."""
        return TimeBase.of(self.bundle)

    @cached_property
    def display_frames(self) -> dict[str, DisplayFrame]:
        """How each estimate, and the SLAM map (``"map"``), is drawn over the ground truth.

        The estimates in the SLAM map's frame (recovered, online) and the map itself are
        moved by the landmark fit truth ← map (``nees_frame.map_anchoring``,
        :func:`recovery.anchoring.anchor_on_landmarks`) when it places the map: its rms
        residual at most the map comparison's cut-off ``c`` (1 m without one; a larger one
        means wrong associations or a broken map, not a frame). Dead reckoning, which never
        saw the map, and every estimate without a usable landmark fit, are moved by the SE(2)
        least-squares fit of their positions on the ground truth's at the same times (the map
        then follows the main estimate). Drawing only: every score is frame-free or says its
        frame. Without ground truth every estimate and the map are drawn as they are, in the
        SLAM map's frame.
        """
        truth = self.bundle.groundtruth
        if truth is None:
            as_is = DisplayFrame(
                Alignment(0.0, np.zeros(2), 1.0),
                "as estimated, in the SLAM map's frame (no ground truth to align to)",
                "map frame",
            )
            return {**{k: as_is for k in self.estimates}, "map": as_is}
        m = None if self.nees_frame is None else self.nees_frame.map_anchoring
        cutoff = 1.0 if self.map_comparison is None else self.map_comparison.cutoff
        out: dict[str, DisplayFrame] = {}
        landmark_fit, unused = None, ""
        if m is not None and m.rms_residual <= cutoff:
            landmark_fit = DisplayFrame(
                m.alignment,
                f"moved by the landmark fit truth ← map (dx = {m.dx:.3g} m, dy = {m.dy:.3g} m, "
                f"dθ = {np.degrees(m.dtheta):.3g}°, on {m.landmarks} landmarks "
                f"{'by id' if m.association == 'id' else 'associated automatically'})",
                "landmark fit",
            )
        elif m is not None:
            unused = (
                f"; the landmark fit leaves {m.rms_residual:.3g} m rms, more than "
                f"c = {cutoff:.3g} m: it does not place the map"
            )
        for name, est in self.estimates.items():
            if landmark_fit is not None and name in ("recovered", "online"):
                out[name] = landmark_fit
                continue
            ref = truth_at(truth, est.timestamps)
            try:
                al = umeyama(est.positions, ref[:, :2])
            except SlamrelError:  # fewer than 2 poses: drawn as they are
                al = Alignment(0.0, np.zeros(2), 1.0)
            out[name] = DisplayFrame(
                al,
                f"moved by its SE(2) fit on the ground truth (dx = {al.translation[0]:.3g} m, "
                f"dy = {al.translation[1]:.3g} m, dθ = {np.degrees(al.angle):.3g}°"
                + (unused if name in ("recovered", "online") else "")
                + ")",
                "SE(2) fit on the truth",
            )
        main = self.main_estimate
        out["map"] = landmark_fit if landmark_fit is not None else out[main]
        return out

    @property
    def recovered(self) -> SetEvaluations | None:
        """The recovered trajectory's scores (``None`` when no trajectory was recovered)."""
        return self.evaluations.get("recovered")

    @property
    def online(self) -> SetEvaluations | None:
        """The filter's online estimate's scores (``None`` without ``online.csv``)."""
        return self.evaluations.get("online")

    @property
    def dead_reckoning(self) -> SetEvaluations | None:
        """Dead reckoning's scores (``None`` when the log gives none)."""
        return self.evaluations.get("dead_reckoning")

    @property
    def main_estimate(self) -> str:
        """The estimate scored as ``trajectory``: recovered, else online, else dead reckoning
        (without ground truth, the first of them the run has)."""
        have = self.evaluations if self.evaluations else self.estimates
        return next(k for k in ("recovered", "online", "dead_reckoning") if k in have)

    @cached_property
    def recovery(self) -> dict[str, Any]:
        """The recovery's JSON summary (``metrics.json`` ``recovery``; empty when none ran).

        :meth:`~recovery.results.Recovery.report` without its ``divergence``, which
        ``metrics.json`` holds once, at the top level, with the NEES blow-ups
        (:attr:`divergence`).
        """
        if self.recovery_result is None:
            return {}
        return {k: v for k, v in self.recovery_result.report().items() if k != "divergence"}

    @cached_property
    def nees_blowups(self) -> tuple[NeesBlowup, ...] | None:
        """The recovered NEES's blow-ups (:func:`slamrel.runs.nees.blowups`; ``None`` without
        a recovery)."""
        curve = self.nees.get("recovered")
        if self.recovery_result is None or curve is None:
            return None
        return tuple(blowups(curve, self.recovery_result.divergence.max_outlier_run))

    @cached_property
    def divergence(self) -> dict[str, Any] | None:
        """``metrics.json`` ``divergence``: where the map and the log disagree
        (:class:`~recovery.results.Divergence`) and, as ``nees_stretches``, the NEES blow-ups
        (``None`` without a recovery)."""
        if self.recovery_result is None:
            return None
        out = self.recovery_result.divergence.as_dict()
        if self.nees_blowups is not None:
            out["nees_stretches"] = [b.as_dict() for b in self.nees_blowups]
        return out

    @cached_property
    def map(self) -> dict[str, Any] | None:
        """The map comparison's JSON (``slamrel map-compare``), when there is one."""
        return None if self.map_comparison is None else self.map_comparison.as_dict()

    @property
    def agreement(self) -> Divergence | None:
        """Where the map and the log disagree (``None`` when no recovery ran)."""
        return None if self.recovery_result is None else self.recovery_result.divergence

    @property
    def placement_dict(self) -> dict[str, Any] | None:
        """``metrics.json`` ``nees_map_placement``: the recovered NEES conditioned on the map's
        placement and the placement itself (``dx``, ``dy`` [m], ``dtheta`` [rad], its NEES
        ``rigid_nees`` over ``dof`` 3, the landmarks it was fitted on)."""
        pn = self.nees_placement
        if pn is None:
            return None
        sp = pn.placement.split
        return {
            "recovered": pn.curve.summary.as_dict(),
            "placement": {
                "dx": sp.dx,
                "dy": sp.dy,
                "dtheta": sp.dtheta,
                "rigid_nees": sp.nees_rigid,
                "dof": sp.dof_rigid,
                "landmarks": pn.placement.landmarks,
            },
        }

    @cached_property
    def map_summary(self) -> MapSummary | None:
        """The map comparison's numbers the report shows, when there is one."""
        return None if self.map_comparison is None else MapSummary.of(self.map_comparison)

    def metrics(self) -> dict[str, Any]:
        """The ``metrics.json`` structure."""
        out: dict[str, Any] = {}
        main_name = self.main_estimate
        for name, evs in self.evaluations.items():
            key = "trajectory" if name == main_name else name
            out[key] = evs.all.as_dict()
            out[key]["by_relation_set"] = {k: evs[k].as_dict() for k in evs.sets}
        out["trajectory_source"] = main_name
        out["map"] = self.map
        out["recovery"] = self.recovery
        out["divergence"] = self.divergence
        out["recovery_error"] = self.recovery_error
        out["nees"] = {k: v.summary.as_dict() for k, v in self.nees.items()}
        out["nees_frame"] = None if self.nees_frame is None else self.nees_frame.as_dict()
        out["nees_truth_frame"] = {k: v.as_dict() for k, v in self.nees_truth_frame.items()}
        if self.nees_placement is not None:
            out["nees_map_placement"] = self.placement_dict
        if self.clock_offset is not None:  # searched only where the map–log lamp is not green
            out["clock_offset"] = self.clock_offset.as_dict()
        out["time_base"] = self.time_base.as_dict()
        out["relation_sets"] = [r.as_dict() for r in self.relation_sets]
        out["notes"] = self.notes
        if self.reference is not None:
            out["reference_relations"] = self.reference.as_dict()
        if self.online_vs_recovered is not None:
            ev = self.online_vs_recovered
            out["online_vs_recovered"] = ev.all.as_dict()
            out["online_vs_recovered"]["by_relation_set"] = {k: ev[k].as_dict() for k in ev.sets}
        return out
