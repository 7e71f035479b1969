"""The main job end to end: world → EKF-SLAM → bundle → recovery → relation metric → report.

Three steps, the I/O at the ends (evo's ``main_ape``: load, a pure ``ape``, write):

* :func:`read_run_input` reads a SLAM result bundle directory (and its ``online.csv``), or
  :func:`simulate_run_input` simulates a built-in world and runs the reference EKF-SLAM —
  either gives a :class:`RunInput`;
* :func:`run_pipeline` (and :func:`score_bundle`) recover and score it and return a
  :class:`~slamrel.runs.result.RunResult` (no I/O): the recovery (:mod:`recovery.recover`)
  and the scores against the ground truth (the relation metric; the NEES of
  :mod:`slamrel.runs.nees`), with the report's notes (:mod:`slamrel.report.notes`);
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
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from landmark_graph.constants import DEFAULT_ASSOCIATE
from landmark_graph.landmark_association import Association
from landmark_graph.map_compare import MapComparison, compare_maps
from landmark_graph.maps import LandmarkMap
from landmark_graph.observability import SensorReach, within_reach
from recovery.anchoring import NeesFrame, anchor_on_landmarks
from recovery.bundle import Bundle
from recovery.clock_offset import ClockOffset, clock_offset
from recovery.constants import DEFAULT_MAP_PRIOR
from recovery.recover import DEFAULT_MAX_OUTLIER_RUN, DEFAULT_ROBUST, recover
from recovery.results import Recovery
from recovery.steps import build_steps
from relation_metric import se2
from relation_metric.consistency import NeesSummary
from relation_metric.errors import InputError, SlamrelError
from relation_metric.evaluate import UnassociatedRelationsWarning, evaluate
from relation_metric.relations import RelationSet, generate_relations
from relation_metric.trajectory import Trajectory
from slamrel.backends.ekf_slam import ekf_slam_bundle
from slamrel.constants import EVALUATE_DEFAULTS
from slamrel.formats.bundle import read_bundle, read_online, write_bundle
from slamrel.formats.results import write_json, write_per_relation_csv
from slamrel.formats.trajectories import write_trajectory
from slamrel.outputs import staged_directory, write_text_atomic
from slamrel.report.html import render_html
from slamrel.report.notes import (
    map_notes,
    nees_notes,
    no_truth_notes,
    persisting_notes,
    run_notes,
)
from slamrel.report.run_page import report_figures, report_sections
from slamrel.report.verdict import RunFacts, map_log_stats, run_verdict
from slamrel.runs.nees import (
    NeesCurve,
    PlacementNees,
    at_truth_times,
    estimate_nees,
    map_pairs,
    placed_frame,
    placement_nees,
)
from slamrel.runs.result import ReferenceScores, RelationSetRule, RunResult, SetEvaluations
from slamrel.runs.time_base import TimeBase
from slamrel.simulation.bundles import world_bundle
from slamrel.simulation.worlds import make_world

__all__ = [
    "DefaultRelations",
    "RunInput",
    "default_relations",
    "landmark_frame",
    "map_comparison",
    "read_run_input",
    "run_pipeline",
    "score_bundle",
    "sensor_reach",
    "simulate_run_input",
    "write_report",
]


#: The relation sets ``slamrel run`` scores, and their parameters (:func:`default_relations`).
RELATION_SPACING = 1.0  # s: the reference is thinned to one pose a second, consecutive pairs
LOOP_RADIUS = 1.0  # m
LOOP_MIN_SEPARATION = 20.0  # s
MAX_LOOPS = 5000
GLOBAL_COUNT = 2000


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
        With ground truth (``groundtruth.csv``) the estimates are scored on relations drawn
        from it; without, the report holds what needs no truth (module docstring).
    name : str
        Shown in the report's title.
    online : Trajectory or None
        The SLAM run's own estimate (validation only).
    online_covariance : ndarray, shape (N, 3, 3) or None
        Its pose covariances, one per pose of ``online``.
    dead_reckoning : Trajectory or None
        Odometry alone; ``None``: chained from the bundle's log.
    reference_relations : RelationSet or None
        Reference relations (Freiburg ``.relations``, read as ``slamrel evaluate`` reads
        them) that every estimate is scored on too, with ground truth or without.
    reference_relations_name : str
        Where they came from (the file), for the report.
    reference_map : LandmarkMap or None
        A reference landmark map (a survey) the SLAM map is compared with, for a bundle
        without ``landmarks_groundtruth.csv``.
    """

    bundle: Bundle
    name: str
    online: Trajectory | None = None
    online_covariance: NDArray[np.float64] | None = None
    dead_reckoning: Trajectory | None = None
    reference_relations: RelationSet | None = None
    reference_relations_name: str = ""
    reference_map: LandmarkMap | None = None


def _evaluate_sets(sets: dict[str, RelationSet], est: Trajectory) -> SetEvaluations:
    # estimates are sampled at ground-truth times where they can be (exact association);
    # otherwise (real logs) the nearest pose within 0.1 s, or SE(2) interpolation
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnassociatedRelationsWarning)  # counted in the JSON
        # an empty set is reported as such (relation_sets says why), not refused
        kw: dict[str, Any] = {"max_time_diff": 0.1, "interpolate": True, "allow_empty": True}
        merged = evaluate(_merge(sets), est, **kw)
        return SetEvaluations(merged, {k: evaluate(rel, est, **kw) for k, rel in sets.items()})


def _set_labels(evs: SetEvaluations) -> NDArray[np.str_]:
    """The relation set of each relation of ``evs.all`` (:func:`_evaluate_sets` merged the
    sets in the order of ``evs.sets``), for the ``set`` column of the per-relation CSV."""
    names = evs.sets
    labels = np.repeat(np.array(names, dtype=np.str_), [len(evs[k].relations) for k in names])
    if labels.size != len(evs.all.relations):
        raise RuntimeError("the merged relations are not the relation sets in order")
    return labels


def read_run_input(directory: str | Path, *, skip_invalid_measurements: bool = False) -> RunInput:
    """Read a SLAM result bundle directory to score (the I/O end of ``slamrel run``).

    The bundle (``docs/bundle.md``) is scored against its ``groundtruth.csv`` (required by
    :func:`score_bundle`) and, when present, ``landmarks_groundtruth.csv``; an ``online.csv``
    beside it (written by ``slamrel slam --store-online``) is scored too, and with its
    covariance columns gets an online NEES (:func:`slamrel.formats.bundle.read_online`).
    """
    bundle = read_bundle(directory, skip_invalid_measurements=skip_invalid_measurements)
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
    jacobians: Literal["standard", "fej", "oc"] = "standard",
    iterations: int = 1,
) -> RunInput:
    """Simulate a built-in world and run the reference EKF-SLAM on it (no I/O).

    The input carries the filter's online estimate and covariances (for validation) and the
    world's odometry as dead reckoning. ``corrupt_fraction``, ``noise_scale``,
    ``process_noise_scale``, ``jacobians`` and ``iterations`` are passed to
    :func:`slamrel.backends.ekf_slam.ekf_slam_bundle`.
    """
    w = make_world(world, noise=noise, seed=seed, rate=rate)
    bundle, slam = ekf_slam_bundle(
        world_bundle(w), corrupt_fraction=corrupt_fraction, noise_scale=noise_scale, seed=seed,
        process_noise_scale=process_noise_scale, jacobians=jacobians, iterations=iterations,
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
    map_prior: str | None = None,
    clock_search: bool = True,
) -> RunResult:
    """Run the whole chain on a built-in world, or score a bundle read earlier (no I/O).

    ``source``: a world name (simulated by :func:`simulate_run_input` with ``noise``, ``seed``,
    ``rate``, ``corrupt_fraction``, ``noise_scale``, ``process_noise_scale``), or a
    :class:`RunInput` (e.g. from :func:`read_run_input` for a bundle directory).
    ``max_outlier_run``, ``on_divergence``, ``robust`` and ``map_prior`` (``None``: the
    default of :func:`recovery.recover.recover`, ``auto``: de-conditioned when the bundle
    states that its map was made from its log, so that ``slamrel recover`` gives the same
    bundle the same covariances) are passed to :func:`recovery.recover.recover`, ``associate`` and
    ``align`` to :func:`map_comparison`, ``clock_search`` to :func:`score_bundle`.
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
        map_prior=map_prior, clock_search=clock_search,
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
    map_prior: str | None = None,
    clock_search: bool = True,
) -> RunResult:
    """Recover the trajectory from a SLAM result bundle and score it (and its baselines).

    ``clock_search``: where the map–log lamp is not green, search the measurements' clock
    offset (:func:`_clock_offset`, about ten more filter passes; the verdict's cause sentence
    and ``metrics.json``). Studies that record only scores or the lamps' levels, which the
    search never changes, turn it off.

    When the recovery fails (``on_divergence="raise"`` on a run where map and log disagree,
    or numerically impossible input), the result still scores dead reckoning (and the online
    estimate) and says why in ``recovery_error``: a report is always written. The map is
    compared with the true landmarks (or ``inp.reference_map``) by :func:`map_comparison`
    (``associate``, ``align``); when no association can be made the report says why instead.

    Without ground truth nothing is scored on relations drawn from it and there is no NEES;
    the recovery, where the map and the log disagree, the robust weights' loss, the map
    comparison with a reference map and the scores on ``inp.reference_relations`` need no
    truth and are all there; the online estimate is compared with the recovered one
    (:func:`_online_against_recovered`).
    """
    bundle = inp.bundle
    truth = bundle.groundtruth
    if inp.reference_map is not None and bundle.landmarks_groundtruth is not None:
        raise InputError(
            "the bundle has its own landmarks_groundtruth.csv; a reference map would replace "
            "it: give one or the other",
            path=bundle.path,
        )
    if truth is not None:
        _check_truth_overlaps(bundle, truth)
    relations = None if truth is None else default_relations(truth, seed=seed)
    map_cmp, failed_map = None, []
    try:
        map_cmp = map_comparison(
            bundle, associate=associate, align=align, reference=inp.reference_map
        )
    except InputError as exc:  # no pair at all, or maps too small to associate: a finding
        failed_map.append(f"No map comparison: {exc.message}.")
    rec_error = None
    try:
        rec = recover(
            bundle, method=method, max_outlier_run=max_outlier_run,
            on_divergence=on_divergence, robust=robust,
            map_prior=DEFAULT_MAP_PRIOR if map_prior is None else map_prior,
        )  # fmt: skip
    except SlamrelError as exc:  # DivergenceError with on_divergence="raise"
        if isinstance(exc, InputError):
            raise
        rec, rec_error = None, str(exc)
    own = _own_estimates(inp, rec)
    notes = run_notes(rec, rec_error, method, has_online=inp.online is not None)
    if rec is not None:  # what the recovery carried in its state
        notes += persisting_notes(bundle.sensor, bundle.motion)
    if bundle.skipped_invalid:  # read with --skip-invalid-measurements
        notes.append(
            f"{bundle.skipped_invalid} measurement(s) with a range <= 0 or a non-finite range "
            "or bearing were skipped by the reader (--skip-invalid-measurements) and not used"
        )
    frame, estimates, evaluations = None, own, {}
    nees: dict[str, NeesCurve] = {}
    nees_truth: dict[str, NeesSummary] = {}
    placement = None
    online_vs_recovered = None
    if truth is not None and relations is not None:
        # the NEES frame's landmark fit on the comparison's pairs (none when it failed)
        frame = placed_frame(bundle) if map_cmp is None else landmark_frame(bundle, map_cmp)[0]
        estimates, nees, nees_truth = _estimates_at_truth(inp, own, rec, frame)
        placement = _placement_nees(bundle, rec, map_cmp, frame)
        evaluations = {k: _evaluate_sets(relations.sets, est) for k, est in estimates.items()}
        notes += nees_notes(
            frame, nees, nees_truth,
            online_without_covariances=inp.online is not None and inp.online_covariance is None,
        )  # fmt: skip
        notes += _online_singular_note(inp)
    else:
        online_vs_recovered = _online_against_recovered(own, seed=seed)
        notes += no_truth_notes(
            relations=inp.reference_relations is not None, online=online_vs_recovered is not None
        )
    if map_cmp is None:
        notes += failed_map
    elif inp.reference_map is not None:
        notes += map_notes(map_cmp, reference="the reference map (--reference-map)")
    else:
        notes += map_notes(map_cmp)
    return RunResult(
        name=inp.name,
        bundle=bundle,
        estimates=estimates,
        evaluations=evaluations,
        nees=nees,
        recovery_result=rec,
        map_comparison=map_cmp,
        notes=notes,
        recovery_error=rec_error,
        nees_frame=frame,
        nees_truth_frame=nees_truth,
        nees_placement=placement,
        relation_sets=() if relations is None else relations.rules,
        reference=_reference_scores(inp, own),
        online_vs_recovered=online_vs_recovered,
        clock_offset=_clock_offset(bundle, rec, robust, max_outlier_run) if clock_search else None,
    )


def _clock_offset(
    bundle: Bundle, rec: Recovery | None, robust: str | None, max_outlier_run: int | None
) -> ClockOffset | None:
    """The measurements' clock offset (:func:`recovery.clock_offset.clock_offset`, with the
    recovery's own settings), searched only where the map–log lamp is not green: it costs
    about ten filter passes, and a lamp that is green has no cause to name."""
    if rec is None:
        return None
    st = map_log_stats(rec.nis, rec.counts.gated, bundle.sensor.outlier_share or 0.0)
    if st is None or st.level == "green":
        return None
    return clock_offset(bundle, robust=robust, max_outlier_run=max_outlier_run, first=rec)


def _reference_scores(inp: RunInput, own: dict[str, Trajectory]) -> ReferenceScores | None:
    """Every estimate (whole, at its own times) scored on the reference relations as
    ``slamrel evaluate RELATIONS ESTIMATE`` scores them with its default options."""
    rel = inp.reference_relations
    if rel is None:
        return None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnassociatedRelationsWarning)  # counted in the JSON
        kw: dict[str, Any] = {
            "max_time_diff": EVALUATE_DEFAULTS["max_time_diff"],
            "interpolate": EVALUATE_DEFAULTS["interpolate"],
            "max_interpolation_gap": EVALUATE_DEFAULTS["max_interpolation_gap"],
            "mode": EVALUATE_DEFAULTS["mode"],
            "allow_empty": True,
        }
        scores = {k: evaluate(rel, est, **kw) for k, est in own.items()}
    return ReferenceScores(inp.reference_relations_name, len(rel), scores)


def _online_against_recovered(
    own: dict[str, Trajectory], *, seed: int = 0
) -> SetEvaluations | None:
    """The online estimate scored on relations drawn from the recovered trajectory by
    :func:`default_relations` (without ground truth, the two estimates' difference: not an
    error of either); ``None`` without one of them."""
    rec, online = own.get("recovered"), own.get("online")
    if rec is None or online is None or len(rec) < 2:
        return None
    sets = default_relations(rec, seed=seed).sets
    if not sets:
        return None
    return _evaluate_sets(sets, online)


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
    reference: LandmarkMap | None = None,
) -> MapComparison | None:
    """The SLAM map against the bundle's true landmarks, or the ``reference`` map when given
    (``None`` when there is neither).

    :func:`landmark_graph.map_compare.compare_maps` with the frame rule (the map moved onto
    the true landmarks by the fit on the pairs, unless ``align=False``) and ``associate``
    (``"id-or-auto"``, ``"id"``, ``"auto"`` or an association; by id with no shared id, the
    maps are associated automatically, and the notes say so). The true landmarks ever within
    the sensor's reach (:func:`sensor_reach`) of the ground-truth trajectory
    (:func:`landmark_graph.observability.within_reach`) are the observable ones; without
    ground truth or measurements every true landmark is.
    """
    ref = reference
    if ref is None:
        if bundle.landmarks_groundtruth is None:
            return None
        ref = LandmarkMap(*bundle.landmarks_groundtruth)
    est = LandmarkMap(bundle.map_ids, bundle.map_xy)
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
        return placed_frame(bundle), None
    if comparison is None:
        try:
            comparison = map_comparison(bundle)
        except SlamrelError as exc:
            del exc  # the map comparison reports it
            return placed_frame(bundle), None
    assert comparison is not None
    assoc = comparison.association
    if assoc.estimate_rows.size < 2:
        return placed_frame(bundle), assoc
    pairs = (comparison.estimate.xy[assoc.estimate_rows],
             comparison.reference.xy[assoc.reference_rows])  # fmt: skip
    how = comparison.association_source
    return placed_frame(bundle, anchor_on_landmarks(*pairs, association=how)), assoc


def _own_estimates(inp: RunInput, rec: Recovery | None) -> dict[str, Trajectory]:
    """The recovered (when a recovery ran), dead-reckoning and online (when given) estimates,
    whole, at their own times; dead reckoning chained from the log when the input has none."""
    bundle = inp.bundle
    dead_reckoning = inp.dead_reckoning
    if dead_reckoning is None:
        steps = build_steps(bundle)
        dead_reckoning = Trajectory(
            steps.times, se2.cumulative_compose(steps.u, start=bundle.initial_pose)
        )
    own: dict[str, Trajectory] = {}
    if rec is not None:
        own["recovered"] = rec.trajectory
    own["dead_reckoning"] = dead_reckoning
    if inp.online is not None:
        own["online"] = inp.online
    return own


def _placement_nees(
    bundle: Bundle, rec: Recovery | None, map_cmp: MapComparison | None, frame: NeesFrame
) -> PlacementNees | None:
    """The recovered NEES conditioned on the map's placement
    (:func:`slamrel.runs.nees.placement_nees`), fitted on the map comparison's pairs with the
    true landmarks; ``None`` where it is not defined."""
    if rec is None or map_cmp is None or bundle.landmarks_groundtruth is None:
        return None
    return placement_nees(bundle, rec, frame, *map_pairs(map_cmp, frame))


def _estimates_at_truth(
    inp: RunInput, own: dict[str, Trajectory], rec: Recovery | None, frame: NeesFrame
) -> tuple[dict[str, Trajectory], dict[str, NeesCurve], dict[str, NeesSummary]]:
    """Recovered, dead-reckoning and online estimates (``own``, :func:`_own_estimates`) at
    the ground-truth times, and NEES.

    The NEES of each estimate with covariances (:func:`slamrel.runs.nees.estimate_nees`) in
    ``frame`` and, unaligned, in the truth frame (summaries only).
    """
    truth = inp.bundle.groundtruth
    assert truth is not None
    estimates: dict[str, Trajectory] = {}
    nees: dict[str, NeesCurve] = {}
    unaligned: dict[str, NeesSummary] = {}

    def score(name: str, est: Trajectory, covs: NDArray[np.float64]) -> None:
        nees[name], unaligned[name] = estimate_nees(truth, est, covs, frame)

    if rec is not None:
        recovered, rec_rows = _at_truth_times(own["recovered"], truth)
        estimates["recovered"] = recovered
        score("recovered", recovered, rec.covariances[rec_rows])
    estimates["dead_reckoning"] = _at_truth_times(own["dead_reckoning"], truth)[0]
    if "online" in own:
        online_t, online_rows = _at_truth_times(own["online"], truth)
        estimates["online"] = online_t
        if inp.online_covariance is not None:
            covs = inp.online_covariance[online_rows]
            ok = positive_definite_rows(covs)  # zero or singular rows: no NEES (counted)
            if ok.any():
                kept = Trajectory(online_t.timestamps[ok], online_t.poses[ok])
                score("online", kept, covs[ok])
    return estimates, nees, unaligned


def positive_definite_rows(covs: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Which of the (N, 3, 3) covariances are positive definite (a zero or singular one,
    as filters write for their first steps, has no NEES), (N,)."""
    if covs.shape[0] == 0:
        return np.zeros(0, dtype=bool)
    return np.asarray(np.linalg.eigvalsh(0.5 * (covs + covs.transpose(0, 2, 1)))[:, 0] > 0.0)


def _online_singular_note(inp: RunInput) -> list[str]:
    """The note counting the online poses whose covariance is zero or singular (no NEES)."""
    if inp.online_covariance is None:
        return []
    n = int((~positive_definite_rows(inp.online_covariance)).sum())
    if not n:
        return []
    return [
        f"online NEES: {n} of {inp.online_covariance.shape[0]} online poses have a zero or "
        "singular covariance (online.csv) and no NEES; they are skipped, the others scored"
    ]


def _at_truth_times(est: Trajectory, truth: Trajectory) -> tuple[Trajectory, NDArray[np.int64]]:
    """The estimate's poses at the ground-truth times it has (within 1 µs); every score of
    ``run`` needs them."""
    got = at_truth_times(est, truth)
    if got is None:
        raise InputError(
            "no estimate pose lies at a ground-truth time; are they in the same time base?"
        )
    return got


def write_report(result: RunResult, directory: str | Path, *, force: bool = True) -> Path:
    """Write the report folder, swapped in whole; returns the path of ``report.html``.

    The folder holds ``bundle/``, ``metrics.json`` (:meth:`RunResult.metrics`, the numbers
    every table of the page shows), ``recovered.txt`` (the recovered trajectory at every
    pose, as ``slamrel recover -o recovered.txt`` writes it), ``relations_<estimate>.csv``
    (with ground truth), ``figure_<k>.png`` and, with a map comparison, ``review.html``.
    ``force``: may an existing report folder (one slamrel wrote) be replaced?
    """
    target = Path(directory)
    metrics = result.metrics()
    with staged_directory(target, kind="report", force=force) as tmp:
        write_bundle(tmp / "bundle", result.bundle)
        write_json(tmp / "metrics.json", metrics)
        if result.recovery_result is not None:  # whole, as `slamrel recover -o FILE.txt`
            write_trajectory(tmp / "recovered.txt", result.recovery_result.trajectory)
        for name, evs in result.evaluations.items():
            write_per_relation_csv(
                tmp / f"relations_{name}.csv", evs.all, relation_sets=_set_labels(evs)
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
