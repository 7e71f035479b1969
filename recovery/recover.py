"""Trajectory recovery from a SLAM result bundle: filter, smoother or batch (no I/O here).

Burgard et al. 2009 recover the trajectory of an EKF-SLAM run "by localisation: run EKF-based
localisation given the landmark locations, data associations, and motion/sensor model used
during SLAM". :func:`recover` does that (:mod:`recovery.ekf`), and, the recovery being
offline, smooths it or refines it as a batch MAP problem over the poses and a correction of
the map (:mod:`recovery.batch_refinement`). The map's uncertainty enters all three by one rule
(:mod:`recovery.map_uncertainty`), stated in every report. Gated measurements are counted
and reported: a large gated fraction is a finding about the map, not noise.

**Divergence is a finding.** Where the map and the log disagree (runs of outlying innovations,
a non-positive-definite covariance) the filter is re-entered by the documented rule of
:func:`recovery.ekf.run_filter` and goes on; :func:`disagreement_stretches` finds the
stretches afterwards and :meth:`Recovery.report` reports them (intervals ``[t0, t1]``, the
fraction of the log, NIS statistics) next to the score. ``on_divergence="raise"`` restores
the error.

**Typed results.** A :class:`Recovery` holds its findings as frozen records —
:class:`RecoveryCounts`, :class:`Divergence` (its :class:`Stretch` es and, with ground truth,
its :class:`NeesBlowup` s), :class:`NisStats`, :class:`NeesStats`, :class:`RobustSettings`,
:class:`BatchCosts` — each with an ``as_dict()`` giving its part of the JSON report
(:meth:`Recovery.report`, ``slamrel recover --report``, ``metrics.json`` of ``slamrel run``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from recovery.anchoring import Anchoring, NeesFrame, start_frame, truth_at_start
from recovery.bundle import Bundle
from recovery.constants import (
    BATCH_MAX_ITERATIONS,
    DEFAULT_ROBUST,
    METHODS,
    SMOOTHER_CHI2_RESOLUTION,
    SMOOTHER_MAX_ITERATIONS,
)
from recovery.ekf import (
    DEFAULT_MAX_OUTLIER_RUN,
    EVENT_KINDS,
    GATED,
    OUTSIDE,
    REENTRY,
    ROBUST_DEFAULTS,
    UNASSOCIATED,
    USED,
    FilterInput,
    FilterResult,
    run_filter,
)
from recovery.map_uncertainty import MapUncertainty, map_uncertainty
from recovery.smoother import smooth
from recovery.steps import Steps, build_steps
from relation_metric import consistency
from relation_metric.arrays import Array
from relation_metric.consistency import OUTLIER_PROBABILITY, chi2_quantile, flag_runs
from relation_metric.errors import InputError
from relation_metric.time_association import match_nearest_times
from relation_metric.trajectory import Trajectory, readonly

__all__ = [
    "DEFAULT_ROBUST",
    "METHODS",
    "DEFAULT_MAX_OUTLIER_RUN",
    "BatchCosts",
    "Divergence",
    "NeesBlowup",
    "NeesStats",
    "NisStats",
    "Recovery",
    "RecoveryCounts",
    "RobustSettings",
    "Stretch",
    "disagreement_stretches",
    "filter_input",
    "nees_blowups",
    "recover",
]


@dataclass(frozen=True)
class Stretch:
    """A stretch of the log where the map and the log disagree (:func:`disagreement_stretches`).

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


def disagreement_stretches(
    fr: FilterResult, inp: FilterInput, *, min_run: int = DEFAULT_MAX_OUTLIER_RUN
) -> list[Stretch]:
    """Stretches where the map and the log disagree, from a filter run.

    In the order the filter processed the measurements, a measurement is *outlying* when its
    NIS exceeds ``fr.outlier_bound``; a stretch is a run of at least ``min_run`` consecutive
    outlying measurements, runs separated by fewer than ``min_run`` measurements merged (one
    stretch per episode, even when a few measurements in it happen to agree).

    Parameters
    ----------
    fr : FilterResult
    inp : FilterInput
        The filter's input (grid times and measurement grid indices).
    min_run : int

    Returns
    -------
    list of Stretch
    """
    order = np.asarray(fr.order)
    v = np.asarray(fr.nis)[order]
    ok = np.isfinite(v)
    order, v = order[ok], v[ok]
    out = v > fr.outlier_bound
    m = max(1, int(min_run))
    st, en = flag_runs(out, m, max_gap=m - 1)
    t = inp.times[inp.meas_grid[order]]
    ev = fr.events
    t_re = inp.times[ev.grid[ev.kind == REENTRY]]
    res = []
    for a, b in zip(st.tolist(), en.tolist()):
        seg = v[a : b + 1]
        t0, t1 = float(t[a]), float(t[b])
        res.append(
            Stretch(
                t0=t0,
                t1=t1,
                measurements=b - a + 1,
                outlying=int(out[a : b + 1].sum()),
                nis_median=float(np.median(seg)),
                nis_max=float(seg.max()),
                reentries=int(((t_re >= t0) & (t_re <= t1)).sum()),
            )
        )
    return res


@dataclass(frozen=True)
class NeesBlowup:
    """A NEES blow-up: a run of poses whose NEES against ground truth is outlying.

    Found by :func:`nees_blowups`: at least ``min_run`` consecutive poses (of those with
    ground truth) whose NEES exceeds ``χ²⁻¹(OUTLIER_PROBABILITY; 3)`` (the single-pose
    bound, 3 dof; :data:`~relation_metric.consistency.OUTLIER_PROBABILITY`), runs fewer than
    ``min_run`` poses apart merged. Not the report verdict's NEES excursions (95 % band,
    short runs, no merging: :func:`slamrel.report.verdict.nees_excursions`).

    Attributes
    ----------
    t0, t1 : float
        Times of its first and last pose [s].
    poses : int
        Poses with ground truth in ``[t0, t1]`` (merged gaps included).
    nees_max : float
        The largest NEES in it (χ², 3 dof).
    """

    t0: float
    t1: float
    poses: int
    nees_max: float

    def as_dict(self) -> dict[str, float | int]:
        return {"t0": self.t0, "t1": self.t1, "poses": self.poses, "nees_max": self.nees_max}


def nees_blowups(
    times: Array, nees: Array, *, min_run: int = DEFAULT_MAX_OUTLIER_RUN
) -> list[NeesBlowup]:
    """The :class:`NeesBlowup` s of a NEES curve ``nees`` (N,) at ``times`` (N,) [s].

    Poses without ground truth (non-finite NEES) are left out before the runs are found, so
    a run goes on across them.
    """
    ok = np.flatnonzero(np.isfinite(nees))
    v = nees[ok]
    m = max(1, min_run)
    st, en = flag_runs(v > chi2_quantile(OUTLIER_PROBABILITY, 3), m, max_gap=m - 1)
    return [
        NeesBlowup(
            t0=float(times[ok[a]]),
            t1=float(times[ok[b]]),
            poses=int(b - a + 1),
            nees_max=float(v[a : b + 1].max()),
        )
        for a, b in zip(st.tolist(), en.tolist())
    ]


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
class NeesStats:
    """Pose NEES of the recovery against ground truth (χ², 3 dof), at the grid poses with one.

    Attributes
    ----------
    mean : float or None
        Mean NEES; ``None`` when no grid pose has ground truth.
    poses : int
        Grid poses with ground truth.
    band95 : tuple of float
        Two-sided 95 % band of one pose's NEES, ``(χ²⁻¹(0.025; 3), χ²⁻¹(0.975; 3))``.
    bound : float
        The single-pose outlier bound ``χ²⁻¹(OUTLIER_PROBABILITY; 3)`` (of :class:`NeesBlowup`).
    fraction_beyond_bound : float or None
        Fraction of the poses with NEES above ``bound``.
    """

    mean: float | None
    poses: int
    band95: tuple[float, float]
    bound: float
    fraction_beyond_bound: float | None

    @classmethod
    def of(cls, nees: Array) -> NeesStats:
        """From the per-grid-pose NEES (N,), NaN where there is no ground truth."""
        ok = np.isfinite(nees)
        bound = chi2_quantile(OUTLIER_PROBABILITY, 3)
        return cls(
            mean=float(np.mean(nees[ok])) if ok.any() else None,
            poses=int(ok.sum()),
            band95=consistency.nees_band(3, 1, 0.95),
            bound=bound,
            fraction_beyond_bound=float((nees[ok] > bound).mean()) if ok.any() else None,
        )

    def as_dict(self) -> dict[str, object]:
        """The report's ``nees`` (keys ``band95_single_pose``, ``bound9999_single_pose``)."""
        return {
            "mean": self.mean,
            "poses": self.poses,
            "band95_single_pose": list(self.band95),
            "bound9999_single_pose": self.bound,
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
        :func:`recover`'s ``max_outlier_run`` (``None``: the filter never re-entered).
    outlier_bound : float
        NIS (χ², 2 dof) beyond which an innovation is outlying.
    stretches : tuple of Stretch
        :func:`disagreement_stretches`, in time order.
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
    nees_blowups : tuple of NeesBlowup or None
        With ground truth, the NEES blow-ups (:func:`nees_blowups`); ``None`` without.
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
    nees_blowups: tuple[NeesBlowup, ...] | None = None

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
        """The report's ``divergence`` (``nees_stretches``: the blow-ups, with ground truth)."""
        out: dict[str, object] = {
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
        if self.nees_blowups is not None:
            out["nees_stretches"] = [b.as_dict() for b in self.nees_blowups]
        return out


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
    nees : ndarray, shape (N,) or None
        Pose NEES against ground truth at grid times that have one (NaN elsewhere).
    map_mode : str
        The form of the map's uncertainty used: ``joint``, ``marginal`` or ``ignore``.
    divergence : Divergence
        Where the map and the log disagree (its stretches, the filter's events, with ground
        truth the NEES blow-ups).
    nis_stats : NisStats
        NIS of the filter's innovations.
    nees_stats : NeesStats or None
        Summary of ``nees`` (``None`` without ground truth).
    nees_frame : NeesFrame or None
        The frame ``nees`` is computed in (:mod:`recovery.anchoring`): the map frame anchored
        to the truth on the landmarks, or the truth frame (``None`` without ground truth).
    nees_stats_truth_frame : NeesStats or None
        The NEES summary with the poses compared with the ground truth as they are, unaligned
        (equal to ``nees_stats`` when the frame is the truth frame).
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
    """

    method: str
    trajectory: Trajectory
    covariances: Array
    counts: RecoveryCounts
    status: NDArray[np.int64]
    nis: Array
    nees: Array | None
    map_mode: str
    divergence: Divergence
    nis_stats: NisStats
    nees_stats: NeesStats | None = None
    iterations: int = 0
    robust: RobustSettings | None = None
    batch: BatchCosts | None = None
    weights: Array | None = None
    map_uncertainty: MapUncertainty | None = None
    map_correction: Array | None = None
    nees_frame: NeesFrame | None = None
    nees_stats_truth_frame: NeesStats | None = None

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
            "poses": len(self.trajectory),
            "measurements": self.counts.as_dict(),
            "divergence": self.divergence.as_dict(),
            "nis": self.nis_stats.as_dict(),
        }
        dead = self.counts.dead_reckoning()
        if dead is not None:  # only then: the reports of observed runs keep their bytes
            out["dead_reckoning"] = dead
        if self.nees_stats is not None:
            out["nees"] = self.nees_stats.as_dict()
        if self.nees_frame is not None:
            out["nees_frame"] = self.nees_frame.as_dict()
        if self.nees_stats_truth_frame is not None:
            out["nees_truth_frame"] = self.nees_stats_truth_frame.as_dict()
        if self.method != "filter":
            out["iterations"] = self.iterations
        if self.robust is not None:
            out["robust"] = self.robust.as_dict()
        if self.batch is not None:
            out["batch"] = self.batch.as_dict()
        return out


def filter_input(
    bundle: Bundle,
    steps: Steps | None = None,
    *,
    map_mode: str = "joint",
    uncertainty: MapUncertainty | None = None,
) -> FilterInput:
    """Arrays for :func:`recovery.ekf.run_filter` from a bundle.

    ``map_mode``: the map uncertainty's form, by the one rule of
    :func:`recovery.map_uncertainty.map_uncertainty` (``joint``: ``map_covariance.npy``, else
    the marginals as a block-diagonal joint covariance; ``marginal``: that block-diagonal
    covariance; ``ignore``: the map exact). ``uncertainty``: that rule's result when already
    computed (``map_mode`` is then not read).
    """
    mu = map_uncertainty(bundle, map_mode) if uncertainty is None else uncertainty
    st = build_steps(bundle) if steps is None else steps
    lines = bundle.measurement_lines
    assert lines is not None  # Bundle.__post_init__ fills it
    src = "measurements.csv"
    labels = tuple(
        f"measurement {j} ({src}:{int(lines[j])})" if lines[j] > 0 else f"measurement {j}"
        for j in range(lines.shape[0])
    )
    return FilterInput(
        times=st.times,
        u=st.u,
        sigma=st.sigma,
        x0=bundle.initial_pose,
        p0=bundle.initial_covariance,
        meas_grid=st.measurement_grid,
        meas_z=bundle.measurements,
        meas_landmark=bundle.map_index(),
        map_xy=bundle.map_xy,
        map_marginals=mu.marginals,
        map_covariance=mu.covariance,
        r=bundle.sensor.covariance,
        meas_labels=labels,
    )


def pose_nees_against(
    truth: Trajectory, times: Array, poses: Array, covs: Array, anchoring: Anchoring | None = None
) -> Array:
    """NEES at the grid times that equal a ground-truth time (within 1 µs), NaN elsewhere.

    With ``anchoring`` (truth ← map, :mod:`recovery.anchoring`) the poses and covariances
    are first taken into the truth frame; without, they are compared as they are.
    """
    at, gt = match_nearest_times(times, truth.timestamps, 1e-6)
    out = np.full(times.shape[0], np.nan)
    if at.size:
        p, c = (poses[at], covs[at]) if anchoring is None else anchoring.apply(poses[at], covs[at])
        out[at] = consistency.pose_nees(p, truth.poses[gt], c)
    return out


#: How :func:`recovery.batch_refinement.refine` stops for each method: the smoother at the data's
#: statistical resolution (a step changing χ² by less than one unit), the batch numerically.
_SMOOTHER_STOP = {
    "max_iterations": SMOOTHER_MAX_ITERATIONS,
    "tolerance": 0.0,
    "cost_tolerance": 0.5 * SMOOTHER_CHI2_RESOLUTION,
}
_BATCH_STOP = {"max_iterations": BATCH_MAX_ITERATIONS}


def recover(
    bundle: Bundle,
    *,
    method: str = "smoother",
    gate: float | None = None,
    map_mode: str = "joint",
    max_outlier_run: int | None = DEFAULT_MAX_OUTLIER_RUN,
    on_divergence: str = "reenter",
    robust: str | None = DEFAULT_ROBUST,
    robust_threshold: float | None = None,
    robust_scale: float | str = "auto",
    progress: bool = False,
    nees_frame: NeesFrame | None = None,
) -> Recovery:
    """Recover the trajectory of a SLAM run by localisation in its final map.

    Parameters
    ----------
    bundle : Bundle
    method : {"filter", "smoother", "batch"}
        EKF only (Schmidt update with the map uncertainty); the smoother: the extended RTS
        smoother of the filter run, then Gauss–Newton steps over all poses and the map
        correction until one lowers χ² by less than one unit (:mod:`recovery.batch_refinement`: the
        map-augmented fixed-interval smoother, relinearised); the batch: that problem
        iterated to numerical convergence. All three use the one map uncertainty of
        :func:`recovery.map_uncertainty.map_uncertainty`.
    gate : float, optional
        χ² probability of the innovation gate; ``None`` (default) gates nothing, so a broken
        map shows in the score instead of being filtered away.
    map_mode : {"joint", "marginal", "ignore"}
    max_outlier_run : int, optional
        Consecutive outlying innovations after which the filter is re-entered and a stretch
        of disagreement is reported; ``None`` never re-enters (stretches are still reported,
        with runs of :data:`DEFAULT_MAX_OUTLIER_RUN`). See :func:`recovery.ekf.run_filter`.
    on_divergence : {"reenter", "raise"}
        ``"raise"``: :class:`~relation_metric.errors.DivergenceError` at the first such run
        (the old behaviour) instead of a trajectory and a report.
    robust : {"redescending", "huber", "cauchy", None}
        M-estimator weights of the innovations (:func:`recovery.ekf.run_filter`); the
        smoother (through the filter's gains) and the batch (``refine(weights=...)``) use the
        same weights. The down-weighted fraction is reported in ``counts``
        (:class:`RecoveryCounts`). ``None`` (or
        ``"none"``) is the plain EKF. Default :data:`DEFAULT_ROBUST` (``"redescending"``,
        ``c = 1.75``), chosen on MRCLAM dataset 7 and the validation grid (numbers in
        notebooks/validation.ipynb): its filter's position ATE after SE(2) alignment at
        the Vicon times is 0.87–1.03 × min(plain EKF, 99.9%-gated EKF) on robots 1–5 and its
        smoother is below its filter on the 1 s relations of all five (on the aligned ATE of
        four: robot 4's biased measurements), while broken maps keep their error (grid:
        recovered ≥ 0.58 × online for every broken run). Smaller ``c`` fits MRCLAM a little
        better and makes over-confident healthy runs of the grid look broken (1.25: 1.71 ×
        online).
    robust_threshold : float, optional
        The M-estimator's ``c`` on the standardised Mahalanobis distance ``d / ŝ`` (default
        :data:`ROBUST_DEFAULTS` of the kind).
    robust_scale : float or "auto"
        ``ŝ``. ``"auto"`` (default) estimates it as in classical M-estimation, robustly from
        the data: a first, plain pass of the filter gives ``ŝ² = median NIS / median χ²₂``,
        so that a filter whose covariances are uniformly mis-scaled (a mis-tuned filter, or
        a map that disagrees with most of the log) is not mistaken for one with outliers —
        the more of the log disagrees, the less is down-weighted, and a broken map cannot be
        weighted away. The filter then runs with ``c_eff = c ŝ``.
    progress : bool
        tqdm bar on the filter's epochs.
    nees_frame : NeesFrame, optional
        The frame of the NEES against ground truth. Default: the map frame anchored to the
        truth on the landmarks the map shares by id with ``landmarks_groundtruth``
        (:meth:`NeesFrame.by_id`; the truth frame when fewer than 2). Aligned, the first
        grid pose (the prior) has no NEES. The unaligned NEES is kept beside it
        (``nees_stats_truth_frame``).

    Returns
    -------
    Recovery
    """
    if method not in METHODS:
        raise InputError(f"unknown method {method!r}; expected one of {', '.join(METHODS)}")
    if gate is not None and not 0.0 < gate < 1.0:
        raise InputError(f"gate probability must be in (0, 1), got {gate}")
    mu = map_uncertainty(bundle, map_mode)
    inp = filter_input(bundle, uncertainty=mu)
    if method != "filter":  # before any work: the joint problem's dense map terms
        from recovery.batch_refinement import check_joint_size

        check_joint_size(int(inp.times.shape[0]), int(mu.factor.shape[1]))
    kw = dict(gate=gate, max_outlier_run=max_outlier_run, on_divergence=on_divergence)
    settings = None
    c_eff = None
    robust = None if robust == "none" else robust
    if robust is not None:
        c = float(robust_threshold) if robust_threshold is not None else ROBUST_DEFAULTS[robust]
        if robust_scale == "auto":
            scale = _nis_scale(run_filter(inp, **{**kw, "on_divergence": "reenter"}))  # type: ignore[arg-type]
        else:
            scale = float(robust_scale)
        c_eff = c * scale
        settings = RobustSettings(kind=robust, threshold=c, scale=scale, effective=c_eff)
    fr: FilterResult = run_filter(
        inp,
        robust=robust,
        robust_threshold=c_eff,
        progress=progress,
        **kw,  # type: ignore[arg-type]
    )
    weights = None if robust is None else fr.weights
    iterations = 0
    costs = None
    correction = None
    if method == "filter":
        poses, covs = fr.poses, fr.covariances
    else:
        from recovery.batch_refinement import refine

        br = refine(
            reentry_relaxed(inp, fr),
            smooth(fr).poses,  # the RTS smoother linearises along the run; then the map step
            used=fr.status == USED,
            weights=weights,
            map_factor=mu.factor,
            **(_SMOOTHER_STOP if method == "smoother" else _BATCH_STOP),
        )
        poses, covs = br.poses, br.covariances
        if br.map_correction is not None:
            correction = readonly(br.map_correction)
        iterations = br.iterations
        if method == "batch":
            costs = BatchCosts(cost_initial=br.cost_initial, cost_final=br.cost_final)
    covs, n_repaired = _check_finite(poses, covs, inp.times, repair=on_divergence != "raise")
    traj = Trajectory(inp.times, poses)
    nees = frame = truth_stats = None
    if bundle.groundtruth is not None:
        gt = bundle.groundtruth
        frame = nees_frame
        if frame is None:
            by_id = NeesFrame.by_id(bundle.map_ids, bundle.map_xy, bundle.landmarks_groundtruth)
            g0 = truth_at_start(gt, float(inp.times[0]))
            frame = start_frame(bundle.initial_pose, bundle.initial_covariance, g0, by_id.anchoring)
        nees = pose_nees_against(gt, inp.times, traj.poses, covs, frame.anchoring)
        if frame.anchoring is not None:
            # the prior pose is exact in the map frame by definition: aligned, its NEES would
            # measure the anchoring's error against the prior's covariance, not the recovery
            nees[0] = np.nan
        truth_stats = NeesStats.of(
            nees if frame.anchoring is None else pose_nees_against(gt, inp.times, traj.poses, covs)
        )
    min_run = max_outlier_run if max_outlier_run else DEFAULT_MAX_OUTLIER_RUN
    stretches = disagreement_stretches(fr, inp, min_run=min_run)
    divergence = divergence_summary(
        fr, inp, stretches, max_outlier_run=max_outlier_run, covariances_repaired=n_repaired,
        nees_blowups=None if nees is None else nees_blowups(inp.times, nees, min_run=min_run),
    )  # fmt: skip
    return Recovery(
        method=method,
        trajectory=traj,
        covariances=readonly(covs),
        counts=RecoveryCounts.of(np.asarray(fr.status), bundle.skipped_unknown, weights),
        status=fr.status,
        nis=fr.nis,
        nees=None if nees is None else readonly(nees),
        map_mode=mu.mode,
        map_uncertainty=mu,
        divergence=divergence,
        nis_stats=NisStats.of(fr),
        nees_stats=None if nees is None else NeesStats.of(nees),
        iterations=iterations,
        robust=settings,
        batch=costs,
        weights=None if weights is None else readonly(weights),
        map_correction=correction,
        nees_frame=frame,
        nees_stats_truth_frame=truth_stats,
    )


def reentry_relaxed(inp: FilterInput, fr: FilterResult) -> FilterInput:
    """``inp`` with each filter re-entry's inflation as extra process noise, for the smoother
    and the batch.

    A re-entry at grid pose ``k`` set the filter's covariance to ``α P``; the smoother and
    the batch see it as process noise ``(α − 1) P = (α − 1)/α · P_k`` (``P_k`` the filter's
    covariance at ``k``) added to the step into ``k`` (rotated into the robot frame at the
    filter's heading of ``k − 1``), or to the prior at ``k = 0``: where the map and the log
    disagreed, the trajectory may jump as the filter's did.
    """
    ev = fr.events
    sel = np.flatnonzero(ev.kind == REENTRY)
    if not sel.size:
        return inp
    sigma, p0 = np.array(inp.sigma), np.array(inp.p0)
    for k, alpha in zip(ev.grid[sel].tolist(), ev.inflation[sel].tolist()):
        extra = (alpha - 1.0) / alpha * np.asarray(fr.covariances[k])
        if k == 0:
            p0 += extra
            continue
        c, s = math.cos(fr.poses[k - 1, 2]), math.sin(fr.poses[k - 1, 2])
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        sigma[k - 1] += rot.T @ extra @ rot
    return replace(inp, sigma=sigma, p0=p0)


def _nis_scale(fr: FilterResult) -> float:
    """``ŝ = √(median NIS / median χ²₂)`` of a plain filter pass (1 without innovations)."""
    v = np.asarray(fr.nis)
    v = v[np.isfinite(v)]
    scale = float(np.sqrt(np.median(v) / chi2_quantile(0.5, 2))) if v.size else 1.0
    return scale if math.isfinite(scale) and scale > 0.0 else 1.0


def divergence_summary(
    fr: FilterResult,
    inp: FilterInput,
    stretches: list[Stretch],
    *,
    max_outlier_run: int | None,
    covariances_repaired: int = 0,
    nees_blowups: list[NeesBlowup] | None = None,
) -> Divergence:
    """The :class:`Divergence` of a filter run: its stretches of disagreement and events."""
    span = float(inp.times[-1] - inp.times[0])
    dur = sum(s.t1 - s.t0 for s in stretches)
    n_proc = int(np.isfinite(np.asarray(fr.nis)).sum())
    ev = fr.events
    kinds = {EVENT_KINDS[k]: int((ev.kind == k).sum()) for k in EVENT_KINDS}
    return Divergence(
        rule=(
            "a stretch is a run of at least max_outlier_run consecutive measurements with NIS "
            "beyond the outlier bound (runs fewer than max_outlier_run measurements apart "
            "merged); the filter is re-entered after each such run by inflating the pose "
            "covariance by max(1, median NIS of the run / outlier bound) around its current "
            "estimate"
            if max_outlier_run
            else "stretches reported with runs of "
            f"{DEFAULT_MAX_OUTLIER_RUN} outliers; the filter is never re-entered"
        ),
        max_outlier_run=max_outlier_run,
        outlier_bound=float(fr.outlier_bound),
        stretches=tuple(stretches),
        fraction_of_log=dur / span if span > 0 else 0.0,
        fraction_of_measurements=(
            sum(s.measurements for s in stretches) / n_proc if n_proc else 0.0
        ),
        events=kinds,
        event_times=tuple(inp.times[ev.grid].tolist()),
        covariances_repaired=covariances_repaired,
        nees_blowups=None if nees_blowups is None else tuple(nees_blowups),
    )


def _check_finite(
    poses: Array, covs: Array, times: Array, *, repair: bool = False
) -> tuple[Array, int]:
    """Non-finite poses raise; a non-PSD smoothed/batch covariance is repaired or raises.

    Non-PSD is the one covariance check of :mod:`relation_metric.checks` (asymmetric, or an
    eigenvalue below ``−COV_RTOL · max |C_ij|``). The RTS recursion subtracts covariances
    that, after a re-entry's inflation, differ by orders of magnitude; rounding can leave a
    slightly indefinite result. With ``repair`` each such covariance is replaced by its
    projection onto the PSD cone (symmetrised, negative eigenvalues set to zero) and the
    number of repaired poses is returned.
    """
    from relation_metric.checks import bad_covariances
    from relation_metric.errors import DivergenceError

    bad = ~(np.isfinite(poses).all(axis=1) & np.isfinite(covs).all(axis=(1, 2)))
    n_rep = 0
    if not bad.any():
        neg = np.zeros(covs.shape[0], dtype=bool)
        neg[bad_covariances(covs)[0]] = True
        if neg.any() and repair:
            sym = 0.5 * (covs[neg] + covs[neg].transpose(0, 2, 1))
            w, v = np.linalg.eigh(sym)
            covs = covs.copy()
            covs[neg] = (v * np.maximum(w, 0.0)[:, None, :]) @ v.transpose(0, 2, 1)
            n_rep = int(neg.sum())
        else:
            bad = neg
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise DivergenceError(
            f"recovery diverged at t={float(times[k]):.6f} s (pose {k}): non-finite or non-PSD "
            "covariance"
        )
    return covs, n_rep
