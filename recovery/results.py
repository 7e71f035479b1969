"""The recovery's typed results: each finding a frozen record with its part of the JSON.

A :class:`Recovery` (what :func:`recovery.recover.recover` returns) holds its findings as
records — :class:`RecoveryCounts` (what became of the measurements), :class:`Divergence`
(where the map and the log disagree: its :class:`Stretch` es and the filter's events),
:class:`NisStats`, :class:`RobustSettings`, :class:`BatchCosts` — each with an ``as_dict()``
giving its part of :meth:`Recovery.report` (``slamrel recover --report``, ``metrics.json``
``recovery`` of ``slamrel run``). The records hold what the recovery itself found, from the
bundle alone: a score against ground truth (the NEES and its blow-ups) is not the
recovery's but the run's (:mod:`slamrel.runs.nees`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from recovery.ekf import GATED, OUTSIDE, UNASSOCIATED, USED, FilterResult
from recovery.map_uncertainty import MapUncertainty
from relation_metric.arrays import Array
from relation_metric.consistency import chi2_quantile
from relation_metric.trajectory import Trajectory

__all__ = [
    "MAP_PRIOR_RULES",
    "BatchCosts",
    "Divergence",
    "NisStats",
    "Recovery",
    "RecoveryCounts",
    "RobustSettings",
    "Stretch",
]

#: Each map prior's assumption, in words (written into the recovery report).
MAP_PRIOR_RULES = {
    "independent": "the map's error independent of the log's noise: a prior the log's "
    "measurements add to",
    "deconditioned": "the map made from this log (its covariance already holds the log's "
    "information): the poses' covariance is their covariance in the exact map plus the map's "
    "covariance through the poses' sensitivity to it (law of total covariance), the log's "
    "information about the map not counted twice",
}


@dataclass(frozen=True)
class Stretch:
    """A stretch of the log where the map and the log disagree.

    Found by :func:`recovery.recover.disagreement_stretches`.

    Attributes
    ----------
    t0, t1 : float
        Times of its first and last outlying measurement [s].
    measurements : int
        Measurements the filter processed in ``[t0, t1]``.
    outlying : int
        Of those, with NIS beyond the outlier bound.
    nis_median, nis_max : float
        Median and largest NIS of those measurements (χ², 2 dof).
    reentries : int
        Filter re-entries inside it.
    """

    t0: float
    t1: float
    measurements: int
    outlying: int
    nis_median: float
    nis_max: float
    reentries: int

    def as_dict(self) -> dict[str, float | int]:
        return {
            "t0": self.t0,
            "t1": self.t1,
            "duration": self.t1 - self.t0,
            "measurements": self.measurements,
            "outlying": self.outlying,
            "nis_median": self.nis_median,
            "nis_max": self.nis_max,
            "reentries": self.reentries,
        }


@dataclass(frozen=True)
class NisStats:
    """NIS of the measurements that reached the filter's update (χ², 2 dof).

    A consistent filter's NIS has mean :attr:`EXPECTED_MEAN` (= 2, the dof) and exceeds the
    95 % quantile ``χ²⁻¹(0.95; 2)`` for 5 % of the measurements.

    Attributes
    ----------
    count : int
        Measurements with a (finite) NIS.
    mean, median : float or None
        Of their NIS; ``None`` without any.
    fraction_beyond_95 : float or None
        Fraction with NIS above ``χ²⁻¹(0.95; 2)``.
    outlier_bound : float
        The filter's outlier bound on the NIS (the gate, or ``χ²⁻¹(OUTLIER_PROBABILITY; 2)``).
    fraction_beyond_bound : float or None
        Fraction with NIS above ``outlier_bound``.
    """

    EXPECTED_MEAN: ClassVar[float] = 2.0

    count: int
    mean: float | None
    median: float | None
    fraction_beyond_95: float | None
    outlier_bound: float
    fraction_beyond_bound: float | None

    @classmethod
    def of(cls, fr: FilterResult) -> NisStats:
        """The statistics of a filter run's NIS."""
        v = np.asarray(fr.nis)
        v = v[np.isfinite(v)]
        bound = float(fr.outlier_bound)
        if not v.size:
            return cls(0, None, None, None, bound, None)
        return cls(
            count=int(v.size),
            mean=float(v.mean()),
            median=float(np.median(v)),
            fraction_beyond_95=float((v > chi2_quantile(0.95, 2)).mean()),
            outlier_bound=bound,
            fraction_beyond_bound=float((v > bound).mean()),
        )

    def as_dict(self) -> dict[str, float | int | None]:
        """The report's ``nis``; without measurements only ``count``, ``mean``, ``median``."""
        if not self.count:
            return {"count": 0, "mean": None, "median": None}
        return {
            "count": self.count,
            "mean": self.mean,
            "median": self.median,
            "expected_mean": self.EXPECTED_MEAN,
            "fraction_beyond_95": self.fraction_beyond_95,
            "outlier_bound": self.outlier_bound,
            "fraction_beyond_bound": self.fraction_beyond_bound,
        }


@dataclass(frozen=True)
class RecoveryCounts:
    """What became of the bundle's measurements.

    The fractions are of the *associated measurements inside the control span*,
    ``used + gated`` (0 when there are none).

    Attributes
    ----------
    measurements : int
        All of the bundle's measurements, ``skipped_unknown`` included.
    used : int
        Reached the filter's update (status ``USED``).
    gated : int
        Rejected by the innovation gate (``GATED``).
    unassociated : int
        Without a landmark association (``UNASSOCIATED``).
    outside : int
        Outside the control span (``OUTSIDE``).
    skipped_unknown : int
        Dropped by the reader: landmark not in the map.
    gated_fraction : float
        ``gated / (used + gated)``.
    downweighted : int
        Used measurements whose robust weight is below 1 (0 without a robust update).
    downweighted_fraction : float
        ``downweighted / (used + gated)``.
    downweight_loss : float
        ``Σ (1 − w) / (used + gated)`` over the used measurements: the share of the
        associated measurements' information the robust weights took away.
    """

    measurements: int
    used: int
    gated: int
    unassociated: int
    outside: int
    skipped_unknown: int
    gated_fraction: float
    downweighted: int
    downweighted_fraction: float
    downweight_loss: float

    @classmethod
    def of(
        cls, status: NDArray[np.int64], skipped: int, weights: Array | None = None
    ) -> RecoveryCounts:
        """From the per-measurement status (J,), the reader's skip count and the weights (J,)."""
        used = int((status == USED).sum())
        gated = int((status == GATED).sum())
        assoc = used + gated
        down = 0 if weights is None else int(((weights < 1.0) & (status == USED)).sum())
        loss = 0.0 if weights is None else float((1.0 - weights[status == USED]).sum())
        return cls(
            measurements=int(status.shape[0]) + skipped,
            used=used,
            gated=gated,
            unassociated=int((status == UNASSOCIATED).sum()),
            outside=int((status == OUTSIDE).sum()),
            skipped_unknown=skipped,
            gated_fraction=gated / assoc if assoc else 0.0,
            downweighted=down,
            downweighted_fraction=down / assoc if assoc else 0.0,
            downweight_loss=loss / assoc if assoc else 0.0,
        )

    def dead_reckoning(self) -> str | None:
        """Why the recovery is dead reckoning, when no measurement reached the filter (None
        otherwise): the filter only predicts on the motion log (and the smoother or batch
        smooths those predictions), so the trajectory and its covariances are the motion
        model's alone."""
        if self.used:
            return None
        if self.measurements == 0:
            why = "the bundle has no measurements"
        else:
            parts = [
                f"{n} {what}"
                for n, what in (
                    (self.unassociated, "unassociated"),
                    (self.outside, "outside the log"),
                    (self.skipped_unknown, "of landmarks not in the map"),
                    (self.gated, "gated"),
                )
                if n
            ]
            why = f"none of its {self.measurements} measurements was used ({', '.join(parts)})"
        return (
            f"nothing was observed: {why}, so the recovered trajectory is dead reckoning (the "
            "filter's prediction on the motion log alone, smoothed by the smoother and the "
            "batch); it measures the motion log and its noise model, not the map"
        )

    def as_dict(self) -> dict[str, float]:
        """The report's ``measurements`` (the counts as int, the fractions as float)."""
        return {
            "measurements": self.measurements,
            "used": self.used,
            "gated": self.gated,
            "unassociated": self.unassociated,
            "outside": self.outside,
            "skipped_unknown": self.skipped_unknown,
            "gated_fraction": self.gated_fraction,
            "downweighted": self.downweighted,
            "downweighted_fraction": self.downweighted_fraction,
            "downweight_loss": self.downweight_loss,
        }


@dataclass(frozen=True)
class Divergence:
    """Where the map and the log disagree, and what the filter did about it.

    Attributes
    ----------
    rule : str
        The rule that found the stretches and re-entered the filter, in words.
    max_outlier_run : int or None
        :func:`recovery.recover.recover`'s ``max_outlier_run`` (``None``: the filter never
        re-entered).
    outlier_bound : float
        NIS (χ², 2 dof) beyond which an innovation is outlying.
    stretches : tuple of Stretch
        :func:`recovery.recover.disagreement_stretches`, in time order.
    fraction_of_log : float
        :attr:`duration` over the log's span (first to last grid time).
    fraction_of_measurements : float
        Measurements inside the stretches over the measurements with a NIS.
    events : mapping of str → int
        How many filter events of each kind (keys: the descriptions in
        :data:`recovery.ekf.EVENT_KINDS`).
    event_times : tuple of float
        Time of each event [s], in the filter's order.
    covariances_repaired : int
        Smoothed/batch pose covariances projected onto the PSD cone (rounding after a
        re-entry's inflation).
    """

    rule: str
    max_outlier_run: int | None
    outlier_bound: float
    stretches: tuple[Stretch, ...]
    fraction_of_log: float
    fraction_of_measurements: float
    events: Mapping[str, int]
    event_times: tuple[float, ...]
    covariances_repaired: int = 0

    @property
    def diverged(self) -> bool:
        """Whether any stretch of disagreement was found or any filter event happened."""
        return bool(self.stretches) or bool(self.event_times)

    @property
    def count(self) -> int:
        """Number of stretches."""
        return len(self.stretches)

    @property
    def duration(self) -> float:
        """Total duration of the stretches, ``Σ (t1 − t0)`` [s]."""
        return sum(s.t1 - s.t0 for s in self.stretches)

    @property
    def event_count(self) -> int:
        """Filter events of all kinds (re-entries and skipped updates)."""
        return sum(self.events.values())

    def as_dict(self) -> dict[str, object]:
        """The report's ``divergence``."""
        return {
            "diverged": self.diverged,
            "rule": self.rule,
            "max_outlier_run": self.max_outlier_run,
            "outlier_bound": self.outlier_bound,
            "stretches": [s.as_dict() for s in self.stretches],
            "count": self.count,
            "duration": self.duration,
            "fraction_of_log": self.fraction_of_log,
            "fraction_of_measurements": self.fraction_of_measurements,
            "events": dict(self.events),
            "event_times": list(self.event_times),
            "covariances_repaired": self.covariances_repaired,
        }


@dataclass(frozen=True)
class RobustSettings:
    """The robust (M-estimator) update the recovery used.

    Attributes
    ----------
    kind : str
        ``redescending``, ``huber`` or ``cauchy``.
    threshold : float
        ``c``, on the standardised Mahalanobis distance ``d / ŝ`` of an innovation.
    scale : float
        ``ŝ`` (estimated from a plain pass with ``robust_scale="auto"``).
    effective : float
        ``c ŝ``, the threshold on ``d`` the filter used.
    """

    kind: str
    threshold: float
    scale: float
    effective: float

    def as_dict(self) -> dict[str, object]:
        return {
            "kind": self.kind,
            "threshold": self.threshold,
            "scale": self.scale,
            "effective": self.effective,
        }


@dataclass(frozen=True)
class BatchCosts:
    """The cost ``½ Σ rᵀ W r`` of the batch refinement over its factors
    (:mod:`recovery.batch_refinement`).

    Attributes
    ----------
    cost_initial, cost_final : float
        At the smoothed trajectory it starts from, and at the refined one.
    """

    cost_initial: float
    cost_final: float

    def as_dict(self) -> dict[str, float]:
        return {"cost_initial": self.cost_initial, "cost_final": self.cost_final}


@dataclass(frozen=True)
class Recovery:
    """A recovered trajectory.

    Attributes
    ----------
    method : str
    trajectory : Trajectory
        One pose per grid time (control/odometry times and measurement times).
    covariances : ndarray, shape (N, 3, 3)
    counts : RecoveryCounts
        What became of the measurements (used, gated, down-weighted, ...).
    status : ndarray of int, shape (J,)
        Per measurement: 0 used, 1 gated, 2 unassociated, 3 outside.
    nis : ndarray, shape (J,)
        Filter innovation NIS per measurement (NaN where not evaluated).
    map_mode : str
        The form of the map's uncertainty used: ``joint``, ``marginal`` or ``ignore``.
    divergence : Divergence
        Where the map and the log disagree (its stretches, the filter's events).
    nis_stats : NisStats
        NIS of the filter's innovations.
    iterations : int
        Gauss–Newton iterations of the smoother or the batch (0 for the filter).
    robust : RobustSettings or None
        The robust update (``None``: the plain EKF).
    batch : BatchCosts or None
        The batch refinement's costs (``method="batch"`` only).
    weights : ndarray, shape (J,)
        Robust weight per measurement (all 1 without a robust update).
    map_uncertainty : MapUncertainty or None
        The map uncertainty every estimator used, with its rule in words.
    map_correction : ndarray, shape (M, 2) or None
        The smoother's or batch's estimate of the map's error ``L η`` (``map.csv`` order).
    map_prior : str
        Where the map's error comes from (:data:`~recovery.constants.MAP_PRIORS`):
        ``independent`` of the log, or ``deconditioned`` (the map made from this log).
    map_loadings : ndarray, shape (N, 3, r), or None
        The smoother's and the batch's map loadings ``V``: each pose's error is
        ``a_k + V_k ξ`` with ``ξ ~ N(0, I_r)`` the map's error, shared by every pose
        (:meth:`recovery.batch_refinement._JointProblem.map_loadings`), so the poses' errors
        are correlated by ``V_k V_lᵀ``; the verdict's consistency lamp uses it. ``None`` for
        the filter.
    map_link : ndarray, shape (r, r), or None
        ``T = Cov(ξ, ζ)``, the loadings' ``ξ`` against the map's own error ``m̂ − m = L ζ``
        (:meth:`recovery.batch_refinement._JointProblem.map_link`): ``Cov(e_k, m̂ − m) =
        V_k T Lᵀ``; the map-frame NEES (:mod:`recovery.anchoring`) conditions each pose on the
        map's placement with it. ``None`` for the filter.
    agreement_covariances : ndarray, shape (N, 3, 3), or None
        With the deconditioned map prior, the smoother's covariances under the independent
        one — the filter's own map model (a Schmidt filter cannot de-condition the map), so
        that the filter-vs-smoother agreement compares two estimates of one model; ``None``
        otherwise (``covariances`` are that).
    filter_poses, filter_covariances : ndarray, shape (N, 3), (N, 3, 3), or None
        The smoother's and the batch's own filter run (the EKF localisation they start
        from) at the same times, for the filter-vs-smoother agreement of the verdict
        (``None`` for ``method="filter"``).
    map_prior_reason : str
        Why that prior (:func:`recovery.recover.resolve_map_prior`): asked for, the bundle's
        ``map_source``, or assumed because the bundle does not say.
    persistence_factor, persistence_rho : float
        The innovations' lag-1 correlation ``ρ`` along each landmark's track and the factor
        ``(1 + ρ)/(1 − ρ)`` the covariances' second pass inflated ``R`` by
        (:func:`~relation_metric.consistency.nis_persistence`); exactly 1 and 0 when the
        innovations are not significantly correlated in time (one pass).
    innovation_det : ndarray, shape (J,), or None
        ``det S`` of each measurement's innovation where ``nis`` has a value (NaN else):
        :attr:`recovery.ekf.FilterResult.innovation_det`.
    """

    method: str
    trajectory: Trajectory
    covariances: Array
    counts: RecoveryCounts
    status: NDArray[np.int64]
    nis: Array
    map_mode: str
    divergence: Divergence
    nis_stats: NisStats
    iterations: int = 0
    robust: RobustSettings | None = None
    batch: BatchCosts | None = None
    weights: Array | None = None
    map_uncertainty: MapUncertainty | None = None
    map_correction: Array | None = None
    map_prior: str = "independent"
    filter_poses: Array | None = None
    filter_covariances: Array | None = None
    map_prior_reason: str = ""
    map_loadings: Array | None = None
    map_link: Array | None = None
    agreement_covariances: Array | None = None
    persistence_factor: float = 1.0
    persistence_rho: float = 0.0
    innovation_det: Array | None = None

    @property
    def stretches(self) -> tuple[Stretch, ...]:
        """Where the map and the log disagree (``divergence.stretches``)."""
        return self.divergence.stretches

    @property
    def diverged(self) -> bool:
        """Whether any stretch of disagreement or filter re-entry was found."""
        return self.divergence.diverged

    def report(self) -> dict[str, object]:
        """A JSON-ready summary: the ``as_dict()`` of each part, under its key."""
        out: dict[str, object] = {
            "method": self.method,
            "map_uncertainty": self.map_mode,
            "map_uncertainty_rule": (
                self.map_uncertainty.rule if self.map_uncertainty is not None else None
            ),
            "map_prior": self.map_prior,
            "map_prior_rule": MAP_PRIOR_RULES[self.map_prior],
            "map_prior_reason": self.map_prior_reason,
            "poses": len(self.trajectory),
            "measurements": self.counts.as_dict(),
            "divergence": self.divergence.as_dict(),
            "nis": self.nis_stats.as_dict(),
        }
        dead = self.counts.dead_reckoning()
        if dead is not None:  # only then: the reports of observed runs keep their bytes
            out["dead_reckoning"] = dead
        if self.method != "filter":
            out["iterations"] = self.iterations
        if self.robust is not None:
            out["robust"] = self.robust.as_dict()
        if self.batch is not None:
            out["batch"] = self.batch.as_dict()
        if self.persistence_factor != 1.0:  # only then: consistent runs keep their bytes
            out["persistence"] = {
                "rho": self.persistence_rho,
                "factor": self.persistence_factor,
                "rule": (
                    "the innovations' lag-1 correlation rho along each landmark's track is "
                    "significantly above 0: the covariances come from a second pass with the "
                    "measurement noise R x (1 + rho)/(1 - rho), the trajectory from the first"
                ),
            }
        return out
