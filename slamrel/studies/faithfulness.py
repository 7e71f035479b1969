"""Is the recovery faithful? Monte Carlo study of recovered vs. online trajectories.

Over seeded runs of the reference EKF-SLAM with different noise types, process-noise tunings
and deliberately degraded maps (a fraction of the data associations corrupted), the relation
metric of the trajectory recovered from each run's final map should rank the runs as the
relation metric of the trajectory the filter estimated online does.
:func:`faithfulness_study` runs the pipeline for every configuration with the CLI's default
recovery (no innovation gate; stretches of disagreement re-entered and reported) and returns
both scores per run; Kendall's τ measures the agreement of the two rankings.
:func:`tuning_study` is the grid over process-noise scale × wrong associations: a broken
map must keep its error however the filter was tuned, and a healthy but mis-tuned run must
not look broken.

Two scores, two questions: the online error is what the filter estimated while it ran; the
recovered error is how well the *final map* (with the run's models and associations)
localises the log. For a healthy, well-tuned run the final map is better than the map the
filter had early on, so the recovered error is lower; for a mis-tuned filter the recovery
inherits the tuning (it uses the same models), so the two can differ either way without the
map being broken. A broken map (wrong associations) must never look healthy: its recovered
error stays of the order of its online error (docs/design.md, measured pitfalls).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.stats import kendalltau

from slamrel.pipeline import run_pipeline

__all__ = [
    "PROCESS_NOISE_SCALES",
    "WRONG_ASSOCIATIONS",
    "FaithfulnessStudy",
    "faithfulness_study",
    "tuning_study",
    "RECOVERY_VARIANTS",
    "ate_at_reference_times",
    "relation_error_1s",
    "relation_error_loops",
    "recovery_variants_table",
]

#: The validation grid: process-noise scale of the EKF-SLAM filter × wrong associations.
PROCESS_NOISE_SCALES = (0.03, 0.1, 0.3, 1.0, 10.0)
WRONG_ASSOCIATIONS = (0.0, 0.002, 0.005, 0.01, 0.02)


@dataclass(frozen=True)
class FaithfulnessStudy:
    """Per-run mean translational relation errors of the online and recovered trajectories.

    Attributes
    ----------
    configs : list of dict
        ``{"noise", "corrupt_fraction", "process_noise_scale", "seed"}`` per run.
    online, recovered : dict of relation set → ndarray, shape (R,)
        Mean translational error per run on ``"global"`` (far-apart) and ``"consecutive"``
        relations.
    disagreement : ndarray, shape (R,)
        Fraction of the log the recovery reported as map/log disagreement.
    """

    world: str
    configs: list[dict[str, object]]
    online: dict[str, NDArray[np.float64]]
    recovered: dict[str, NDArray[np.float64]]
    disagreement: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))

    def kendall_tau(self, relations: str = "global") -> float:
        """Kendall's τ (τ-b) between the online and the recovered ranking of the runs."""
        return float(kendalltau(self.online[relations], self.recovered[relations]).statistic)

    def ratio(self, relations: str = "global") -> NDArray[np.float64]:
        """Recovered / online mean error per run."""
        return self.recovered[relations] / self.online[relations]

    @property
    def broken(self) -> NDArray[np.bool_]:
        """Runs with wrong data associations (a broken map)."""
        return np.array([float(c["corrupt_fraction"]) > 0 for c in self.configs])  # type: ignore[arg-type]

    def separation(self, relations: str = "global") -> float:
        """P(recovered error of a broken run > that of a healthy run), over all such pairs.

        The rank statistic suited to the question a user asks of the recovered score (is this
        map broken?) when the healthy runs' errors differ by less than their run-to-run
        spread, which makes τ among them a coin toss: 1 means every broken run scores worse
        than every healthy one (the Mann–Whitney AUC).
        """
        b, h = self.recovered[relations][self.broken], self.recovered[relations][~self.broken]
        if not b.size or not h.size:
            return float("nan")
        return float((b[:, None] > h[None, :]).mean() + 0.5 * (b[:, None] == h[None, :]).mean())

    def summary(self) -> dict[str, Any]:
        """τ (far-apart, consecutive), separation, ratio bounds for broken and healthy runs."""
        r = self.ratio("global")
        return {
            "runs": len(self.configs),
            "kendall_tau_global": self.kendall_tau("global"),
            "kendall_tau_consecutive": self.kendall_tau("consecutive"),
            "separation_global": self.separation("global"),
            "ratio_broken_min": float(r[self.broken].min()) if self.broken.any() else None,
            "ratio_healthy_max": float(r[~self.broken].max()) if (~self.broken).any() else None,
        }


def faithfulness_study(
    world: str = "complex1",
    *,
    noises: Sequence[str] = ("a", "b", "c"),
    corruptions: Sequence[float] = (0.0, 0.01, 0.02, 0.04),
    seeds: Sequence[int] = (0, 1),
    process_noise_scales: Sequence[float] = (1.0,),
    recovery: dict[str, Any] | None = None,
) -> FaithfulnessStudy:
    """Run the pipeline for every (seed, noise, process-noise scale, corruption).

    ``recovery``: keyword arguments for :func:`slamrel.pipeline.run_pipeline`'s recovery
    (``max_outlier_run``, ``robust``, …); default: the CLI's default recovery.
    """
    configs: list[dict[str, object]] = []
    rows: list[list[float]] = []
    for seed, noise, scale, corrupt in itertools.product(
        seeds, noises, process_noise_scales, corruptions
    ):
        r = run_pipeline(
            world,
            noise=noise,
            seed=seed,
            corrupt_fraction=corrupt,
            process_noise_scale=scale,
            clock_search=False,  # scores only: the search changes none
            **(recovery or {}),
        )
        configs.append(
            {
                "noise": noise,
                "corrupt_fraction": corrupt,
                "process_noise_scale": scale,
                "seed": seed,
            }
        )
        rows.append(
            [
                r.evaluations[k][s].translation.abs.mean
                for k in ("online", "recovered")
                for s in ("global", "consecutive")
            ]
            + [0.0 if r.agreement is None else r.agreement.fraction_of_log]
        )
    a = np.asarray(rows)
    return FaithfulnessStudy(
        world=world,
        configs=configs,
        online={"global": a[:, 0], "consecutive": a[:, 1]},
        recovered={"global": a[:, 2], "consecutive": a[:, 3]},
        disagreement=a[:, 4],
    )


def tuning_study(
    world: str = "complex1",
    *,
    noise: str = "b",
    seeds: Sequence[int] = (3,),
    process_noise_scales: Sequence[float] = PROCESS_NOISE_SCALES,
    corruptions: Sequence[float] = WRONG_ASSOCIATIONS,
    recovery: dict[str, Any] | None = None,
) -> FaithfulnessStudy:
    """Faithfulness over the filter's tuning as well as association errors.

    EKF-SLAM runs over process-noise scale × wrong associations (default: the 5 × 5 grid
    :data:`PROCESS_NOISE_SCALES` × :data:`WRONG_ASSOCIATIONS`), recovered with the CLI's
    default recovery.
    """
    return faithfulness_study(
        world,
        noises=(noise,),
        corruptions=corruptions,
        seeds=seeds,
        process_noise_scales=process_noise_scales,
        recovery=recovery,
    )


#: Recovery variants compared on real data (keyword arguments of ``recover``): the plain EKF
#: and the 99.9%-gated EKF as they were (no re-entry, no weights), the plain EKF with
#: re-entry (the default before the redescending weights), the CLI default (redescending
#: weights + re-entry), and the iterated M-estimators.
RECOVERY_VARIANTS: dict[str, dict[str, Any]] = {
    "plain": {"max_outlier_run": None, "robust": None},
    "gated": {"gate": 0.999, "max_outlier_run": None, "robust": None},
    "reentry": {"robust": None},
    "default": {},
    "cauchy": {"robust": "cauchy"},
    "huber": {"robust": "huber"},
}


def ate_at_reference_times(
    times: NDArray[np.float64],
    poses: NDArray[np.float64],
    reference: Any,
    *,
    max_time_diff: float = 0.02,
    align: bool = True,
) -> float:
    """Position ATE (RMSE, m) after SE(2) alignment, at the reference's (Vicon's) times.

    Each reference pose takes the estimate's pose nearest in time (within
    ``max_time_diff``); the estimate is aligned to the reference by Umeyama (rotation and
    translation, no scale) over those pairs. ``align=False``: no alignment (for estimates
    already in the reference's frame, e.g. localised in a surveyed map).
    """
    from relation_metric.alignment import umeyama
    from relation_metric.time_association import nearest_index

    t_ref = reference.timestamps
    k = nearest_index(np.asarray(times, dtype=np.float64), t_ref)
    ok = np.abs(times[k] - t_ref) <= max_time_diff
    est, ref = poses[k[ok]], reference.poses[ok]
    moved = umeyama(est[:, :2], ref[:, :2]).apply(est) if align else est
    d = ref[:, :2] - moved[:, :2]
    return float(np.sqrt(np.mean(np.sum(d * d, axis=1))))


def relation_error_1s(
    times: NDArray[np.float64], poses: NDArray[np.float64], reference: Any
) -> float:
    """Mean translational error [m] of the 1 s relations (consecutive poses of the reference
    taken once a second; the relation metric, no alignment)."""
    from relation_metric.relations import generate_relations

    rel = generate_relations(_once_a_second(reference), "consecutive")
    return _mean_translation_error(rel, times, poses)


def relation_error_loops(
    times: NDArray[np.float64],
    poses: NDArray[np.float64],
    reference: Any,
    *,
    radius: float = 0.5,
    min_separation_time: float = 30.0,
) -> float:
    """Mean translational error [m] of the loop relations: pairs of reference poses (taken
    once a second) within ``radius`` of each other and at least ``min_separation_time`` apart
    (the relation metric, no alignment; NaN when the reference never revisits a place)."""
    from relation_metric.relations import generate_relations

    ref = _once_a_second(reference)
    rel = generate_relations(ref, "loops", radius=radius, min_separation_time=min_separation_time)
    return _mean_translation_error(rel, times, poses) if len(rel) else float("nan")


def _once_a_second(reference: Any) -> Any:
    """The reference poses taken once a second (the first stored pose at or after each whole
    second from the start), as a Trajectory."""
    from relation_metric.trajectory import Trajectory

    t = reference.timestamps
    k = np.unique(np.searchsorted(t, np.arange(t[0], t[-1], 1.0)))
    return Trajectory(t[k], reference.poses[k])


def _mean_translation_error(
    rel: Any, times: NDArray[np.float64], poses: NDArray[np.float64]
) -> float:
    import warnings

    from relation_metric.evaluate import evaluate
    from relation_metric.trajectory import Trajectory

    with warnings.catch_warnings():  # relations beyond the estimate's span are reported, not used
        warnings.simplefilter("ignore")
        return float(evaluate(rel, Trajectory(times, poses)).translation.abs.mean)


def recovery_variants_table(
    bundles: dict[str, Any], variants: dict[str, dict[str, Any]] | None = None
) -> list[dict[str, Any]]:
    """Filter and smoother ATE (:func:`ate_at_reference_times`) of each recovery variant.

    Parameters
    ----------
    bundles : dict of name → Bundle
        Bundles with ground truth (e.g. MRCLAM robots, with the surveyed map or an EKF-SLAM
        map).
    variants : dict of name → recover keyword arguments
        Default :data:`RECOVERY_VARIANTS`.

    Returns
    -------
    list of dict
        One row per (bundle, variant): ``filter``, ``smoother`` [m] (position ATE after
        SE(2) alignment, :func:`ate_at_reference_times`), their ratios to
        ``min(plain, gated)`` (when both variants are in the table); the same without
        alignment (``filter_raw``, ``smoother_raw``) and for the 1 s relations
        (``filter_1s``, ``smoother_1s``, :func:`relation_error_1s`) and the loop relations
        (``filter_loops``, ``smoother_loops``, :func:`relation_error_loops`); ``gated_fraction``,
        ``downweighted_fraction``, ``downweight_loss``, ``stretches``, ``fraction_of_log``.
    """
    from recovery.recover import recover

    variants = RECOVERY_VARIANTS if variants is None else variants
    rows: list[dict[str, Any]] = []
    for name, b in bundles.items():
        part = []
        for v, kw in variants.items():
            f = recover(b, method="filter", **kw)
            sm = recover(b, method="smoother", **kw)
            c = f.counts
            row: dict[str, Any] = {"bundle": name, "variant": v}
            for key, rec in (("filter", f), ("smoother", sm)):
                t, x, gt = rec.trajectory.timestamps, rec.trajectory.poses, b.groundtruth
                row[key] = ate_at_reference_times(t, x, gt)
                row[f"{key}_raw"] = ate_at_reference_times(t, x, gt, align=False)
                row[f"{key}_1s"] = relation_error_1s(t, x, gt)
                row[f"{key}_loops"] = relation_error_loops(t, x, gt)
            row.update(
                gated_fraction=c.gated_fraction,
                downweighted_fraction=c.downweighted_fraction,
                downweight_loss=c.downweight_loss,
                stretches=f.divergence.count,
                fraction_of_log=f.divergence.fraction_of_log,
            )
            part.append(row)
        best = {r["variant"]: r for r in part}
        if "plain" in best and "gated" in best:
            for key in ("filter", "smoother", "filter_raw", "smoother_raw", "filter_1s",
                        "smoother_1s", "filter_loops", "smoother_loops"):  # fmt: skip
                m = min(best["plain"][key], best["gated"][key])
                for r in part:
                    r[f"{key}_ratio"] = r[key] / m
        rows += part
    return rows
