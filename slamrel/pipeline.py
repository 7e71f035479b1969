"""The main job end to end: world → EKF-SLAM → bundle → recovery → relation metric → report.

:func:`run_pipeline` computes everything and returns a :class:`RunResult` (no I/O);
:func:`write_report` writes it atomically into a report folder (``report.html``,
``metrics.json``, per-relation CSVs, figures).

The trajectory is scored on three relation sets generated from the ground truth — consecutive
(local), loop-closing and global (far-apart) — because local relations alone cannot see
global breakage (DESIGN.md, measured pitfalls). Dead reckoning is scored the same way as the
baseline everyone understands; the SLAM run's online estimate is scored *for validation only*
(a filter-based SLAM system does not keep it).
"""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from landmark_graph.compare import MapComparison, compare_maps
from landmark_graph.maps import LandmarkMap
from landmark_graph.plots import map_figure
from recovery.bundle import Bundle, read_bundle, write_bundle
from recovery.recover import DEFAULT_MAX_OUTLIER_RUN, DEFAULT_ROBUST, recover
from recovery.steps import build_steps
from relation_metric import se2
from relation_metric.association import match_nearest_times, nearest_index
from relation_metric.consistency import NeesSummary, pose_nees, summarize_nees
from relation_metric.errors import InputError, SlamrelError
from relation_metric.evaluate import Evaluation, UnassociatedRelationsWarning, evaluate
from relation_metric.formats import read_trajectory
from relation_metric.outputs import staged_directory, write_text_atomic
from relation_metric.plots import evaluation_figure
from relation_metric.relations import RelationSet, generate_relations
from relation_metric.results import write_per_relation_csv
from relation_metric.trajectory import Trajectory
from slamrel.figures import (
    mark_stretches_time,
    mark_stretches_xy,
    nees_figure,
    trajectories_figure,
)
from slamrel.report import Figure, Section, Table, figure_png, render_html
from slamrel.simulate import slam_bundle, world_bundle
from slamrel.verdict import run_verdict
from slamrel.worlds import make_world

__all__ = ["RunResult", "default_relations", "run_pipeline", "write_report"]


def default_relations(reference: Trajectory, *, seed: int = 0) -> dict[str, RelationSet]:
    """Consecutive (1 s apart), loop-closing and global relations from the ground truth.

    On the reference sampled at about one pose a second. Loops: poses within 1 m that are at
    least 20 s apart (at most 5000, a seeded subset); global: 2000 random pairs at least a
    quarter of the trajectory's extent apart.
    """
    t = reference.timestamps
    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    step = max(1, int(round(1.0 / dt)))
    # one pose a second: dense ground truth (e.g. 100 Hz Vicon) would give millions of pairs
    coarse = Trajectory(t[::step], reference.poses[::step])
    loops = generate_relations(coarse, "loops", radius=1.0, min_separation_time=20.0)
    if len(loops) > 5000:  # a seeded, uniform subset keeps reports fast on long runs
        pick = np.sort(np.random.default_rng(seed).choice(len(loops), 5000, replace=False))
        loops = loops.subset(pick)
    sets = {
        "consecutive": generate_relations(coarse, "consecutive"),
        "loops": loops,
        "global": generate_relations(coarse, "global", count=2000, seed=seed),
    }
    return {k: v for k, v in sets.items() if len(v)}


def _merge(sets: dict[str, RelationSet]) -> RelationSet:
    parts = list(sets.values())
    return RelationSet(
        np.concatenate([p.first for p in parts]),
        np.concatenate([p.second for p in parts]),
        np.concatenate([p.delta for p in parts]),
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
    nees : dict of name → (NeesSummary, per-step NEES)
    recovery : dict
        Counts of measurements used / gated / unassociated.
    map : dict or None
        The landmark-map comparison (``slamrel map-compare`` JSON), when available.
    notes : list of str
    recovery_error : str or None
        Why no trajectory was recovered (``--fail-on-divergence``, or numerically impossible
        input); the report then scores dead reckoning (and the online estimate).
    """

    name: str
    bundle: Bundle
    estimates: dict[str, Trajectory]
    evaluations: dict[str, dict[str, Evaluation]]
    nees: dict[str, tuple[NeesSummary, np.ndarray]]
    recovery: dict[str, Any]
    map: dict[str, Any] | None
    notes: list[str] = field(default_factory=list)
    map_comparison: MapComparison | None = None
    recovery_error: str | None = None

    def metrics(self) -> dict[str, Any]:
        """The ``metrics.json`` structure."""
        out: dict[str, Any] = {}
        main_name = next(
            k for k in ("recovered", "online", "dead_reckoning") if k in self.evaluations
        )
        for name, evs in self.evaluations.items():
            key = "trajectory" if name == main_name else name
            out[key] = evs["all"].as_dict()
            out[key]["by_relation_set"] = {k: v.as_dict() for k, v in evs.items() if k != "all"}
        out["trajectory_source"] = main_name
        out["map"] = self.map
        out["recovery"] = self.recovery
        out["divergence"] = self.recovery.get("divergence")
        out["recovery_error"] = self.recovery_error
        out["nees"] = {k: v[0].as_dict() for k, v in self.nees.items()}
        out["notes"] = self.notes
        return out


def _evaluate_sets(sets: dict[str, RelationSet], est: Trajectory) -> dict[str, Evaluation]:
    # estimates are sampled at ground-truth times where they can be (exact association);
    # otherwise (real logs) the nearest pose within 0.1 s, or SE(2) interpolation
    kw = {"max_time_diff": 0.1, "interpolate": True}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnassociatedRelationsWarning)  # counted in the JSON
        out = {"all": evaluate(_merge(sets), est, **kw)}  # type: ignore[arg-type]
        for k, rel in sets.items():
            out[k] = evaluate(rel, est, **kw)  # type: ignore[arg-type]
    return out


def run_pipeline(
    source: str = "simple1",
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
) -> RunResult:
    """Run the whole chain on a built-in world, or score a SLAM result bundle directory.

    A world name simulates the world, runs the reference EKF-SLAM and scores its bundle (with
    the filter's online estimate for validation). A directory is read as a SLAM result bundle
    (``../shared/BUNDLE.md``) and scored against its ``groundtruth.csv`` (required) and, when
    present, ``landmarks_groundtruth.csv``; an ``online.csv`` beside it (written by
    ``slamrel slam --store-online``) is scored too. ``max_outlier_run``, ``on_divergence``
    and ``robust`` are passed to :func:`recovery.recover.recover`; ``process_noise_scale`` to
    :func:`slamrel.simulate.slam_bundle` (worlds only).
    """
    if Path(source).is_dir():
        bundle = read_bundle(source)
        online_path = Path(source) / "online.csv"
        online_traj = (
            read_trajectory(online_path, format="csv").trajectory if online_path.is_file() else None
        )
        return score_bundle(
            bundle,
            name=str(source),
            seed=seed,
            method=method,
            max_outlier_run=max_outlier_run,
            online=online_traj,
            on_divergence=on_divergence,
            robust=robust,
        )
    world = make_world(source, noise=noise, seed=seed, rate=rate)
    log = world_bundle(world)
    bundle, slam = slam_bundle(
        log, corrupt_fraction=corrupt_fraction, noise_scale=noise_scale, seed=seed,
        process_noise_scale=process_noise_scale,
    )  # fmt: skip
    return score_bundle(
        bundle, name=f"{source}/{noise}/seed {seed}", seed=seed, method=method,
        max_outlier_run=max_outlier_run, online=slam.online,
        online_covariance=slam.online_covariance, dead_reckoning=world.odometry,
        on_divergence=on_divergence, robust=robust,
    )  # fmt: skip


def score_bundle(
    bundle: Bundle,
    *,
    name: str,
    seed: int = 0,
    method: str = "smoother",
    max_outlier_run: int | None = DEFAULT_MAX_OUTLIER_RUN,
    online: Trajectory | None = None,
    online_covariance: NDArray[np.float64] | None = None,
    dead_reckoning: Trajectory | None = None,
    on_divergence: str = "reenter",
    robust: str | None = DEFAULT_ROBUST,
) -> RunResult:
    """Recover the trajectory from a SLAM result bundle and score it (and its baselines).

    When the recovery fails (``on_divergence="raise"`` on a run where map and log disagree,
    or numerically impossible input), the result still scores dead reckoning (and the online
    estimate) and says why in ``recovery_error``: a report is always written.
    """
    truth = bundle.groundtruth
    if truth is None:
        raise InputError(
            "the bundle has no groundtruth.csv: nothing to score against", path=bundle.path
        )
    sets = default_relations(truth, seed=seed)
    rec_error = None
    try:
        rec = recover(
            bundle,
            method=method,
            max_outlier_run=max_outlier_run,
            on_divergence=on_divergence,
            robust=robust,
        )
    except SlamrelError as exc:  # DivergenceError with on_divergence="raise"
        if isinstance(exc, InputError):
            raise
        rec, rec_error = None, str(exc)
    if dead_reckoning is None:
        steps = build_steps(bundle)
        dead_reckoning = Trajectory(
            steps.times, se2.cumulative_compose(steps.u, start=bundle.initial_pose)
        )
    estimates: dict[str, Trajectory] = {}
    nees: dict[str, tuple[NeesSummary, np.ndarray]] = {}
    if rec is not None:
        recovered, rec_rows = _at_truth_times(rec.trajectory, truth)
        estimates["recovered"] = recovered
        truth_at = _truth_at(truth, recovered.timestamps)
        nees_rec = pose_nees(recovered.poses[1:], truth_at[1:], rec.covariances[rec_rows][1:])
        nees["recovered"] = (summarize_nees(nees_rec, dof=3), nees_rec)
    estimates["dead_reckoning"] = _at_truth_times(dead_reckoning, truth)[0]
    if online is not None:
        online_t, online_rows = _at_truth_times(online, truth)
        estimates["online"] = online_t
        if online_covariance is not None:
            v = pose_nees(
                online_t.poses[1:],
                _truth_at(truth, online_t.timestamps)[1:],
                online_covariance[online_rows][1:],
            )
            nees["online"] = (summarize_nees(v, dof=3), v)
    evaluations = {k: _evaluate_sets(sets, est) for k, est in estimates.items()}
    map_cmp = None
    if bundle.landmarks_groundtruth is not None:
        gt_ids, gt_xy = bundle.landmarks_groundtruth
        map_cmp = compare_maps(
            LandmarkMap(bundle.map_ids, bundle.map_xy), LandmarkMap(gt_ids, gt_xy)
        )
    notes = _recovery_notes(rec, method) if rec is not None else [
        f"No trajectory was recovered: {rec_error}. The report scores dead reckoning"
        + (" and the online estimate." if online is not None else ".")
    ]  # fmt: skip
    if online is not None:
        notes.append(
            "The online estimate is the EKF-SLAM filter's own pose; it is shown for validation "
            "only (a filter-based SLAM system keeps no trajectory)."
        )
    return RunResult(
        name=name,
        bundle=bundle,
        estimates=estimates,
        evaluations=evaluations,
        nees=nees,
        recovery=rec.report() if rec is not None else {},
        map=None if map_cmp is None else map_cmp.as_dict(),
        notes=notes,
        map_comparison=map_cmp,
        recovery_error=rec_error,
    )


def _recovery_notes(rec: Any, method: str) -> list[str]:
    counts = rec.counts
    notes = [
        f"The recovered trajectory is EKF localisation in the SLAM run's final map with its "
        f"data associations and models, then smoothed ({method}); it scores the final map, "
        "not the estimate the filter had online.",
        f"Recovery used {int(counts['used'])} of {int(counts['measurements'])} measurements; "
        f"{int(counts['gated'])} were gated ({100 * counts['gated_fraction']:.1f}%), "
        f"{int(counts['unassociated'])} were unassociated. A large gated fraction is a finding "
        "about the map, not noise.",
    ]
    if counts.get("downweighted"):
        notes.append(
            f"The robust update down-weighted {int(counts['downweighted'])} measurements "
            f"({100 * counts['downweighted_fraction']:.1f}%, weight lost "
            f"{100 * counts['downweight_loss']:.1f}%); like a gated fraction, a large loss is a "
            "finding about the map."
        )
    d = rec.divergence
    if d.get("stretches"):
        notes.append(
            f"The map and the log DISAGREE on {len(d['stretches'])} stretch(es) covering "
            f"{100 * d['fraction_of_log']:.1f}% of the log (runs of innovations beyond the "
            f"χ² bound {d['outlier_bound']:.2f}; mean NIS {rec.nis_stats['mean']:.3g}, 2 "
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


def _stats_table(result: RunResult, part: str) -> Table:
    rows = []
    for name, evs in result.evaluations.items():
        for set_name, ev in evs.items():
            s = getattr(ev, part)["abs"]
            q = getattr(ev, part)["sqr"]
            rows.append([name, set_name, s.mean, s.std, q.mean, s.max, s.count])
    unit = "m" if part == "translation" else "rad"
    return Table(
        f"{part} relation error [{unit}]",
        [
            "estimate",
            "relations",
            f"abs mean [{unit}]",
            f"abs std [{unit}]",
            f"sqr mean [{unit}²]",
            f"abs max [{unit}]",
            "count",
        ],
        rows,
    )


def _divergence_section(result: RunResult) -> Section:
    """Where the map and the log disagree (stretches, NIS), or why nothing was recovered."""
    if result.recovery_error is not None:
        return Section(
            "Map–log agreement",
            paragraphs=[f"No trajectory was recovered: {result.recovery_error}"],
        )
    d = result.recovery.get("divergence") or {}
    nis = result.recovery.get("nis") or {}
    st = d.get("stretches") or []
    paragraphs = [
        "EKF localisation in the final map checks every innovation against its covariance: "
        f"a stretch is a run of at least {d.get('max_outlier_run') or 'the default number of'} "
        f"consecutive innovations with NIS beyond the χ² bound {d.get('outlier_bound', 0.0):.2f}"
        " (2 dof). Divergence is a finding about the map (or the models), not an error: "
        "the filter was re-entered after each run (its pose covariance inflated) and went on, "
        "and the scores above include these stretches.",
        f"Rule: {d.get('rule', '')}.",
        (
            f"{len(st)} stretch(es), {100 * float(d.get('fraction_of_log', 0.0)):.1f}% of the log, "
            f"{100 * float(d.get('fraction_of_measurements', 0.0)):.1f}% of the measurements."
            if st
            else "The map and the log agree: no stretch of outlying innovations."
        ),
    ]
    ns = d.get("nees_stretches") or []
    if ns:
        paragraphs.append(
            f"Against the ground truth, the recovered pose's NEES exceeds its 99.99% χ² bound "
            f"(3 dof) on {len(ns)} stretch(es): "
            + ", ".join(f"[{s['t0']:.6g}, {s['t1']:.6g}] s" for s in ns[:10])
            + (" …" if len(ns) > 10 else "")
            + "."
        )
    rows = [
        [s["t0"], s["t1"], s["duration"], s["measurements"], s["outlying"], s["nis_median"],
         s["nis_max"], s["reentries"]]
        for s in st[:50]
    ]  # fmt: skip
    if len(st) > 50:
        paragraphs.append(f"The first 50 of {len(st)} stretches are listed; all in metrics.json.")
    tables = [
        Table(
            "NIS of the recovery's innovations (2 dof)",
            ["measurements", "mean", "median", "expected mean", "beyond 95%", "beyond bound"],
            [
                [
                    nis.get("count"),
                    nis.get("mean"),
                    nis.get("median"),
                    2.0,
                    nis.get("fraction_beyond_95"),
                    nis.get("fraction_beyond_bound"),
                ]
            ],
        ),  # fmt: skip
    ]
    if rows:
        tables.append(
            Table(
                "stretches where the map and the log disagree (times in s)",
                [
                    "t0",
                    "t1",
                    "duration",
                    "measurements",
                    "outlying",
                    "NIS median",
                    "NIS max",
                    "re-entries",
                ],
                rows,
            )  # fmt: skip
        )
    return Section("Map–log agreement", paragraphs=paragraphs, tables=tables)


def write_report(result: RunResult, directory: str | Path, *, force: bool = True) -> Path:
    """Write the report folder, swapped in whole; returns the path of ``report.html``.

    ``force``: may an existing report folder (one slamrel wrote) be replaced?
    """
    target = Path(directory)
    metrics = result.metrics()
    truth = result.bundle.groundtruth
    assert truth is not None
    with staged_directory(target, kind="report", force=force) as tmp:
        write_bundle(tmp / "bundle", result.bundle)
        write_text_atomic(
            tmp / "metrics.json", json.dumps(metrics, indent=2, allow_nan=False) + "\n"
        )
        for name, evs in result.evaluations.items():
            write_per_relation_csv(tmp / f"relations_{name}.csv", evs["all"])
        main_name = metrics["trajectory_source"]
        stretches = (result.recovery.get("divergence") or {}).get("stretches") or []
        figs = [
            Figure(
                "Estimates against the ground truth, with the true landmarks and the SLAM map",
                figure_png(
                    mark_stretches_xy(
                        trajectories_figure(
                            truth,
                            result.estimates,
                            landmarks=result.bundle.landmarks_groundtruth[1]
                            if result.bundle.landmarks_groundtruth
                            else None,
                            mapped=result.bundle.map_xy,
                        ),
                        stretches,
                        result.estimates.get("recovered"),
                    )
                ),
            ),
            Figure(
                f"The {main_name} trajectory coloured by relation error (all relation sets), "
                "and the errors over time",
                figure_png(
                    mark_stretches_time(
                        evaluation_figure(
                            result.evaluations[main_name]["all"], result.estimates[main_name]
                        ),
                        stretches,
                        result.evaluations[main_name]["all"],
                    )
                ),
            ),
        ]
        nees_curves = {k: v[1] for k, v in result.nees.items()}
        nees_sum = {k: v[0] for k, v in result.nees.items()}
        figs.append(
            Figure(
                "NEES over time with the 95% χ² band (3 dof)",
                figure_png(nees_figure(truth.timestamps[1:], nees_curves, nees_sum)),
            )
        )
        map_figs = []
        if result.map_comparison is not None:
            map_figs.append(
                Figure(
                    "The SLAM map against the true landmarks: the Delaunay mesh of the true "
                    "landmarks, each edge coloured by its length error",
                    figure_png(map_figure(result.map_comparison)),
                )
            )
        figs += map_figs
        for k, fig in enumerate(figs):
            (tmp / f"figure_{k + 1}.png").write_bytes(fig.png)
        review_links = []
        if result.map_comparison is not None:
            from landmark_graph.review import write_review

            mc = result.map_comparison
            write_review(
                tmp / "review.html", mc.estimate, mc.reference, mc.association, cutoff=mc.cutoff,
                names=("SLAM map", "true landmarks"), title=f"slamrel review — {result.name}",
            )  # fmt: skip
            review_links.append(
                (
                    "review.html",
                    "Review the landmark association in a browser (accept, reject or draw "
                    "pairs; save the CSV for slamrel map-compare --associate FILE)",
                )
            )
        sections = [
            Section(
                f"slamrel run: {result.name}",
                paragraphs=[
                    "Relation metric (Kümmerle et al. 2009): relative motions of each estimate "
                    "against ground-truth relations, ε = 1/N Σ ‖δ_ij ⊖ δ*_ij‖².",
                    *result.notes,
                ],
                tables=[_stats_table(result, "translation"), _stats_table(result, "rotation")],
                figures=figs[:2],
            ),
            Section(
                "Consistency",
                tables=[
                    Table(
                        "NEES (3 dof) of the pose estimates",
                        ["estimate", "mean", "band low", "band high", "fraction inside"],
                        [[k, v.mean, v.band[0], v.band[1], v.inside] for k, v in nees_sum.items()],
                    )
                ],
                figures=figs[2:3],
            ),
        ]
        sections.append(_divergence_section(result))
        if result.map is not None:
            mp = result.map
            sections.append(
                Section(
                    "Map",
                    paragraphs=[
                        "Relations of the landmark map: the Delaunay mesh over the true "
                        "landmarks; per edge the length error, per triangle corner the angle "
                        "error — local and independent of the map's frame.",
                    ],
                    tables=[
                        Table(
                            "landmark-map relation errors",
                            ["relation", "abs mean", "abs std", "abs max", "count"],
                            [
                                ["edge length [m]"]
                                + [
                                    mp["translation"]["abs"][k]
                                    for k in ("mean", "std", "max", "count")
                                ],
                                ["corner angle [rad]"]
                                + [
                                    mp["rotation"]["abs"][k]
                                    for k in ("mean", "std", "max", "count")
                                ],
                            ],
                        ),
                        Table(
                            "association and set distances",
                            [
                                "matched",
                                "missed",
                                "spurious",
                                "OSPA [m]",
                                "GOSPA [m]",
                                "c [m]",
                                "p",
                            ],
                            [
                                [
                                    mp["association"]["matched"],
                                    mp["association"]["missed"],
                                    mp["association"]["spurious"],
                                    mp["ospa"]["value"],
                                    mp["gospa"]["value"],
                                    mp["ospa"]["c"],
                                    mp["ospa"]["p"],
                                ]
                            ],
                        ),
                    ],
                    figures=figs[3:],
                    links=review_links,
                )
            )
        write_text_atomic(
            tmp / "report.html",
            render_html(
                f"slamrel report — {result.name}",
                sections,
                verdict=run_verdict(metrics, {k: v[1] for k, v in result.nees.items()}),
            ),
        )
    return target / "report.html"
