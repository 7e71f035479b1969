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

**Recovery only.** :func:`recover` uses the bundle's map, associations and log, never its
ground truth: scoring the recovered trajectory against the truth (its NEES, in the frame of
:mod:`recovery.anchoring`, and the NEES blow-ups) is the run's work
(:mod:`slamrel.runs.nees`, which ``slamrel run`` and ``slamrel recover --report`` share), so
that every NEES slamrel reports has one computation.

**Typed results.** A :class:`~recovery.results.Recovery` holds its findings as frozen records
(:mod:`recovery.results`; importable from here too), each with an ``as_dict()`` giving its
part of the JSON report.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

from recovery.bundle import Bundle
from recovery.constants import (
    BATCH_MAX_ITERATIONS,
    DEFAULT_MAP_PRIOR,
    DEFAULT_ROBUST,
    INITIAL_COVARIANCE_FLOOR,
    MAP_PRIOR_CHOICES,
    METHODS,
    SMOOTHER_CHI2_RESOLUTION,
    SMOOTHER_MAX_ITERATIONS,
)
from recovery.ekf import (
    DEFAULT_MAX_OUTLIER_RUN,
    EVENT_KINDS,
    HEAVY_TAIL_C,
    REENTRY,
    ROBUST_DEFAULTS,
    USED,
    FilterInput,
    FilterResult,
    run_filter,
)
from recovery.map_uncertainty import MapUncertainty, map_uncertainty
from recovery.models import MotionPersisting, PersistingError
from recovery.mount import loadings_to_robot_frame, to_robot_frame, to_sensor_frame
from recovery.results import (
    BatchCosts,
    Divergence,
    NisStats,
    Recovery,
    RecoveryCounts,
    RobustSettings,
    Stretch,
)
from recovery.smoother import smooth
from recovery.steps import Steps, build_steps
from relation_metric.arrays import Array
from relation_metric.consistency import chi2_quantile, flag_runs, nis_persistence
from relation_metric.errors import InputError
from relation_metric.trajectory import Trajectory, readonly

__all__ = [
    "DEFAULT_ROBUST",
    "METHODS",
    "DEFAULT_MAX_OUTLIER_RUN",
    "BatchCosts",
    "Divergence",
    "MapPriorChoice",
    "NisStats",
    "Recovery",
    "RecoveryCounts",
    "RobustSettings",
    "Stretch",
    "disagreement_stretches",
    "filter_input",
    "recover",
    "resolve_map_prior",
]


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
        p0=start_covariance(bundle.initial_covariance),
        meas_grid=st.measurement_grid,
        meas_z=bundle.measurements,
        meas_landmark=bundle.map_index(),
        map_xy=bundle.map_xy,
        map_marginals=mu.marginals,
        map_covariance=mu.covariance,
        r=bundle.sensor.covariance,
        meas_labels=labels,
    )


def start_covariance(p0: Array) -> Array:
    """The filter's initial covariance: ``p0`` when positive definite, else ``p0 + εI``.

    A positive semi-definite ``initial_covariance`` that is not definite (exactly zero: the
    start pose known exactly) gets :data:`~recovery.constants.INITIAL_COVARIANCE_FLOOR` on its
    diagonal (docs/bundle.md), since every method needs the inverse; (3, 3) -> (3, 3).
    """
    p0 = np.asarray(p0, dtype=np.float64)
    if np.linalg.eigvalsh(0.5 * (p0 + p0.T)).min() > 0.0:
        return p0
    return p0 + INITIAL_COVARIANCE_FLOOR * np.eye(3)


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
    map_prior: str = DEFAULT_MAP_PRIOR,
    persistence: bool = False,
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
        ``c = √χ²₂(0.999) ≈ 3.717``, :data:`recovery.ekf.REDESCENDING_C`): a consistent
        innovation is weighted down with probability 0.1 %, so a clean run costs nothing
        against the plain EKF, while wrong associations are still weighted down (issue 38,
        benchmarks/robust_default.py; ``c = 1.75``, the default before, down-weighted 22–25 %
        of healthy runs' measurements and cost them 4–10 % of accuracy).
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
    map_prior : {"auto", "independent", "deconditioned"}
        Where the map's error comes from (:data:`~recovery.constants.MAP_PRIOR_CHOICES`).
        ``"auto"`` (default): ``deconditioned`` when the bundle states ``map_source="log"``
        and the method is the smoother or the batch, else ``independent``
        (:func:`resolve_map_prior`; the choice and its reason are in the report).
        ``"independent"``: a map made apart from the log (surveyed, or drawn
        independently of its noise), whose ``Σ_m`` is a prior the log's measurements add
        to. ``"deconditioned"``: a map made from this very log (an EKF-SLAM's final map and
        its joint covariance), whose ``Σ_m`` already holds the log's information: the poses'
        covariance is then ``A⁻¹ + A⁻¹ B Σ_m Bᵀ A⁻¹`` (the law of total covariance), not the
        poses' block of the joint information with the log's information about the map
        counted a second time (docs/recovery.md). The trajectory is the same under both;
        smoother and batch only.
    persistence : bool
        Default ``False`` (one pass): it also hides a map whose stated covariance is
        too small, whose error persists along each track too (docs/verdict.md). ``True``:
        when the first pass's innovations are correlated in time along
        each landmark's track (:func:`~relation_metric.consistency.nis_persistence`: lag-1
        correlation ``ρ`` significantly above 0), a white-noise filter counts a persisting
        error's sightings as independent; a second whole pass with the measurement noise
        ``R × (1 + ρ)/(1 − ρ)`` gives the covariances (and the map loadings, the filter's
        covariances), while the trajectory stays the first pass's (the score judges the
        filter's map). The factor and ``ρ`` are in :class:`Recovery`; without a significant
        ``ρ`` the factor is exactly 1 and nothing is re-run.

    Returns
    -------
    Recovery

    Raises
    ------
    InputError
        For an unknown method, map mode or map prior, a gate outside ``(0, 1)``, or
        ``map_prior="deconditioned"`` with the filter.
    """
    _check_options(method, gate, map_prior)
    prior = resolve_map_prior(bundle, method, map_prior)
    mu = map_uncertainty(bundle, map_mode)
    inp = filter_input(bundle, uncertainty=mu)
    mount = np.asarray(bundle.sensor.mount) if bundle.sensor.mounted else None
    if mount is not None:  # the filter runs on the sensor's poses (recovery.mount)
        inp = to_sensor_frame(inp, mount)
    if method != "filter":  # before any work: the joint problem's dense map terms
        from recovery.batch_refinement import check_joint_size

        check_joint_size(int(inp.times.shape[0]), int(mu.factor.shape[1]))
    kw = dict(gate=gate, max_outlier_run=max_outlier_run, on_divergence=on_divergence)
    robust = None if robust == "none" else robust
    pe, mp = bundle.sensor.persisting, bundle.motion.persisting
    if pe is not None or mp is not None:  # persisting errors: the augmented filter, smoother
        settings, fr, est = _persisting_recovery(
            inp, (pe, mp), method, prior.prior, robust, robust_threshold, robust_scale
        )
        pers = None
    else:
        settings = _robust_settings(inp, kw, robust, robust_threshold, robust_scale)
        threshold = None if settings is None else settings.effective
        setup = _PassSetup(method, mu, prior.prior, kw, robust, threshold)
        fr, est = _pass(setup, inp, progress)
        pers = nis_persistence(fr.nis, bundle.measurement_landmarks) if persistence else None
    weights = None if robust is None else fr.weights
    filt_covs = fr.covariances
    if pers is not None and pers.significant:
        est, filt_covs = _persistent_pass(setup, inp, est, pers.factor)
    filt = None if method == "filter" else (fr.poses, filt_covs)
    if mount is not None:
        poses, covariances = to_robot_frame(est.poses, est.covariances, mount)
        loadings, ind = est.map_loadings, est.independent_covariances
        if loadings is not None:
            loadings = loadings_to_robot_frame(est.poses, loadings, mount)
        if ind is not None:
            ind = to_robot_frame(est.poses, ind, mount)[1]
        est = replace(
            est,
            poses=poses,
            covariances=covariances,
            map_loadings=loadings,
            independent_covariances=ind,
        )
        if filt is not None:  # the agreement lamp compares both in the robot's frame
            filt = to_robot_frame(filt[0], filt[1], mount)
    covs, n_repaired = _check_finite(
        est.poses, est.covariances, inp.times, repair=on_divergence != "raise"
    )
    min_run = max_outlier_run if max_outlier_run else DEFAULT_MAX_OUTLIER_RUN
    stretches = disagreement_stretches(fr, inp, min_run=min_run)
    divergence = divergence_summary(
        fr, inp, stretches, max_outlier_run=max_outlier_run, covariances_repaired=n_repaired
    )
    return Recovery(
        method=method,
        trajectory=Trajectory(inp.times, est.poses),
        covariances=readonly(covs),
        counts=RecoveryCounts.of(np.asarray(fr.status), bundle.skipped_unknown, weights),
        status=fr.status,
        nis=fr.nis,
        innovation_det=fr.innovation_det,
        map_mode=mu.mode,
        map_uncertainty=mu,
        divergence=divergence,
        nis_stats=NisStats.of(fr),
        iterations=est.iterations,
        robust=settings,
        batch=est.costs,
        weights=None if weights is None else readonly(weights),
        map_correction=est.map_correction,
        map_prior=prior.prior,
        map_prior_reason=prior.reason,
        map_loadings=None if est.map_loadings is None else readonly(est.map_loadings),
        map_link=None if est.map_link is None else readonly(est.map_link),
        agreement_covariances=None
        if est.independent_covariances is None
        else readonly(est.independent_covariances),
        filter_poses=None if filt is None else readonly(filt[0]),
        filter_covariances=None if filt is None else readonly(filt[1]),
        persistence_factor=1.0 if pers is None else pers.factor,
        persistence_rho=0.0 if pers is None else pers.rho,
    )


@dataclass(frozen=True)
class _PassSetup:
    """What every pass of one :func:`recover` call shares: the method, the map's
    uncertainty and prior, the filter's options, the robust kind and effective threshold."""

    method: str
    mu: MapUncertainty
    prior: str
    kw: Mapping[str, object]
    robust: str | None
    threshold: float | None


def _pass(
    setup: _PassSetup, inp: FilterInput, progress: bool = False
) -> tuple[FilterResult, _Estimate]:
    """One whole pass of the method on ``inp``: the filter run and its estimate."""
    method = setup.method
    fr: FilterResult = run_filter(
        inp,
        robust=setup.robust,
        robust_threshold=setup.threshold,
        progress=progress,
        **setup.kw,  # type: ignore[arg-type]
    )
    weights = None if setup.robust is None else fr.weights
    try:
        return fr, _estimate(method, inp, fr, setup.mu, weights, setup.prior)
    except np.linalg.LinAlgError as exc:
        from relation_metric.errors import DivergenceError

        raise DivergenceError(
            f"the {method} could not factor a covariance or information matrix ({exc}): "
            "in float64 it is singular or indefinite, as when the motion or sensor noise is "
            "many orders of magnitude beyond the motion and the map; expected noise on their "
            "scale (method filter needs no such factorisation)"
        ) from None


def _persistent_pass(
    setup: _PassSetup, inp: FilterInput, first: _Estimate, factor: float
) -> tuple[_Estimate, Array]:
    """``first`` with the covariances of a second whole pass whose measurement noise is
    ``R × factor`` (:func:`~relation_metric.consistency.nis_persistence`), and that pass's
    filter covariances; the poses (and the map correction) stay the first pass's: the score
    judges the filter's map, the second pass only says how much the persisting errors are
    worth. The robust threshold (on the Mahalanobis distance) is divided by ``√factor`` so
    that about the same innovations are down-weighted as in the first pass."""
    th = None if setup.threshold is None else setup.threshold / math.sqrt(factor)
    inp2 = replace(inp, r=np.asarray(inp.r) * factor)
    fr2, second = _pass(replace(setup, threshold=th), inp2)
    est = replace(
        first,
        covariances=second.covariances,
        map_loadings=second.map_loadings,
        independent_covariances=second.independent_covariances,
        map_link=second.map_link,
    )
    return est, fr2.covariances


def _persisting_recovery(
    inp: FilterInput,
    stated: tuple[PersistingError | None, MotionPersisting | None],
    method: str,
    prior: str,
    robust: str | None,
    threshold: float | None,
    scale: float | str,
) -> tuple[RobustSettings | None, FilterResult, _Estimate]:
    """The recovery of a bundle that states a persisting error (:mod:`recovery.persisting`;
    ``stated``: the measurements' and the odometry's, either may be None): the augmented EKF
    (``method="filter"``) or its RTS smoother (smoother and batch: the augmented model's
    fixed-interval smoother), with the robust rule of :func:`recover` (``ŝ`` and the
    heavy-tail choice of ``c`` from a plain augmented pass)."""
    from recovery.persisting import run_persisting, smooth_persisting

    pe, mp = stated
    keys = " and ".join(k for k, v in (("sensor_model", pe), ("motion_model", mp)) if v is not None)
    if prior == "deconditioned":
        raise InputError(
            f"the bundle states a persisting error ({keys}.persisting) and a map made from "
            "its log: the augmented recovery has no de-conditioned map prior; expected map "
            "prior independent (a surveyed map) or a bundle without persisting"
        )
    if robust not in (None, "redescending"):
        raise InputError(
            f"robust {robust!r} with a persisting error ({keys}.persisting): the augmented "
            "recovery has the redescending update only; expected redescending or none"
        )
    common: dict[str, object] = {"motion": mp}
    if pe is not None and pe.common is not None:
        common.update(common_sigma=pe.common.sigma, common_tau=pe.common.tau)
    sigma, tau = (None, None) if pe is None else (pe.sigma, pe.tau)
    settings = None
    c_eff = None
    if robust is not None:
        c = float(threshold) if threshold is not None else ROBUST_DEFAULTS[robust]
        if scale == "auto":
            plain = run_persisting(inp, sigma, tau, **common).fr  # type: ignore[arg-type]
            s = _nis_scale(plain)
            if threshold is None and _heavy_tailed(plain.nis, s):
                c = HEAVY_TAIL_C
        else:
            s = float(scale)
        settings = RobustSettings(kind=robust, threshold=c, scale=s, effective=c * s)
        c_eff = settings.effective
    run = run_persisting(inp, sigma, tau, robust_threshold=c_eff, **common)  # type: ignore[arg-type]
    fr = run.fr
    if method == "filter":
        return settings, fr, _Estimate(fr.poses, fr.covariances)
    poses, covs, states = smooth_persisting(run)
    # the iterated extended smoother: the measurements relinearised at the smoothed states
    # (as the white recovery's Gauss–Newton steps do), PERSISTING_ITERATIONS passes
    for _ in range(PERSISTING_ITERATIONS):
        again = run_persisting(
            inp,
            sigma,
            tau,
            robust_threshold=c_eff,
            linearize_at=states,
            **common,  # type: ignore[arg-type]
        )
        poses, covs, states = smooth_persisting(again)
    return settings, fr, _Estimate(poses, covs, iterations=PERSISTING_ITERATIONS)


#: Relinearised passes of the augmented smoother after its first (recovery.persisting).
PERSISTING_ITERATIONS = 2


@dataclass(frozen=True)
class MapPriorChoice:
    """The map prior a recovery uses (:data:`~recovery.constants.MAP_PRIORS`) and why."""

    prior: str
    reason: str


def resolve_map_prior(
    bundle: Bundle, method: str, asked: str = DEFAULT_MAP_PRIOR
) -> MapPriorChoice:
    """The map prior for ``asked`` (:data:`~recovery.constants.MAP_PRIOR_CHOICES`) on
    ``bundle`` with ``method``, and the reason in words.

    ``auto``: ``deconditioned`` when the bundle states ``map_source="log"`` (its map was
    estimated from this log, so its covariance holds the log's information) and the method is
    the smoother or the batch; else ``independent`` — said to be *assumed* when the bundle does
    not state where its map came from, and said to count the log twice when the map is the
    log's but the filter cannot de-condition it. An explicit prior is used as asked.
    """
    if asked != "auto":
        return MapPriorChoice(asked, f"asked for (map prior {asked})")
    source = bundle.map_source
    if source == "log" and method != "filter":
        return MapPriorChoice(
            "deconditioned", "the bundle states map_source log: its map was made from this log"
        )
    if source == "log":
        return MapPriorChoice(
            "independent",
            "the bundle states map_source log, but the filter cannot de-condition the map "
            "(its pose at t reads only the log before t): the log's information about the map "
            "counts twice, the covariance is too small; the smoother or the batch de-condition it",
        )
    if source == "independent":
        return MapPriorChoice(
            "independent", "the bundle states map_source independent: a map made apart from its log"
        )
    return MapPriorChoice(
        "independent",
        "assumed: the bundle does not state map_source; were its map made from this log (an "
        "EKF-SLAM's), the recovered covariance would be too small (state map_source log in "
        "bundle.json)",
    )


def _check_options(method: str, gate: float | None, map_prior: str = DEFAULT_MAP_PRIOR) -> None:
    """:class:`~relation_metric.errors.InputError` for an unknown method or map prior, the
    deconditioned map prior with the filter, or a gate outside ``(0, 1)``, before any work."""
    if method not in METHODS:
        raise InputError(f"unknown method {method!r}; expected one of {', '.join(METHODS)}")
    if map_prior not in MAP_PRIOR_CHOICES:
        raise InputError(
            f"unknown map prior {map_prior!r}; expected one of {', '.join(MAP_PRIOR_CHOICES)}"
        )
    if map_prior == "deconditioned" and method == "filter":
        raise InputError(
            "map prior 'deconditioned' needs the smoother or the batch: the filter's pose at "
            "time t reads only the log before t, and its error's correlation with a map made "
            "from the whole log has no closed form; expected method smoother or batch, or map "
            "prior independent"
        )
    if gate is not None and not 0.0 < gate < 1.0:
        raise InputError(f"gate probability must be in (0, 1), got {gate}")


def _robust_settings(
    inp: FilterInput,
    kw: Mapping[str, object],
    robust: str | None,
    threshold: float | None,
    scale: float | str,
) -> RobustSettings | None:
    """The robust update :func:`recover` runs the filter with (``None``: the plain EKF).

    ``c`` is ``threshold`` or the kind's default; ``scale="auto"`` estimates ``ŝ`` from a
    first, plain pass of the filter with the same gate and re-entry rule (``kw``), re-entering
    rather than raising: the scale is a statistic of the whole log.
    """
    if robust is None:
        return None
    c = float(threshold) if threshold is not None else ROBUST_DEFAULTS[robust]
    if scale == "auto":
        plain = run_filter(inp, **{**kw, "on_divergence": "reenter"})  # type: ignore[arg-type]
        s = _nis_scale(plain)
        if threshold is None and robust == "redescending" and _heavy_tailed(plain.nis, s):
            c = HEAVY_TAIL_C
    else:
        s = float(scale)
    return RobustSettings(kind=robust, threshold=c, scale=s, effective=c * s)


def _heavy_tailed(nis: Array, scale: float) -> bool:
    """Whether a plain pass's innovations, standardised by ``ŝ²``, have more beyond the
    99.9 % χ²(2) bound than consistent ones could: above the Poisson 99.99 % quantile of
    that count and 0.5 % of them (the map–log lamp's red rule)."""
    from relation_metric.consistency import nis_tail_level

    v = np.asarray(nis, dtype=np.float64)
    v = v[np.isfinite(v)] / (scale * scale)
    return nis_tail_level(int((v > chi2_quantile(0.999, 2)).sum()), v.size) == "red"


@dataclass(frozen=True)
class _Estimate:
    """The poses and covariances of a method, before the finiteness check."""

    poses: Array
    covariances: Array
    iterations: int = 0
    costs: BatchCosts | None = None
    map_correction: Array | None = None
    map_loadings: Array | None = None
    independent_covariances: Array | None = None
    map_link: Array | None = None


def _estimate(
    method: str,
    inp: FilterInput,
    fr: FilterResult,
    mu: MapUncertainty,
    weights: Array | None,
    map_prior: str = "independent",
) -> _Estimate:
    """The filter's poses, or the smoother's or batch's refinement of them.

    The smoother and the batch start from the RTS smoother of the filter run (it linearises
    along the run) and step over all poses and the map correction
    (:func:`recovery.batch_refinement.refine`, the filter's re-entries as extra process noise:
    :func:`reentry_relaxed`), the smoother until a step changes χ² by less than one unit, the
    batch to numerical convergence.
    """
    if method == "filter":
        return _Estimate(fr.poses, fr.covariances)
    from recovery.batch_refinement import refine

    br = refine(
        reentry_relaxed(inp, fr),
        smooth(fr).poses,
        used=fr.status == USED,
        weights=weights,
        map_factor=mu.factor,
        map_prior=map_prior,
        **(_SMOOTHER_STOP if method == "smoother" else _BATCH_STOP),
    )
    return _Estimate(
        br.poses,
        br.covariances,
        iterations=br.iterations,
        costs=(
            BatchCosts(cost_initial=br.cost_initial, cost_final=br.cost_final)
            if method == "batch"
            else None
        ),
        map_correction=None if br.map_correction is None else readonly(br.map_correction),
        map_loadings=br.map_loadings,
        independent_covariances=br.independent_covariances,
        map_link=br.map_link,
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
    from relation_metric.trajectory import MAX_COORDINATE

    # a position beyond MAX_COORDINATE (the bound of every position slamrel reads) is a
    # recovery that left the map's scale, not a trajectory to write
    far = np.asarray(~(np.abs(poses[:, :2]) <= MAX_COORDINATE).all(axis=1), dtype=bool)
    bad = ~(np.isfinite(poses).all(axis=1) & np.isfinite(covs).all(axis=(1, 2))) | far
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
        what = (
            f"position ({poses[k, 0]:.6g}, {poses[k, 1]:.6g}) beyond {MAX_COORDINATE:.0e} m"
            if far[k] and np.isfinite(poses[k]).all()
            else "non-finite or non-PSD covariance"
        )
        raise DivergenceError(f"recovery diverged at t={float(times[k]):.6f} s (pose {k}): {what}")
    return covs, n_rep
