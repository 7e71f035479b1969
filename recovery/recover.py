"""Trajectory recovery from a SLAM result bundle: filter, smoother or batch (no I/O here).

Burgard et al. 2009 recover the trajectory of an EKF-SLAM run "by localisation: run EKF-based
localisation given the landmark locations, data associations, and motion/sensor model used
during SLAM". :func:`recover` does that (:mod:`recovery.ekf`), and, the recovery being
offline, smooths it (:mod:`recovery.smoother`) or refines it as a batch MAP problem
(:mod:`recovery.batch`). Gated measurements are counted and reported: a large gated fraction
is a finding about the map, not noise.

**Divergence is a finding.** Where the map and the log disagree (runs of outlying innovations,
a non-positive-definite covariance) the filter is re-entered by the documented rule of
:func:`recovery.ekf.run_filter` and goes on; :func:`disagreement_stretches` finds the
stretches afterwards and :meth:`Recovery.report` reports them (intervals ``[t0, t1]``, the
fraction of the log, NIS statistics) next to the score. ``on_divergence="raise"`` restores
the error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from recovery.bundle import Bundle
from recovery.constants import DEFAULT_ROBUST, MAP_MODES, METHODS
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
from recovery.smoother import smooth
from recovery.steps import Steps, build_steps
from relation_metric import consistency
from relation_metric.arrays import Array
from relation_metric.consistency import chi2_quantile
from relation_metric.errors import InputError
from relation_metric.time_association import match_nearest_times
from relation_metric.trajectory import Trajectory, readonly

__all__ = [
    "DEFAULT_ROBUST",
    "METHODS",
    "MAP_MODES",
    "DEFAULT_MAX_OUTLIER_RUN",
    "Recovery",
    "Stretch",
    "disagreement_stretches",
    "filter_input",
    "recover",
]


@dataclass(frozen=True)
class Stretch:
    """A stretch of the log where the map and the log disagree.

    Attributes
    ----------
    t0, t1 : float
        Times of its first and last outlying measurement [s].
    measurements : int
        Measurements the filter processed in ``[t0, t1]``.
    outlying : int
        Of those, with NIS beyond the outlier bound.
    nis_median, nis_max : float
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


def _runs(
    flags: NDArray[np.bool_], min_len: int, bridge: int
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Maximal runs of True of length ≥ ``min_len``, merged across fewer than ``bridge`` False.

    Returns inclusive ``(start, end)`` index arrays (vectorised).
    """
    f = np.concatenate(([0], flags.astype(np.int8), [0]))
    d = np.diff(f)
    st = np.flatnonzero(d == 1)
    en = np.flatnonzero(d == -1) - 1
    keep = en - st + 1 >= min_len
    st, en = st[keep], en[keep]
    if st.size > 1:
        new = np.concatenate(([True], st[1:] - en[:-1] - 1 >= bridge))
        first = np.flatnonzero(new)
        st, en = st[first], np.maximum.reduceat(en, first)
    return st, en


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
    st, en = _runs(out, max(1, int(min_run)), max(1, int(min_run)))
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


def nees_stretches(
    times: Array, nees: Array, *, min_run: int = DEFAULT_MAX_OUTLIER_RUN
) -> list[dict[str, float | int]]:
    """NEES blow-ups against ground truth: runs of at least ``min_run`` consecutive poses (with
    ground truth) whose NEES exceeds the 99.99% χ² bound (3 dof), merged across fewer than
    ``min_run`` poses; ``[t0, t1]``, pose count and the largest NEES of each."""
    ok = np.flatnonzero(np.isfinite(nees))
    v = nees[ok]
    st, en = _runs(v > chi2_quantile(0.9999, 3), max(1, min_run), max(1, min_run))
    return [
        {
            "t0": float(times[ok[a]]),
            "t1": float(times[ok[b]]),
            "poses": int(b - a + 1),
            "nees_max": float(v[a : b + 1].max()),
        }
        for a, b in zip(st.tolist(), en.tolist())
    ]


def nis_summary(fr: FilterResult) -> dict[str, float | int | None]:
    """NIS statistics of the measurements that reached the update (2 dof; mean 2 expected)."""
    v = np.asarray(fr.nis)
    v = v[np.isfinite(v)]
    if not v.size:
        return {"count": 0, "mean": None, "median": None}
    return {
        "count": int(v.size),
        "mean": float(v.mean()),
        "median": float(np.median(v)),
        "expected_mean": 2.0,
        "fraction_beyond_95": float((v > chi2_quantile(0.95, 2)).mean()),
        "outlier_bound": float(fr.outlier_bound),
        "fraction_beyond_bound": float((v > fr.outlier_bound).mean()),
    }


@dataclass(frozen=True)
class Recovery:
    """A recovered trajectory.

    Attributes
    ----------
    method : str
    trajectory : Trajectory
        One pose per grid time (control/odometry times and measurement times).
    covariances : ndarray, shape (N, 3, 3)
    counts : dict
        ``measurements``, ``used``, ``gated``, ``unassociated``, ``outside`` (of the control
        span), ``skipped_unknown`` (dropped by the reader), and ``gated_fraction`` (of the
        associated measurements inside the span); with a robust update ``downweighted`` (weight
        below 1), ``downweighted_fraction`` and ``downweight_loss`` (``Σ (1 − w)`` over the
        associated measurements, the share of their information the weights took away).
    status : ndarray of int, shape (J,)
        Per measurement: 0 used, 1 gated, 2 unassociated, 3 outside.
    nis : ndarray, shape (J,)
        Filter innovation NIS per measurement (NaN where not evaluated).
    nees : ndarray, shape (N,) or None
        Pose NEES against ground truth at grid times that have one (NaN elsewhere).
    map_mode : str
        How the map's uncertainty entered: ``joint`` (Schmidt), ``marginal`` or ``ignore``.
    stretches : tuple of Stretch
        Where the map and the log disagree (:func:`disagreement_stretches`).
    divergence : dict
        Summary of the stretches and of the filter's re-entries (JSON-ready).
    nis_stats : dict
        :func:`nis_summary`.
    weights : ndarray, shape (J,)
        Robust weight per measurement (all 1 without a robust update).
    """

    method: str
    trajectory: Trajectory
    covariances: Array
    counts: dict[str, float]
    status: NDArray[np.int64]
    nis: Array
    nees: Array | None
    map_mode: str
    iterations: int = 0
    extra: dict[str, object] = field(default_factory=dict)
    stretches: tuple[Stretch, ...] = ()
    divergence: dict[str, object] = field(default_factory=dict)
    nis_stats: dict[str, object] = field(default_factory=dict)
    weights: Array | None = None

    @property
    def diverged(self) -> bool:
        """Whether any stretch of disagreement or filter re-entry was found."""
        return bool(self.divergence.get("diverged", False))

    def report(self) -> dict[str, object]:
        """A JSON-ready summary."""
        out: dict[str, object] = {
            "method": self.method,
            "map_uncertainty": self.map_mode,
            "poses": len(self.trajectory),
            "measurements": dict(self.counts),
            "divergence": dict(self.divergence),
            "nis": dict(self.nis_stats),
        }
        if self.nees is not None:
            ok = np.isfinite(self.nees)
            bound = chi2_quantile(0.9999, 3)
            out["nees"] = {
                "mean": float(np.mean(self.nees[ok])) if ok.any() else None,
                "poses": int(ok.sum()),
                "band95_single_pose": list(consistency.nees_band(3, 1, 0.95)),
                "bound9999_single_pose": bound,
                "fraction_beyond_bound": float((self.nees[ok] > bound).mean())
                if ok.any()
                else None,
            }
        if self.method == "batch":
            out["iterations"] = self.iterations
        out.update(self.extra)
        return out


def filter_input(
    bundle: Bundle, steps: Steps | None = None, *, map_mode: str = "joint"
) -> FilterInput:
    """Arrays for :func:`recovery.ekf.run_filter` from a bundle.

    ``map_mode``: ``joint`` uses ``map_covariance.npy`` when present (else the marginals),
    ``marginal`` the per-landmark covariances only, ``ignore`` treats the map as exact.
    """
    if map_mode not in MAP_MODES:
        raise InputError(f"unknown map mode {map_mode!r}; expected one of {', '.join(MAP_MODES)}")
    st = build_steps(bundle) if steps is None else steps
    marg = bundle.map_marginals if map_mode != "ignore" else np.zeros_like(bundle.map_marginals)
    joint = bundle.map_covariance if map_mode == "joint" else None
    lines = bundle.measurement_lines
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
        map_marginals=marg,
        map_covariance=joint,
        r=bundle.sensor.covariance,
        meas_labels=labels,
    )


def _counts(
    status: NDArray[np.int64], skipped: int, weights: Array | None = None
) -> dict[str, float]:
    used = int((status == USED).sum())
    gated = int((status == GATED).sum())
    c: dict[str, float] = {
        "measurements": int(status.shape[0]) + skipped,
        "used": used,
        "gated": gated,
        "unassociated": int((status == UNASSOCIATED).sum()),
        "outside": int((status == OUTSIDE).sum()),
        "skipped_unknown": skipped,
    }
    c["gated_fraction"] = gated / (used + gated) if used + gated else 0.0
    down = 0 if weights is None else int(((weights < 1.0) & (status == USED)).sum())
    c["downweighted"] = down
    c["downweighted_fraction"] = down / (used + gated) if used + gated else 0.0
    # the information the weights took away: Σ (1 − w) over the associated measurements
    loss = 0.0 if weights is None else float((1.0 - weights[status == USED]).sum())
    c["downweight_loss"] = loss / (used + gated) if used + gated else 0.0
    return c


def pose_nees_against(truth: Trajectory, times: Array, poses: Array, covs: Array) -> Array:
    """NEES at the grid times that equal a ground-truth time (within 1 µs), NaN elsewhere."""
    at, gt = match_nearest_times(times, truth.timestamps, 1e-6)
    out = np.full(times.shape[0], np.nan)
    if at.size:
        out[at] = consistency.pose_nees(poses[at], truth.poses[gt], covs[at])
    return out


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
) -> Recovery:
    """Recover the trajectory of a SLAM run by localisation in its final map.

    Parameters
    ----------
    bundle : Bundle
    method : {"filter", "smoother", "batch"}
        EKF only; EKF + extended RTS smoother; smoother followed by Gauss–Newton/LM over all
        poses with the map fixed.
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
        same weights. The down-weighted fraction is reported in ``counts``. ``None`` (or
        ``"none"``) is the plain EKF. Default :data:`DEFAULT_ROBUST` (``"redescending"``,
        ``c = 1.75``), chosen on MRCLAM dataset 7 and the validation grid (issue 12; numbers
        in notebooks/validation.ipynb): its filter's position ATE after SE(2) alignment at
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

    Returns
    -------
    Recovery
    """
    if method not in METHODS:
        raise InputError(f"unknown method {method!r}; expected one of {', '.join(METHODS)}")
    if gate is not None and not 0.0 < gate < 1.0:
        raise InputError(f"gate probability must be in (0, 1), got {gate}")
    inp = filter_input(bundle, map_mode=map_mode)
    kw = dict(gate=gate, max_outlier_run=max_outlier_run, on_divergence=on_divergence)
    extra: dict[str, object] = {}
    c_eff = None
    robust = None if robust == "none" else robust
    if robust is not None:
        c = float(robust_threshold) if robust_threshold is not None else ROBUST_DEFAULTS[robust]
        if robust_scale == "auto":
            scale = _nis_scale(run_filter(inp, **{**kw, "on_divergence": "reenter"}))  # type: ignore[arg-type]
        else:
            scale = float(robust_scale)
        c_eff = c * scale
        extra["robust"] = {"kind": robust, "threshold": c, "scale": scale, "effective": c_eff}
    fr: FilterResult = run_filter(
        inp,
        robust=robust,
        robust_threshold=c_eff,
        progress=progress,
        **kw,  # type: ignore[arg-type]
    )
    weights = None if robust is None else fr.weights
    iterations = 0
    if method == "filter":
        poses, covs = fr.poses, fr.covariances
    else:
        sm = smooth(fr)
        poses, covs = sm.poses, sm.covariances
        if method == "batch":
            from recovery.batch import refine

            br = refine(inp, poses, used=fr.status == USED, weights=weights)
            poses, covs, iterations = br.poses, br.covariances, br.iterations
            extra["batch"] = {"cost_initial": br.cost_initial, "cost_final": br.cost_final}
    covs, n_repaired = _check_finite(poses, covs, inp.times, repair=on_divergence != "raise")
    traj = Trajectory(inp.times, poses)
    nees = None
    if bundle.groundtruth is not None:
        nees = pose_nees_against(bundle.groundtruth, inp.times, traj.poses, covs)
    mode = map_mode if (map_mode != "joint" or bundle.map_covariance is not None) else "marginal"
    min_run = max_outlier_run if max_outlier_run else DEFAULT_MAX_OUTLIER_RUN
    stretches = disagreement_stretches(fr, inp, min_run=min_run)
    divergence = divergence_summary(fr, inp, stretches, max_outlier_run=max_outlier_run)
    divergence["covariances_repaired"] = n_repaired
    if nees is not None:
        divergence["nees_stretches"] = nees_stretches(inp.times, nees, min_run=min_run)
    return Recovery(
        method=method,
        trajectory=traj,
        covariances=readonly(covs),
        counts=_counts(np.asarray(fr.status), bundle.skipped_unknown, weights),
        status=fr.status,
        nis=fr.nis,
        nees=None if nees is None else readonly(nees),
        map_mode=mode,
        iterations=iterations,
        extra=extra,
        stretches=tuple(stretches),
        divergence=divergence,
        nis_stats=nis_summary(fr),
        weights=None if weights is None else readonly(weights),
    )


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
) -> dict[str, object]:
    """JSON-ready summary of the stretches of disagreement and of the filter's events."""
    span = float(inp.times[-1] - inp.times[0])
    dur = sum(s.t1 - s.t0 for s in stretches)
    n_proc = int(np.isfinite(np.asarray(fr.nis)).sum())
    ev = fr.events
    kinds = {EVENT_KINDS[k]: int((ev.kind == k).sum()) for k in EVENT_KINDS}
    return {
        "diverged": bool(stretches) or bool(ev.kind.size),
        "rule": (
            "a stretch is a run of at least max_outlier_run consecutive measurements with NIS "
            "beyond the outlier bound (runs fewer than max_outlier_run measurements apart "
            "merged); the filter is re-entered after each such run by inflating the pose "
            "covariance by max(1, median NIS of the run / outlier bound) around its current "
            "estimate"
            if max_outlier_run
            else "stretches reported with runs of "
            f"{DEFAULT_MAX_OUTLIER_RUN} outliers; the filter is never re-entered"
        ),
        "max_outlier_run": max_outlier_run,
        "outlier_bound": float(fr.outlier_bound),
        "stretches": [s.as_dict() for s in stretches],
        "count": len(stretches),
        "duration": dur,
        "fraction_of_log": dur / span if span > 0 else 0.0,
        "fraction_of_measurements": (
            sum(s.measurements for s in stretches) / n_proc if n_proc else 0.0
        ),
        "events": kinds,
        "event_times": inp.times[ev.grid].tolist(),
    }


def _check_finite(
    poses: Array, covs: Array, times: Array, *, repair: bool = False
) -> tuple[Array, int]:
    """Non-finite poses raise; a non-PSD smoothed/batch covariance is repaired or raises.

    The RTS recursion subtracts covariances that, after a re-entry's inflation, differ by
    orders of magnitude; rounding can leave a slightly indefinite result. With ``repair`` each
    such covariance is replaced by its projection onto the PSD cone (symmetrised, negative
    eigenvalues set to zero) and the number of repaired poses is returned.
    """
    from relation_metric.errors import DivergenceError

    bad = ~(np.isfinite(poses).all(axis=1) & np.isfinite(covs).all(axis=(1, 2)))
    n_rep = 0
    if not bad.any():
        ev = np.linalg.eigvalsh(covs)
        scale = np.maximum(np.abs(ev).max(axis=1), 1e-300)
        neg = ev[:, 0] < -1e-9 * scale
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
