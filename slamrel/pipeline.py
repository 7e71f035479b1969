"""The main job end to end: world → EKF-SLAM → bundle → recovery → relation metric → report.

Three steps, the I/O at the ends (evo's ``main_ape``: load, a pure ``ape``, write):

* :func:`read_run_input` reads a SLAM result bundle directory (and its ``online.csv``), or
  :func:`simulate_run_input` simulates a built-in world and runs the reference EKF-SLAM —
  either gives a :class:`RunInput`;
* :func:`run_pipeline` (and :func:`score_bundle`) recover and score it and return a
  :class:`RunResult` (no I/O);
* :func:`write_report` writes the result atomically into a report folder (``report.html``,
  ``metrics.json``, per-relation CSVs, figures); the page itself is built by
  :mod:`slamrel.report.run_page`.

The trajectory is scored on three relation sets generated from the ground truth — consecutive
(local), loop-closing and global (far-apart) — because local relations alone cannot see
global breakage (docs/design.md, measured pitfalls). Dead reckoning is scored the same way as the
baseline everyone understands; the SLAM run's online estimate is scored *for validation only*
(a filter-based SLAM system does not keep it).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from landmark_graph.constants import DEFAULT_ASSOCIATE
from landmark_graph.landmark_association import Association
from landmark_graph.map_compare import SOURCE_WORDS, MapComparison, compare_maps
from landmark_graph.maps import LandmarkMap
from landmark_graph.observability import SensorReach, within_reach
from recovery.anchoring import (
    Anchoring,
    NeesFrame,
    anchor_on_landmarks,
    start_frame,
    truth_at_start,
)
from recovery.bundle import Bundle
from recovery.recover import DEFAULT_MAX_OUTLIER_RUN, DEFAULT_ROBUST, Divergence, Recovery, recover
from recovery.steps import build_steps
from relation_metric import se2
from relation_metric.alignment import Alignment, umeyama
from relation_metric.consistency import NeesSummary, pose_nees, summarize_nees
from relation_metric.errors import InputError, SlamrelError
from relation_metric.evaluate import (
    Evaluation,
    UnassociatedRelationsWarning,
    error_summaries,
    evaluate,
)
from relation_metric.relations import RelationSet, generate_relations
from relation_metric.stats import Summary
from relation_metric.time_association import match_nearest_times, nearest_index
from relation_metric.trajectory import Trajectory
from slamrel.backends.ekf_slam import ekf_slam_bundle
from slamrel.formats.bundle import read_bundle, read_online, write_bundle
from slamrel.formats.results import write_json, write_per_relation_csv
from slamrel.outputs import staged_directory, write_text_atomic
from slamrel.report.html import render_html
from slamrel.report.run_page import report_figures, report_sections
from slamrel.report.verdict import RunFacts, expected_downweight_loss, run_verdict
from slamrel.simulation.bundles import world_bundle
from slamrel.simulation.worlds import make_world

__all__ = [
    "DefaultRelations",
    "DisplayFrame",
    "MapSummary",
    "NeesCurve",
    "RelationSetRule",
    "RunInput",
    "RunResult",
    "default_relations",
    "landmark_frame",
    "map_comparison",
    "read_run_input",
    "run_pipeline",
    "score_bundle",
    "sensor_reach",
    "simulate_run_input",
    "TimeBase",
    "write_report",
]


#: The relation sets ``slamrel run`` scores, and their parameters (:func:`default_relations`).
RELATION_SPACING = 1.0  # s: the reference is thinned to one pose a second, consecutive pairs
LOOP_RADIUS = 1.0  # m
LOOP_MIN_SEPARATION = 20.0  # s
MAX_LOOPS = 5000
GLOBAL_COUNT = 2000


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
class DefaultRelations:
    """The relation sets of :func:`default_relations` (the non-empty ones, by name) and how
    each of the three was made (:class:`RelationSetRule`, absent sets included)."""

    sets: dict[str, RelationSet]
    rules: tuple[RelationSetRule, ...]


def default_relations(reference: Trajectory, *, seed: int = 0) -> DefaultRelations:
    """Consecutive (1 s apart), loop-closing and global relations from the ground truth.

    On the reference thinned to about one pose a second (:data:`RELATION_SPACING`).
    Consecutive: each pose with the next. Loops: poses within :data:`LOOP_RADIUS` that are at
    least :data:`LOOP_MIN_SEPARATION` apart (at most :data:`MAX_LOOPS`, a seeded subset);
    global: :data:`GLOBAL_COUNT` random pairs at least a quarter of the diagonal of the
    reference's bounding box apart. Empty sets are left out of ``sets`` and say why in
    ``rules``.
    """
    t = reference.timestamps
    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    step = max(1, int(round(RELATION_SPACING / dt)))
    # one pose a second: dense ground truth (e.g. 100 Hz Vicon) would give millions of pairs
    coarse = Trajectory(t[::step], reference.poses[::step])
    thinned = (
        f"on the ground truth thinned to one pose every {step * dt:.3g} s ({len(coarse)} poses)"
    )
    consecutive = generate_relations(coarse, "consecutive")
    loops = generate_relations(
        coarse, "loops", radius=LOOP_RADIUS, min_separation_time=LOOP_MIN_SEPARATION
    )
    found = len(loops)
    if found > MAX_LOOPS:  # a seeded, uniform subset keeps reports fast on long runs
        pick = np.sort(np.random.default_rng(seed).choice(found, MAX_LOOPS, replace=False))
        loops = loops.subset(pick)
    xy = coarse.positions
    extent = float(np.linalg.norm(xy.max(axis=0) - xy.min(axis=0)))
    far = generate_relations(
        coarse, "global", count=GLOBAL_COUNT, min_distance=extent / 4.0, seed=seed
    )
    rules = (
        RelationSetRule(
            "consecutive", f"each pose with the next, {thinned}", len(consecutive),
            len(consecutive), "" if len(consecutive) else "fewer than 2 poses",
            {"spacing_s": step * dt},
        ),
        RelationSetRule(
            "loops",
            f"pairs of poses within {LOOP_RADIUS:g} m of each other and at least "
            f"{LOOP_MIN_SEPARATION:g} s apart, at most {MAX_LOOPS}"
            + (f" (a seeded subset of the {found} found)" if found > MAX_LOOPS else "")
            + f", {thinned}",
            found, len(loops),
            "" if len(loops) else (
                f"no two poses lie within {LOOP_RADIUS:g} m of each other at least "
                f"{LOOP_MIN_SEPARATION:g} s apart: the run never comes back to where it was"
            ),
            {"radius_m": LOOP_RADIUS, "min_separation_s": LOOP_MIN_SEPARATION,
             "max_relations": MAX_LOOPS},
        ),
        RelationSetRule(
            "global",
            f"{GLOBAL_COUNT} seeded random pairs at least {extent / 4.0:.3g} m apart (a quarter "
            f"of the {extent:.3g} m diagonal of the ground truth's bounding box)"
            + (f" — only {len(far)} distinct pairs lie that far apart" if len(far) < GLOBAL_COUNT
               else "")
            + f", {thinned}",
            len(far), len(far),
            "" if len(far) else f"no two poses lie {extent / 4.0:.3g} m or more apart",
            {"count": GLOBAL_COUNT, "min_distance_m": extent / 4.0},
        ),
    )  # fmt: skip
    sets = {"consecutive": consecutive, "loops": loops, "global": far}
    return DefaultRelations({k: v for k, v in sets.items() if len(v)}, rules)


def _merge(sets: dict[str, RelationSet]) -> RelationSet:
    parts = list(sets.values())
    return RelationSet(
        np.concatenate([p.first for p in parts]),
        np.concatenate([p.second for p in parts]),
        np.concatenate([p.delta for p in parts]),
    )


@dataclass(frozen=True)
class RunInput:
    """What ``slamrel run`` scores: a SLAM result bundle and the baselines that came with it.

    Attributes
    ----------
    bundle : Bundle
        With ground truth (``groundtruth.csv``): required to score.
    name : str
        Shown in the report's title.
    online : Trajectory or None
        The SLAM run's own estimate (validation only).
    online_covariance : ndarray, shape (N, 3, 3) or None
        Its pose covariances, one per pose of ``online``.
    dead_reckoning : Trajectory or None
        Odometry alone; ``None``: chained from the bundle's log.
    """

    bundle: Bundle
    name: str
    online: Trajectory | None = None
    online_covariance: NDArray[np.float64] | None = None
    dead_reckoning: Trajectory | None = None


class NeesCurve(NamedTuple):
    """The NEES of one estimate: its summary, the per-step values, shape (steps,), and their
    times [s] (the estimate's poses where the NEES exists; ``None``: not known)."""

    summary: NeesSummary
    values: NDArray[np.float64]
    times: NDArray[np.float64] | None = None


@dataclass(frozen=True)
class TimeBase:
    """The report's one time axis: seconds since the run's start (every timeline, interval
    and stretch of the page is given on it).

    Attributes
    ----------
    t0, t1 : float
        Start and end of the run's log (first and last control, or odometry, time) [s, on
        the log's own clock, e.g. Unix time].
    """

    t0: float
    t1: float

    @property
    def duration(self) -> float:
        """``t1 − t0`` [s]."""
        return self.t1 - self.t0

    def since_start(self, t: ArrayLike) -> NDArray[np.float64]:
        """Times ``t`` [s, the log's clock] as seconds since the run's start."""
        return np.asarray(t, dtype=np.float64) - self.t0

    @classmethod
    def of(cls, bundle: Bundle) -> TimeBase:
        """The span of the bundle's log (``controls.csv``, else ``odometry.csv``)."""
        if bundle.controls is not None:
            t = bundle.controls[:, 0]
        else:
            assert bundle.odometry is not None  # a bundle has one or the other (Bundle checks)
            t = bundle.odometry.timestamps
        return cls(float(t[0]), float(t[-1]))

    def as_dict(self) -> dict[str, Any]:
        return {"t0": self.t0, "t1": self.t1, "duration": self.duration,
                "unit": "s since the run's start (t0 on the log's clock)"}  # fmt: skip


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
    evaluations : dict of name → dict of relation-set name → Evaluation
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
    relation_sets : tuple of RelationSetRule
        How each relation set was made (:func:`default_relations`), absent sets included.

    Derived (computed once, on first use): ``recovery`` and ``map``, the JSON of the recovery
    and of the map comparison (``metrics.json``); ``agreement``, the recovery's
    :class:`~recovery.recover.Divergence`; ``map_summary``, the :class:`MapSummary`;
    ``time_base``, the report's :class:`TimeBase`; ``display_frames``, how the figures draw
    each estimate and the map over the ground truth (:class:`DisplayFrame`).
    """

    name: str
    bundle: Bundle
    estimates: dict[str, Trajectory]
    evaluations: dict[str, dict[str, Evaluation]]
    nees: dict[str, NeesCurve]
    recovery_result: Recovery | None
    map_comparison: MapComparison | None = None
    notes: list[str] = field(default_factory=list)
    recovery_error: str | None = None
    nees_frame: NeesFrame | None = None
    nees_truth_frame: dict[str, NeesSummary] = field(default_factory=dict)
    relation_sets: tuple[RelationSetRule, ...] = ()

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
        frame.
        """
        truth = self.bundle.groundtruth
        assert truth is not None
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
            ref = _truth_at(truth, est.timestamps)
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
    def main_estimate(self) -> str:
        """The estimate scored as ``trajectory``: recovered, else online, else dead reckoning."""
        return next(k for k in ("recovered", "online", "dead_reckoning") if k in self.evaluations)

    @cached_property
    def recovery(self) -> dict[str, Any]:
        """The recovery's JSON summary (``metrics.json`` ``recovery``; empty when none ran)."""
        return {} if self.recovery_result is None else self.recovery_result.report()

    @cached_property
    def map(self) -> dict[str, Any] | None:
        """The map comparison's JSON (``slamrel map-compare``), when there is one."""
        return None if self.map_comparison is None else self.map_comparison.as_dict()

    @property
    def agreement(self) -> Divergence | None:
        """Where the map and the log disagree (``None`` when no recovery ran)."""
        return None if self.recovery_result is None else self.recovery_result.divergence

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
            out[key] = evs["all"].as_dict()
            out[key]["by_relation_set"] = {k: v.as_dict() for k, v in evs.items() if k != "all"}
        out["trajectory_source"] = main_name
        out["map"] = self.map
        out["recovery"] = self.recovery
        out["divergence"] = self.recovery.get("divergence")
        out["recovery_error"] = self.recovery_error
        out["nees"] = {k: v.summary.as_dict() for k, v in self.nees.items()}
        out["nees_frame"] = None if self.nees_frame is None else self.nees_frame.as_dict()
        out["nees_truth_frame"] = {k: v.as_dict() for k, v in self.nees_truth_frame.items()}
        out["time_base"] = self.time_base.as_dict()
        out["relation_sets"] = [r.as_dict() for r in self.relation_sets]
        out["notes"] = self.notes
        return out


def _evaluate_sets(sets: dict[str, RelationSet], est: Trajectory) -> dict[str, Evaluation]:
    # estimates are sampled at ground-truth times where they can be (exact association);
    # otherwise (real logs) the nearest pose within 0.1 s, or SE(2) interpolation
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnassociatedRelationsWarning)  # counted in the JSON
        # an empty set is reported as such (relation_sets says why), not refused
        kw: dict[str, Any] = {"max_time_diff": 0.1, "interpolate": True, "allow_empty": True}
        out = {"all": evaluate(_merge(sets), est, **kw)}
        for k, rel in sets.items():
            out[k] = evaluate(rel, est, **kw)
    return out


def _set_labels(evs: dict[str, Evaluation]) -> NDArray[np.str_]:
    """The relation set of each relation of ``evs["all"]`` (:func:`_evaluate_sets` merged
    the sets in the order of ``evs``), for the ``set`` column of the per-relation CSV."""
    names = [k for k in evs if k != "all"]
    labels = np.repeat(np.array(names, dtype=np.str_), [len(evs[k].relations) for k in names])
    if labels.size != len(evs["all"].relations):
        raise RuntimeError("the merged relations are not the relation sets in order")
    return labels


def read_run_input(directory: str | Path) -> RunInput:
    """Read a SLAM result bundle directory to score (the I/O end of ``slamrel run``).

    The bundle (``docs/bundle.md``) is scored against its ``groundtruth.csv`` (required by
    :func:`score_bundle`) and, when present, ``landmarks_groundtruth.csv``; an ``online.csv``
    beside it (written by ``slamrel slam --store-online``) is scored too, and with its
    covariance columns gets an online NEES (:func:`slamrel.formats.bundle.read_online`).
    """
    bundle = read_bundle(directory)
    online_path = Path(directory) / "online.csv"
    if not online_path.is_file():
        return RunInput(bundle, name=str(directory))
    online = read_online(online_path)
    return RunInput(
        bundle, name=str(directory), online=online.trajectory,
        online_covariance=online.covariances,
    )  # fmt: skip


def simulate_run_input(
    world: str = "simple1",
    *,
    noise: str = "a",
    seed: int = 0,
    rate: int = 0,
    corrupt_fraction: float = 0.0,
    noise_scale: float = 1.0,
    process_noise_scale: float = 1.0,
) -> RunInput:
    """Simulate a built-in world and run the reference EKF-SLAM on it (no I/O).

    The input carries the filter's online estimate and covariances (for validation) and the
    world's odometry as dead reckoning. ``corrupt_fraction``, ``noise_scale`` and
    ``process_noise_scale`` are passed to :func:`slamrel.backends.ekf_slam.ekf_slam_bundle`.
    """
    w = make_world(world, noise=noise, seed=seed, rate=rate)
    bundle, slam = ekf_slam_bundle(
        world_bundle(w), corrupt_fraction=corrupt_fraction, noise_scale=noise_scale, seed=seed,
        process_noise_scale=process_noise_scale,
    )  # fmt: skip
    return RunInput(
        bundle, name=f"{world}/{noise}/seed {seed}", online=slam.online,
        online_covariance=slam.online_covariance, dead_reckoning=w.odometry,
    )  # fmt: skip


def run_pipeline(
    source: str | RunInput = "simple1",
    *,
    noise: str = "a",
    seed: int = 0,
    rate: int = 0,
    corrupt_fraction: float = 0.0,
    noise_scale: float = 1.0,
    method: str = "smoother",
    max_outlier_run: int | None = DEFAULT_MAX_OUTLIER_RUN,
    on_divergence: str = "reenter",
    robust: str | None = DEFAULT_ROBUST,
    process_noise_scale: float = 1.0,
    associate: str | Association = DEFAULT_ASSOCIATE,
    align: bool = True,
) -> RunResult:
    """Run the whole chain on a built-in world, or score a bundle read earlier (no I/O).

    ``source``: a world name (simulated by :func:`simulate_run_input` with ``noise``, ``seed``,
    ``rate``, ``corrupt_fraction``, ``noise_scale``, ``process_noise_scale``), or a
    :class:`RunInput` (e.g. from :func:`read_run_input` for a bundle directory).
    ``max_outlier_run``, ``on_divergence`` and ``robust`` are passed to
    :func:`recovery.recover.recover`, ``associate`` and ``align`` to :func:`map_comparison`.
    """
    inp = source
    if not isinstance(inp, RunInput):
        inp = simulate_run_input(
            inp, noise=noise, seed=seed, rate=rate, corrupt_fraction=corrupt_fraction,
            noise_scale=noise_scale, process_noise_scale=process_noise_scale,
        )  # fmt: skip
    return score_bundle(
        inp, seed=seed, method=method, max_outlier_run=max_outlier_run,
        on_divergence=on_divergence, robust=robust, associate=associate, align=align,
    )  # fmt: skip


def score_bundle(
    inp: RunInput,
    *,
    seed: int = 0,
    method: str = "smoother",
    max_outlier_run: int | None = DEFAULT_MAX_OUTLIER_RUN,
    on_divergence: str = "reenter",
    robust: str | None = DEFAULT_ROBUST,
    associate: str | Association = DEFAULT_ASSOCIATE,
    align: bool = True,
) -> RunResult:
    """Recover the trajectory from a SLAM result bundle and score it (and its baselines).

    When the recovery fails (``on_divergence="raise"`` on a run where map and log disagree,
    or numerically impossible input), the result still scores dead reckoning (and the online
    estimate) and says why in ``recovery_error``: a report is always written. The map is
    compared with the true landmarks by :func:`map_comparison` (``associate``, ``align``);
    when no association can be made the report says why instead.
    """
    bundle = inp.bundle
    truth = bundle.groundtruth
    if truth is None:
        raise InputError(
            "the bundle has no groundtruth.csv: nothing to score against", path=bundle.path
        )
    _check_truth_overlaps(bundle, truth)
    relations = default_relations(truth, seed=seed)
    sets = relations.sets
    map_cmp, map_notes = None, []
    try:
        map_cmp = map_comparison(bundle, associate=associate, align=align)
    except InputError as exc:  # no pair at all, or maps too small to associate: a finding
        map_notes.append(f"No map comparison: {exc.message}.")
    # the NEES frame's landmark fit on the comparison's pairs (none when it failed)
    frame = _placed(bundle, None) if map_cmp is None else landmark_frame(bundle, map_cmp)[0]
    rec_error = None
    try:
        rec = recover(
            bundle, method=method, max_outlier_run=max_outlier_run,
            on_divergence=on_divergence, robust=robust, nees_frame=frame,
        )  # fmt: skip
    except SlamrelError as exc:  # DivergenceError with on_divergence="raise"
        if isinstance(exc, InputError):
            raise
        rec, rec_error = None, str(exc)
    estimates, nees, nees_truth = _estimates_at_truth(inp, rec, frame)
    notes = _notes(rec, rec_error, method, has_online=inp.online is not None)
    notes += _nees_notes(frame, nees, nees_truth, inp)
    notes += map_notes if map_cmp is None else _map_notes(map_cmp)
    return RunResult(
        name=inp.name,
        bundle=bundle,
        estimates=estimates,
        evaluations={k: _evaluate_sets(sets, est) for k, est in estimates.items()},
        nees=nees,
        recovery_result=rec,
        map_comparison=map_cmp,
        notes=notes,
        recovery_error=rec_error,
        nees_frame=frame,
        nees_truth_frame=nees_truth,
        relation_sets=relations.rules,
    )


def _check_truth_overlaps(bundle: Bundle, truth: Trajectory) -> None:
    """InputError (before any work or output) when no ground-truth time lies in the log's
    span: every score of ``run`` compares estimate poses at ground-truth times."""
    tb = TimeBase.of(bundle)
    lo, hi = truth.span()
    if hi < tb.t0 - 1e-6 or lo > tb.t1 + 1e-6:
        raise InputError(
            f"the ground truth spans [{lo:.9g}, {hi:.9g}] s, the log [{tb.t0:.9g}, "
            f"{tb.t1:.9g}] s: they do not overlap, so there is nothing to score; expected "
            "groundtruth.csv in the time base of the log",
            path=None if bundle.path is None else Path(bundle.path) / "groundtruth.csv",
        )


def sensor_reach(bundle: Bundle) -> SensorReach | None:
    """How far the bundle's sensor sees: declared by its sensor model (``max_range``, ``fov``,
    docs/bundle.md), else the largest range among its measurements, all around (``None``
    without measurements)."""
    s = bundle.sensor
    if s.max_range is not None:
        return SensorReach(s.max_range, s.fov, "declared")
    if bundle.measurements.shape[0] == 0:
        return None
    return SensorReach(float(bundle.measurements[:, 0].max()), None, "largest measured range")


def map_comparison(
    bundle: Bundle,
    *,
    associate: str | Association = DEFAULT_ASSOCIATE,
    align: bool = True,
    cutoff: float = 1.0,
    seed: int = 0,
) -> MapComparison | None:
    """The SLAM map against the bundle's true landmarks (``None`` when it has none).

    :func:`landmark_graph.map_compare.compare_maps` with the frame rule (the map moved onto
    the true landmarks by the fit on the pairs, unless ``align=False``) and ``associate``
    (``"id-or-auto"``, ``"id"``, ``"auto"`` or an association; by id with no shared id, the
    maps are associated automatically, and the notes say so). The true landmarks ever within
    the sensor's reach (:func:`sensor_reach`) of the ground-truth trajectory
    (:func:`landmark_graph.observability.within_reach`) are the observable ones; without
    ground truth or measurements every true landmark is.
    """
    if bundle.landmarks_groundtruth is None:
        return None
    est = LandmarkMap(bundle.map_ids, bundle.map_xy)
    ref = LandmarkMap(*bundle.landmarks_groundtruth)
    reach = sensor_reach(bundle)
    observable = None
    if reach is not None and bundle.groundtruth is not None:
        observable = within_reach(bundle.groundtruth.poses, ref.xy, reach)
    return compare_maps(
        est, ref, associate=associate, cutoff=cutoff, seed=seed, align=align,
        observable=observable, reach=reach, fallback=True,
    )  # fmt: skip


def landmark_frame(
    bundle: Bundle, comparison: MapComparison | None = None
) -> tuple[NeesFrame, Association | None]:
    """The frame to compute NEES in, and the landmark association it was anchored on.

    The SLAM map's landmark pairs with ``landmarks_groundtruth`` are those of the map
    comparison (``comparison``; by default :func:`map_comparison` with its default
    association: by id when the shared ids mostly match, else automatically); the truth ← map
    transform is fitted on them (:func:`recovery.anchoring.anchor_on_landmarks`, the same
    least-squares fit as the comparison's alignment) and reported beside the frame placed by
    the start pose. Without landmark ground truth, or when fewer than 2 pairs are found, there
    is no landmark fit. The association is ``None`` when none was made.
    """
    if bundle.landmarks_groundtruth is None:
        return _placed(bundle, None), None
    if comparison is None:
        try:
            comparison = map_comparison(bundle)
        except SlamrelError as exc:
            del exc  # the map comparison reports it
            return _placed(bundle, None), None
    assert comparison is not None
    assoc = comparison.association
    if assoc.estimate_rows.size < 2:
        return _placed(bundle, None), assoc
    pairs = (comparison.estimate.xy[assoc.estimate_rows],
             comparison.reference.xy[assoc.reference_rows])  # fmt: skip
    how = comparison.association_source
    return _placed(bundle, anchor_on_landmarks(*pairs, association=how)), assoc


def _map_notes(mc: MapComparison) -> list[str]:
    """The report's notes on the map comparison: association, frame, unobserved landmarks."""
    al = mc.alignment
    how = SOURCE_WORDS[mc.association_source]
    text = (
        f"The map is compared with the true landmarks associated {how} "
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


def _placed(bundle: Bundle, map_anchoring: Anchoring | None) -> NeesFrame:
    """The frame placed by the run's start pose (:func:`recovery.anchoring.start_frame`), the
    landmark fit reported beside it."""
    assert bundle.groundtruth is not None
    g0 = truth_at_start(bundle.groundtruth, TimeBase.of(bundle).t0)
    return start_frame(bundle.initial_pose, bundle.initial_covariance, g0, map_anchoring)


def _estimates_at_truth(
    inp: RunInput, rec: Recovery | None, frame: NeesFrame
) -> tuple[dict[str, Trajectory], dict[str, NeesCurve], dict[str, NeesSummary]]:
    """Recovered, dead-reckoning and online estimates at the ground-truth times, and NEES.

    The NEES in ``frame`` (the poses and covariances taken into the truth frame by its
    anchoring first) and, unaligned, in the truth frame (summaries only).
    """
    bundle, truth = inp.bundle, inp.bundle.groundtruth
    assert truth is not None
    dead_reckoning = inp.dead_reckoning
    if dead_reckoning is None:
        steps = build_steps(bundle)
        dead_reckoning = Trajectory(
            steps.times, se2.cumulative_compose(steps.u, start=bundle.initial_pose)
        )
    estimates: dict[str, Trajectory] = {}
    nees: dict[str, NeesCurve] = {}
    unaligned: dict[str, NeesSummary] = {}

    def score(name: str, est: Trajectory, covs: NDArray[np.float64]) -> None:
        # the first pose is the prior (the start pose, known): left out
        poses, covs, ref = est.poses[1:], covs[1:], _truth_at(truth, est.timestamps)[1:]
        v0 = pose_nees(poses, ref, covs)
        unaligned[name] = summarize_nees(v0, dof=3)
        if frame.anchoring is not None:
            poses, covs = frame.anchoring.apply(poses, covs)
        v = v0 if frame.anchoring is None else pose_nees(poses, ref, covs)
        nees[name] = NeesCurve(summarize_nees(v, dof=3), v, est.timestamps[1:])

    if rec is not None:
        recovered, rec_rows = _at_truth_times(rec.trajectory, truth)
        estimates["recovered"] = recovered
        score("recovered", recovered, rec.covariances[rec_rows])
    estimates["dead_reckoning"] = _at_truth_times(dead_reckoning, truth)[0]
    if inp.online is not None:
        online_t, online_rows = _at_truth_times(inp.online, truth)
        estimates["online"] = online_t
        if inp.online_covariance is not None:
            score("online", online_t, inp.online_covariance[online_rows])
    return estimates, nees, unaligned


def _nees_notes(
    frame: NeesFrame,
    nees: dict[str, NeesCurve],
    unaligned: dict[str, NeesSummary],
    inp: RunInput,
) -> list[str]:
    """The report's notes on the NEES: its frame, the anchoring, and a missing online NEES."""
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
    if inp.online is not None and inp.online_covariance is None:
        notes.append(
            "The online estimate has no covariances (online.csv without the columns "
            "cxx,cxy,cxt,cyy,cyt,ctt): there is no online NEES."
        )
    return notes


def _notes(
    rec: Recovery | None, rec_error: str | None, method: str, *, has_online: bool
) -> list[str]:
    """The report's notes: what was recovered (or why nothing), and what the online estimate is."""
    if rec is None:
        notes = [
            f"No trajectory was recovered: {rec_error}. The report scores dead "
            "reckoning" + (" and the online estimate." if has_online else ".")
        ]
    else:
        notes = _recovery_notes(rec, method)
    if has_online:
        notes.append(
            "The online estimate is the EKF-SLAM filter's own pose; it is shown for validation "
            "only (a filter-based SLAM system keeps no trajectory)."
        )
    return notes


def _recovery_notes(rec: Recovery, method: str) -> list[str]:
    counts = rec.counts
    notes = [
        f"The recovered trajectory is EKF localisation in the SLAM run's final map with its "
        f"data associations and models, then smoothed ({method}); it scores the final map, "
        "not the estimate the filter had online.",
        f"Recovery used {counts.used} of {counts.measurements} measurements; "
        f"{counts.gated} were gated ({100 * counts.gated_fraction:.1f}%), "
        f"{counts.unassociated} were unassociated. A large gated fraction is a finding "
        "about the map, not noise.",
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


def _at_truth_times(est: Trajectory, truth: Trajectory) -> tuple[Trajectory, NDArray[np.int64]]:
    """The estimate's poses at the ground-truth times it has (within 1 µs)."""
    at, k = match_nearest_times(truth.timestamps, est.timestamps, 1e-6)
    if not at.size:
        raise InputError(
            "no estimate pose lies at a ground-truth time; are they in the same time base?"
        )
    return Trajectory(truth.timestamps[at], est.poses[k]), k


def _truth_at(truth: Trajectory, t: NDArray[np.float64]) -> NDArray[np.float64]:
    """Ground-truth poses nearest in time to ``t`` (the callers pass ground-truth times)."""
    return truth.poses[nearest_index(truth.timestamps, t)]


def write_report(result: RunResult, directory: str | Path, *, force: bool = True) -> Path:
    """Write the report folder, swapped in whole; returns the path of ``report.html``.

    The folder holds ``bundle/``, ``metrics.json`` (:meth:`RunResult.metrics`, the numbers
    every table of the page shows), ``relations_<estimate>.csv``, ``figure_<k>.png`` and,
    with a map comparison, ``review.html``. ``force``: may an existing report folder (one
    slamrel wrote) be replaced?
    """
    target = Path(directory)
    metrics = result.metrics()
    with staged_directory(target, kind="report", force=force) as tmp:
        write_bundle(tmp / "bundle", result.bundle)
        write_json(tmp / "metrics.json", metrics)
        for name, evs in result.evaluations.items():
            write_per_relation_csv(
                tmp / f"relations_{name}.csv", evs["all"], relation_sets=_set_labels(evs)
            )
        figures = report_figures(result)
        for k, fig in enumerate(figures.in_order()):
            (tmp / f"figure_{k + 1}.png").write_bytes(fig.png)
        review = None
        if result.map_comparison is not None:
            review = _write_review(tmp / "review.html", result)
        sections = report_sections(result, figures, review=review)
        write_text_atomic(
            tmp / "report.html",
            render_html(
                f"slamrel report — {result.name}",
                sections.in_order(),
                verdict=run_verdict(RunFacts.of(result)),
            ),
        )
    return target / "report.html"


def _write_review(path: Path, result: RunResult) -> tuple[str, str]:
    """Write the landmark-association review page; returns its ``(href, text)`` link."""
    from slamrel.review.page import write_review

    mc = result.map_comparison
    assert mc is not None
    write_review(
        path, mc.estimate, mc.reference, mc.association, cutoff=mc.cutoff,
        names=("SLAM map", "true landmarks"), title=f"slamrel review — {result.name}",
    )  # fmt: skip
    return (
        path.name,
        "Review the landmark association in a browser (accept, reject or draw "
        "pairs; save the CSV for slamrel map-compare --associate FILE)",
    )
