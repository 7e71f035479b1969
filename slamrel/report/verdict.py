"""The verdict that opens a ``slamrel run`` report: how good the run is, and how sure we are.

Each line is a :class:`Judgement`: a quantity, its value, a level and the rule that gave the
level, written next to it on the page. Every lamp judges its quantity against **what correct
models produce** — the χ² law of a consistent estimator's NEES and NIS, the expected loss of
the robust weights — with a stated allowance for the recovery's approximations; the rules
were checked on runs healthy by construction and on broken ones
(:mod:`slamrel.studies.calibration`, rates in docs/verdict.md), and a test keeps them so.

Lamps (``green`` / ``amber`` / ``red``):

* **recovered vs dead reckoning** — ratio ``r`` of the mean absolute translation relation
  errors [m]: with correct models the map only adds information, so green ``r ≤ 1``, amber
  ``r ≤ 1.5``, red above (the map or the models make the trajectory worse than odometry);
* **online vs recovered** (when both exist) — ratio of the same errors: the online one worse
  (its map was the run's map at the time, the recovery's the final one) green within a factor
  :data:`ONLINE_WORSE` ``[0]`` (4), amber within 8; the recovered one worse green within a
  factor 2, amber within 4; red beyond; *never greener than the consistency and map–log
  lamps*: two equally broken estimates agree, and agreement alone proves nothing;
* **consistency** — the mean NEES over its dof, ``q = ε̄ / d``, against the interval of the
  mean of ``n_eff`` independent χ²(d) values (:func:`~relation_metric.consistency.
  mean_chi2_interval`; ``n_eff`` the effective sample size of the NEES sequence,
  :func:`~relation_metric.consistency.effective_sample_size`: a recovered trajectory's NEES
  is correlated over time; for the smoother and the batch ``n_eff = h/3`` of the mean NEES's
  moment-matched ``g χ²(h)`` with the map's error every pose shares,
  :func:`~relation_metric.nees_law.shared_error_law`, docs/verdict.md). Overconfident:
  amber when ``q`` is above the 99 % interval *and* above :data:`OVERCONFIDENT` ``[0]``
  (1.5), red when above the 99.99 % interval and above ``OVERCONFIDENT[1]`` (3).
  Conservative: amber below the 99 % interval and below :data:`CONSERVATIVE` ``[0]`` (0.5),
  red below ``CONSERVATIVE[1]`` (0.1: covariances ten times the error's say nothing). The
  allowances are the recovery's approximations (linearisation; with a joint map covariance
  the recovered covariance is conservative, docs/verdict.md gives the calibration);
* **NEES excursions** — runs of at least :data:`MIN_EXCURSION` consecutive steps with NEES
  above the 95 % single-pose band (:func:`nees_excursions`, no merging of runs), as a share
  of the steps: green ≤ 5 %, amber ≤ 20 %, red above. A consistent estimator is above the
  band 2.5 % of the time, in runs when its errors are correlated. Not the recovery's NEES
  *blow-ups* of the map–log section (beyond the 99.99 % single-pose bound for at least
  ``max_outlier_run`` poses): an excursion says the covariance is locally optimistic, a
  blow-up that the estimate is lost;
* **map–log agreement** — the innovations of the recovery's filter (its NIS, χ²(2) for
  consistent models, :class:`recovery.results.NisStats`): the mean over 2, ``q``, and the
  tail, the innovations beyond the 99.9 % bound (plus the gated ones) against the 0.1 % a
  consistent filter has (a Poisson count). Red when ``q`` is outside ``[0.5, 1.5]`` or the
  tail exceeds its Poisson 99.99 % quantile and 0.5 % of the innovations; amber when ``q`` is
  outside ``[0.75, 1.25]`` or the tail exceeds its 99.9 % quantile and 0.2 %. Wrong
  associations, a map that does not fit the log and mis-stated noise show here;
* **map consistency** (when the map states a covariance and the true landmarks are known) —
  the map's NEES ``eᵀ Σ⁻¹ e`` over its ``2K`` dof (``e`` the error of the ``K`` matched
  landmarks in the NEES frame: joint covariance, or the marginals as independent blocks),
  against the χ²(2K) interval, with the allowances of the consistency lamp;
* **filter vs smoother agreement** (no truth needed) — the recovery's filter minus its
  smoother, ``d``, against ``P_f − P_s``, its covariance for consistent estimates
  (:mod:`relation_metric.agreement`): ``q`` = mean ``dᵀ(P_f − P_s)⁻¹d`` over its dof, judged as
  the consistency lamp on the overconfident side (``q < 1`` is green: a map made from the log
  makes the two closer than stated, docs/verdict.md); a filter that diverges is red here;
* **down-weighted information** (robust ``redescending``, the default) — the share of the
  measurements' information the robust weights took, against its expectation for
  consistent innovations, ``E[1 − w] = e^{−a} − a E₁(a)``, ``a = c²/2`` (χ²(2) innovations,
  ``w = min(1, c²/d²)``): green ≤ 1.5× or within the 99.9 % quantile of its sampling law
  (:func:`downweight_loss_bound`: at the default ``c = √χ²₂(0.999)`` only 0.1 % of
  consistent innovations are touched, a few measurements' worth per run), red > 3× and
  beyond the 99.99 % quantile, amber between. (A robust estimator always down-weights some
  perfectly Gaussian innovations — 22 % of them at ``c = 1.75`` — so the fraction itself is
  no finding.)

Without ground truth the lamps that need it (the NEES's consistency and excursions, the map's
consistency) are lines at the level ``not judged`` that say what they need; the accuracy lamps
are judged on the reference relations when the user gave some (``--relations``), and are not
judged otherwise, when the online estimate's difference from the recovered one is an
information line instead. Lines that are not judged do not set the overall level.

Information lines (``info``, not lamps; they do not set the overall level): the map's edge
error and OSPA — accuracies in metres, which a healthy map has as large as its stated
covariance allows (the map consistency lamp judges that) — and the down-weighted
information of the ``huber``/``cauchy`` updates (iterated weights: no closed expectation).

The overall level is the worst lamp; "how sure" states the evidence (relations, poses,
matched landmarks). The verdict judges typed results (:class:`RunFacts`, read from a
:class:`slamrel.runs.result.RunResult`), the same the tables and ``metrics.json`` are written
from.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relation_metric.agreement import Agreement, estimate_agreement
from relation_metric.consistency import (
    FAR_LAG,
    NeesSummary,
    chi2_quantile,
    effective_sample_size,
    flag_runs,
    mean_chi2_interval,
    nis_persistence,
    nis_tail_expected,
    nis_tail_level,
)
from relation_metric.errors import InputError
from relation_metric.nees_law import NeesLaw

if TYPE_CHECKING:
    from recovery.clock_offset import ClockOffset
    from recovery.placement import Placement
    from recovery.results import Recovery, RecoveryCounts, RobustSettings
    from relation_metric.evaluate import Evaluation
    from slamrel.runs.result import MapSummary, RunResult

__all__ = [
    "Judgement",
    "Verdict",
    "RunFacts",
    "MapNees",
    "run_verdict",
    "nees_excursions",
    "expected_downweight_loss",
    "downweight_loss_bound",
    "map_nees",
    "map_log_stats",
    "MapLogStats",
    "gaussian_breaks",
    "MIN_EXCURSION",
    "LEVELS",
    "INFO",
    "NOT_JUDGED",
    "OVERCONFIDENT",
    "CONSERVATIVE",
    "ONLINE_WORSE",
    "RECOVERED_WORSE",
]

LEVELS = ("green", "amber", "red")
#: The level of an information line: shown, not a lamp (it does not set the overall level).
INFO = "info"
#: The level of a lamp that could not be judged (it needs ground truth the run does not have).
NOT_JUDGED = "not judged"
#: Shortest run of consecutive steps above the 95 % NEES band that counts as an excursion.
MIN_EXCURSION = 3
#: Allowances on ``q = mean NEES / dof`` above 1: amber beyond the first, red beyond the
#: second (each only when also outside the χ² interval of the mean).
OVERCONFIDENT = (1.5, 3.0)
#: Allowances below 1: amber below the first (and the 99 % interval), red below the second.
CONSERVATIVE = (0.5, 0.1)
#: The online-vs-recovered lamp, online error over recovered error ``r ≥ 1``: green up to the
#: first, amber up to the second. Healthy reference EKF-SLAM runs (120 standard, 120 OC, seeds
#: 40–49, docs/verdict.md): ``r`` median 1.58 / 1.61, 95th percentile 2.86 / 2.25, at most
#: 4.23 / 3.09 — the online pose used the map as it was then, the recovery the final one.
ONLINE_WORSE = (4.0, 8.0)
#: The same lamp with the recovered trajectory worse, ``1/r``: the final map or the recovery
#: lost what the run had.
RECOVERED_WORSE = (2.0, 4.0)
#: The map–log lamp: green/amber ranges of the mean NIS over its dof.
NIS_RANGES = ((0.75, 1.25), (0.5, 1.5))
#: The filter-vs-smoother lamp's allowance on ``q`` (amber/red only above it): healthy runs
#: by construction reach 2.3 (the joint map error, shared by every pose, correlates the
#: statistic beyond what ``n_eff`` sees), overconfident filters and 3× map errors start at 4.7
#: (docs/verdict.md).
AGREEMENT_ALLOWANCE = 3.0
#: A map NEES per dof below this is rounding, not an error: the reference landmarks are the
#: map's own numbers (MRCLAM's surveyed map against the same survey gives ~1e-28); no map
#: estimated from data comes within 1e-12 of its truth in units of its own σ.
SAME_MAP_Q = 1e-12
#: The NIS tail probability (innovations beyond the 99.9 % bound are the tail).
NIS_TAIL = 0.999


@dataclass(frozen=True)
class Judgement:
    """One line of the verdict: ``what`` is ``value`` → ``level`` by ``rule``.

    ``key`` names the lamp for programs (``accuracy``, ``online``, ``consistency``,
    ``excursions``, ``map_log``, ``map_consistency``, ``measurements``, ``map_edge``,
    ``map_ospa``); ``measure`` is the number the rule judged (e.g. ``q``), for studies.
    """

    what: str
    value: str
    level: str  # one of LEVELS, or INFO
    rule: str
    key: str = ""
    measure: float = float("nan")


@dataclass(frozen=True)
class Verdict:
    """The overall level (worst lamp), the evidence sentence and the lines."""

    level: str
    evidence: str
    lines: Sequence[Judgement]


def _g(x: float) -> str:
    """A number with 3 significant digits, never a numpy repr."""
    return f"{float(x):.3g}"


def _level(x: float, green: float, amber: float) -> str:
    """green when ``x ≤ green``, amber when ``x ≤ amber``, else red."""
    return "green" if x <= green else "amber" if x <= amber else "red"


def _worst(*levels: str) -> str:
    return max((lv for lv in levels if lv in LEVELS), key=LEVELS.index, default="green")


@dataclass(frozen=True)
class MapNees:
    """The map's NEES against its stated covariance (:func:`map_nees`).

    Attributes
    ----------
    value : float
        ``eᵀ Σ⁻¹ e`` over the matched landmarks.
    landmarks : int
        ``K``, the matched landmarks (the dof is ``2K``).
    covariance : str
        ``"joint"`` or ``"marginal"`` (blocks taken as independent).
    placement : float or None
        The part of ``value`` that is the map's placement, a rigid motion of the whole map
        (:func:`recovery.anchoring.rigid_split`'s ``nees_rigid``, 3 dof; the rest, its shape,
        has ``2K − 3``): with the joint covariance and ``K ≥ 3``, else None.
    """

    value: float
    landmarks: int
    covariance: str
    placement: float | None = None

    @property
    def dof(self) -> int:
        return 2 * self.landmarks


def map_nees(
    map_xy: ArrayLike,
    truth_xy: ArrayLike,
    *,
    joint: ArrayLike | None = None,
    marginals: ArrayLike | None = None,
) -> MapNees | None:
    """The NEES of the map rows ``map_xy`` (K, 2) against ``truth_xy`` (K, 2), both in the
    map's frame, with the joint covariance of those rows ``joint`` (2K, 2K) or their
    marginals (K, 2, 2). ``None`` when neither is given, or the covariance is singular."""
    e = np.asarray(map_xy, dtype=np.float64) - np.asarray(truth_xy, dtype=np.float64)
    k = e.shape[0]
    if k == 0:
        return None
    try:
        placement = None
        if joint is not None:
            c = np.asarray(joint, dtype=np.float64)
            v = float(e.ravel() @ np.linalg.solve(c, e.ravel()))
            kind = "joint"
            placement = _placement_nees(map_xy, truth_xy, c) if k >= 3 else None
        elif marginals is not None:
            m = np.asarray(marginals, dtype=np.float64)
            v = float(np.einsum("ki,ki->", e, np.linalg.solve(m, e[..., None])[..., 0]))
            kind = "marginal"
        else:
            return None
    except np.linalg.LinAlgError:
        return None
    if not math.isfinite(v):
        return None
    return MapNees(v, k, kind, placement)


def _placement_nees(
    map_xy: ArrayLike, truth_xy: ArrayLike, joint: NDArray[np.float64]
) -> float | None:
    """The placement's share of the map's NEES (:func:`recovery.anchoring.rigid_split`), or
    None where the split is not defined (a covariance that is not positive definite)."""
    from recovery.anchoring import rigid_split

    try:
        return rigid_split(map_xy, truth_xy, joint).nees_rigid
    except InputError:
        return None


def expected_downweight_loss(threshold: float) -> float:
    """``E[1 − w]`` of the redescending weight ``w = min(1, c²/d²)`` when ``d²`` is χ²(2):
    ``e^{−a} − a E₁(a)``, ``a = c²/2`` (``E₁`` the exponential integral).

    >>> round(expected_downweight_loss(1.75), 4)
    0.07
    """
    from scipy.special import exp1

    a = 0.5 * float(threshold) ** 2
    return float(math.exp(-a) - a * exp1(a))


def downweight_loss_bound(threshold: float, n: int, p: float) -> float:
    """The ``p`` quantile of ``S = Σ (1 − w_i)`` over ``n`` consistent innovations (χ²(2)
    NIS), in measurements, for the redescending weight at ``c = threshold``.

    ``S`` is a compound Poisson sum (only innovations beyond ``c`` contribute): skewed when
    ``c`` is far in the tail, normal when it is not. Matched on its mean ``n μ`` and variance
    ``n m₂`` (``μ = E[1 − w]``, ``m₂ = E[(1 − w)²] = (1 + a) e^{−a} − (2a + a²) E₁(a)``,
    ``a = c²/2``) by a scaled Poisson count, ``S ≈ θ N``, ``θ = m₂/μ``,
    ``N ~ Poisson(n μ²/m₂)``: the quantile is ``θ F⁻¹(p)``.
    """
    from scipy.special import exp1
    from scipy.stats import poisson

    a = 0.5 * float(threshold) ** 2
    mu = expected_downweight_loss(threshold)
    m2 = float((1.0 + a) * math.exp(-a) - (2.0 * a + a * a) * exp1(a))
    if n <= 0 or mu <= 0.0 or m2 <= 0.0:
        return 0.0
    return float(m2 / mu * poisson.ppf(p, n * mu * mu / m2))


@dataclass(frozen=True)
class RunFacts:
    """What the verdict judges: typed parts of a run's results (:meth:`of`).

    Attributes
    ----------
    main : str
        The main estimate (``recovered``, else ``online``, else ``dead_reckoning``).
    translation_errors : mapping of str → float
        Per estimate, the mean absolute translation relation error over all relation sets [m].
    relations : int
        Relations the main estimate was scored on (associated: unassociated ones are not).
    nees : NeesSummary or None
        The main estimate's NEES summary (3 dof), when it has covariances.
    nees_values : ndarray, shape (steps,), or None
        Its per-step NEES (for the excursions and the effective sample size).
    map : MapSummary or None
        The landmark-map comparison, when the bundle has the true landmarks.
    counts : RecoveryCounts or None
        The recovery's measurement counts (``None`` when no recovery ran).
    poses : int or None
        Poses of the recovered trajectory.
    nis : ndarray, shape (J,), or None
        The recovery filter's NIS per measurement (NaN where it has none).
    robust : RobustSettings or None
        The robust update the recovery used (``None``: plain EKF).
    map_nees : MapNees or None
        The map's NEES against its stated covariance.
    online_nees : NeesSummary or None
        The online estimate's NEES summary, when it came with covariances.
    online_nees_values : ndarray or None
    unassociated : int or None
        Relations generated for the main estimate that could not be scored (no pose near an
        end); ``None``: not known.
    has_truth : bool
        Whether the run has a ground-truth trajectory (without, lamps that need it are said
        to be not judged).
    scored_on : str
        What ``translation_errors`` were scored on, when not on relations drawn from the
        ground truth (``"the reference relations"``); empty otherwise.
    has_online : bool
        Whether the run has an online estimate.
    online_difference : float or None
        Without ground truth: the online estimate's mean abs translation relation error on
        relations drawn from the recovered trajectory [m] (their difference).
    online_difference_relations : int
        The relations it was computed on.
    nis_landmarks : ndarray of int, shape (J,), or None
        The landmark of each ``nis`` value's measurement (``None``: not known; the NIS's
        correlation is then taken along the measurement order).
    """

    main: str
    translation_errors: Mapping[str, float]
    relations: int
    nees: NeesSummary | None = None
    nees_values: NDArray[np.float64] | None = None
    map: MapSummary | None = None
    counts: RecoveryCounts | None = None
    poses: int | None = None
    nis: NDArray[np.float64] | None = None
    robust: RobustSettings | None = None
    map_nees: MapNees | None = None
    online_nees: NeesSummary | None = None
    online_nees_values: NDArray[np.float64] | None = None
    unassociated: int | None = None
    has_truth: bool = True
    scored_on: str = ""
    has_online: bool = False
    online_difference: float | None = None
    online_difference_relations: int = 0
    nis_landmarks: NDArray[np.int64] | None = None
    agreement: Agreement | None = None
    nees_law: NeesLaw | None = None
    placement: Placement | None = None
    #: The bundle states a persisting measurement error (``sensor_model.persisting``), which
    #: the recovery holds in its state (:mod:`recovery.persisting`).
    persisting_stated: bool = False
    #: The share of gross errors the bundle states (``sensor_model.outlier_share``; 0: none).
    outlier_share: float = 0.0
    #: The measurements' clock offset, searched where the map–log lamp is not green
    #: (:mod:`recovery.clock_offset`; ``None``: not searched).
    clock: ClockOffset | None = None

    @classmethod
    def of(cls, result: RunResult) -> RunFacts:
        main = result.main_estimate
        rec = result.recovery_result
        curve = result.nees.get(main)
        placed = result.nees_placement if main == "recovered" else None
        if placed is not None:  # the recovered NEES in the map's frame (its placement out)
            curve = placed.curve
        online = result.nees.get("online") if main != "online" else None
        errors, scored, scored_on = _scores_of(result, main)
        diff = result.online_vs_recovered
        return cls(
            main=main,
            translation_errors=errors,
            relations=0 if scored is None else int(scored.valid.sum()),
            nees=None if curve is None else curve.summary,
            nees_values=None if curve is None else curve.values,
            map=result.map_summary,
            counts=None if rec is None else rec.counts,
            poses=None if rec is None else len(rec.trajectory),
            nis=None if rec is None else np.asarray(rec.nis, dtype=np.float64),
            nis_landmarks=None if rec is None else result.bundle.measurement_landmarks,
            persisting_stated=result.bundle.sensor.persisting is not None,
            outlier_share=result.bundle.sensor.outlier_share or 0.0,
            clock=result.clock_offset,
            robust=None if rec is None else rec.robust,
            map_nees=_map_nees_of(result),
            online_nees=None if online is None else online.summary,
            online_nees_values=None if online is None else online.values,
            unassociated=None if scored is None else int((~scored.valid).sum()),
            has_truth=result.has_truth,
            scored_on=scored_on,
            has_online="online" in result.estimates,
            online_difference=None if diff is None else diff.all.translation.abs.mean,
            online_difference_relations=0 if diff is None else int(diff.all.valid.sum()),
            agreement=_agreement_of(rec),
            nees_law=None if curve is None or main != "recovered" else _nees_law_of(result),
            placement=None if placed is None else placed.placement,
        )


def _scores_of(result: RunResult, main: str) -> tuple[dict[str, float], Evaluation | None, str]:
    """The accuracy the verdict judges: per estimate the mean abs translation relation error
    on the relations drawn from the ground truth, else on the reference relations the user
    gave (estimates with no scored relation left out); the main estimate's evaluation; what
    they were scored on (empty: the ground truth)."""
    if result.evaluations:
        errors = {k: evs.all.translation.abs.mean for k, evs in result.evaluations.items()}
        return errors, result.evaluations[main].all, ""
    if result.reference is None:
        return {}, None, ""
    scores = result.reference.scores
    errors = {k: ev.translation.abs.mean for k, ev in scores.items() if ev.valid.any()}
    return errors, scores.get(main), "the reference relations"


def _agreement_of(rec: Recovery | None) -> Agreement | None:
    """The recovery's own filter run against its smoother (or batch): no truth needed. The
    smoother's covariances are taken under the filter's map model (the independent prior:
    :attr:`~recovery.results.Recovery.agreement_covariances` when the map was de-conditioned),
    so that ``P_f − P_s`` is ``d``'s covariance under one model."""
    if rec is None or rec.filter_poses is None or rec.filter_covariances is None:
        return None
    ps = rec.covariances if rec.agreement_covariances is None else rec.agreement_covariances
    return estimate_agreement(rec.filter_poses, rec.filter_covariances, rec.trajectory.poses, ps)


def _nees_law_of(result: RunResult) -> NeesLaw | None:
    """The law of the recovered mean NEES with the map's error every pose shares
    (:func:`~relation_metric.nees_law.shared_error_law`), on the poses the NEES is computed at
    (:func:`slamrel.runs.nees.recovery_nees`); the log's own serial correlation from the NEES
    sequence's ``n_eff``. ``None`` without map loadings (the filter)."""
    from relation_metric.nees_law import shared_error_law
    from slamrel.runs.nees import at_truth_times

    rec, truth = result.recovery_result, result.bundle.groundtruth
    curve = result.nees.get("recovered")
    if rec is None or rec.map_loadings is None or truth is None or curve is None:
        return None
    placed = result.nees_placement
    if placed is not None:  # the shared error left once the map's placement is known
        curve = placed.curve
        covs, loadings = placed.placement.covariances[1:], placed.placement.loadings[1:]
    else:
        got = at_truth_times(rec.trajectory, truth)
        if got is None:
            return None
        rows = got[1][1:]  # the NEES leaves the prior out
        covs, loadings = rec.covariances[rows], rec.map_loadings[rows]
    v = np.asarray(curve.values, dtype=np.float64)
    if covs.shape[0] != v.size or not np.isfinite(v).all() or v.size < 2:
        return None
    tau = v.size / effective_sample_size(v)
    try:
        return shared_error_law(covs, loadings, local_factor=tau)
    except InputError:
        return None


def _map_nees_of(result: RunResult) -> MapNees | None:
    """The map's NEES in the NEES frame: the true landmarks moved into the map's frame."""
    from slamrel.runs.nees import map_pairs

    b, mc = result.bundle, result.map_comparison
    if mc is None or b.landmarks_groundtruth is None:
        return None
    rows, truth = map_pairs(mc, result.nees_frame)
    est = np.asarray(b.map_xy)[rows]
    if b.map_covariance is not None:
        idx = np.stack((2 * rows, 2 * rows + 1), axis=1).ravel()
        return map_nees(est, truth, joint=np.asarray(b.map_covariance)[np.ix_(idx, idx)])
    marg = np.asarray(b.map_marginals)[rows]
    if not np.any(marg):
        return None  # a map without uncertainty
    return map_nees(est, truth, marginals=marg)


def nees_excursions(nees: ArrayLike, high: float, *, min_length: int = MIN_EXCURSION) -> list[int]:
    """Lengths of the runs of ≥ ``min_length`` consecutive values above ``high`` (no merging)."""
    st, en = flag_runs(np.asarray(nees, dtype=np.float64) > high, min_length)
    return (en - st + 1).tolist()


def run_verdict(facts: RunFacts) -> Verdict:
    """The verdict of a run from its typed results (:meth:`RunFacts.of` a ``RunResult``)."""
    health = _with_causes(
        facts, [*_consistency_lines(facts), *_map_log_lines(facts), *_map_consistency_lines(facts)]
    )
    lines = [
        *_accuracy_lines(facts, health),
        *health,
        *_agreement_lines(facts),
        *_measurement_lines(facts),
        *(_map_lines(facts.map) if facts.map is not None else []),
    ]
    if not facts.has_truth:
        lines += _not_judged_lines(facts, lines)
    lamps = [ln.level for ln in lines if ln.level in LEVELS]
    level = max(lamps, key=LEVELS.index) if lamps else "amber"
    return Verdict(level, _evidence(facts), lines)


def gaussian_breaks(facts: RunFacts) -> list[str]:
    """The Gaussian white-noise assumptions the recovery filter's innovations break, each a
    sentence with its number (empty: none shown). Needs no ground truth.

    * **clock offset** — the measurements restamped by the offset the recovery filter's NIS
      point to (:mod:`recovery.clock_offset`, searched where the map–log lamp is not green)
      make the lamp greener by its own rule, the offset beyond chance: said with
      the offset, the lamp's ``q`` and tail before and after, and the likelihood ratio. A
      tail the offset explains is then not also called heavy.
    * **heavy tails** — more innovations beyond the 99.9 % bound ``b`` of χ²(2) than a
      consistent filter's 0.1 % (above the Poisson 99.9 % quantile and 0.2 %) while the bulk
      is no wider than stated (median NIS ≤ 1.25 × 2 ln 2): outlying measurements, heavy-tailed
      noise or wrong associations. Said with the mean NIS of the rest over its expectation
      ``E[χ²₂ | ≤ b] = 2 − b e^{−b/2} / (1 − e^{−b/2})``. A share of gross errors the bundle
      states (``sensor_model.outlier_share``) is expected in the tail: named only beyond it.
    * **correlated in time** — the rank correlation of the NIS of successive sightings of
      one landmark exceeds that of sightings ``FAR_LAG`` apart by ``ρ_s`` above
      ``NIS_CORRELATION`` and its 99.9 % bound ``3.29 √(1/n₁ + 1/n₁₀)`` (pairs each more
      than 30): an error that fades over sightings (a fixed map error does not). For Gaussian
      innovations correlated ``ρ``, squared ones correlate ``ρ²``: ``ρ ≈ √ρ_s``, and a
      white-noise filter takes a run of such measurements for about ``(1 + ρ)/(1 − ρ)`` times
      the information it holds (AR(1)), which is how much too high to expect the NEES. The
      one rule is :func:`~relation_metric.consistency.nis_persistence`, which
      :func:`recovery.recover.recover` also uses for its second pass.
    """

    if facts.nis is None:
        return []
    v = np.asarray(facts.nis, dtype=np.float64)
    v = v[np.isfinite(v)]
    if v.size < 50:
        return []
    causes = []
    clock = _clock_cause(facts)
    if clock is not None:
        causes.append(clock[0])
    bound = chi2_quantile(NIS_TAIL, 2)
    tail = int((v > bound).sum())
    median = float(np.median(v))
    stated = facts.outlier_share
    heavy = nis_tail_level(tail, v.size, NIS_TAIL, stated) != "green"
    if clock is not None and clock[1]:  # the tail is the offset's: no heavy tail of its own
        heavy = False
    if heavy and median <= 1.25 * 2 * math.log(2):
        rest = inlier_nis_ratio(v, bound)
        also = f" with {100 * stated:.2g} % gross errors stated" if stated else ""
        causes.append(
            f"heavy tails: {100 * tail / v.size:.2g} % of the innovations beyond the 99.9 % "
            f"bound ({100 * (1 - NIS_TAIL):.1g} % expected{also}) while the bulk is no wider than "
            f"stated (median NIS {_g(median)}, {_g(2 * math.log(2))} expected); the others' "
            f"mean NIS is {_g(rest)}× its expectation"
            + (
                f"; the {facts.robust.kind} update down-weighted them"
                if facts.robust is not None
                else "; the plain EKF used them at full weight (--robust down-weights them)"
            )
        )
    per = nis_persistence(facts.nis, facts.nis_landmarks)
    if per.significant and facts.persisting_stated:
        causes.append(
            f"innovations correlated in time: rank correlation of the NIS of successive "
            f"sightings of a landmark {_g(per.near)}, of sightings {FAR_LAG} apart {_g(per.far)}, "
            "with the bundle's persisting error in the recovery's state: the recovery already "
            "holds a persisting value of the errors, so this is not information counted twice; "
            "a persisting size (variance) of the errors, which no stated model holds, "
            "correlates the NIS so"
        )
    elif per.significant:
        causes.append(
            f"innovations correlated in time: rank correlation of the NIS of successive "
            f"sightings of a landmark {_g(per.near)}, of sightings {FAR_LAG} apart {_g(per.far)} "
            f"(equal for white innovations in a map with a fixed error), errors correlated "
            f"about √{_g(per.rho_s)} = {_g(per.rho)} from one sighting to the next: a white-noise "
            f"filter counts such measurements as about {_g(per.factor)}× the "
            "information they hold (the NEES that much too high); a persisting sensor or "
            "odometry error, not in the models"
        )
    return causes


def _clock_cause(facts: RunFacts) -> tuple[str, bool] | None:
    """The clock-offset sentence and whether the restamped log's tail is green; None unless
    the offset is significant (:attr:`recovery.clock_offset.ClockOffset.significant`) and
    the map–log lamp, judged by its own rule on the restamped log, would be
    greener than it is (an offset that leaves the lamp as it is does not explain it)."""
    c = facts.clock
    if c is None or not (c.significant and c.material) or facts.nis is None:
        return None
    gated = 0 if facts.counts is None else facts.counts.gated
    now = map_log_stats(facts.nis, gated, facts.outlier_share)
    then = map_log_stats(c.nis_at_offset, gated, facts.outlier_share)
    if now is None or then is None or LEVELS.index(then.level) >= LEVELS.index(now.level):
        return None
    when = "earlier" if c.offset < 0 else "later"
    lag = "the motion lags them" if c.offset < 0 else "the motion leads them"
    quiet = nis_tail_level(then.tail, then.count, NIS_TAIL, facts.outlier_share) == "green"
    return (
        f"clock offset: the log agrees best with its motion with every measurement restamped "
        f"by {c.offset:+.3g} s (taken {abs(c.offset):.3g} s {when} than stamped: {lag}); "
        f"restamped, q = {_g(then.q)} and {100 * then.share:.2g} % of the innovations beyond "
        f"the 99.9 % bound (now {_g(now.q)} and {100 * now.share:.2g} %): the map–log lamp "
        f"{then.level} instead of {now.level}; the NIS trimmed at the bound falls "
        f"{100 * c.explained:.2g} % (likelihood ratio {c.likelihood_ratio:.0f} over "
        f"{c.count} innovations); correct the stamps (or the odometry's delay) before judging "
        "the run",
        quiet,
    )


def _with_causes(facts: RunFacts, health: Sequence[Judgement]) -> list[Judgement]:
    """The consistency, excursion and map–log lines that are not green, with the Gaussian
    assumptions the innovations break (:func:`gaussian_breaks`) named after their value."""
    causes = gaussian_breaks(facts)
    keys = ("consistency", "online_consistency", "excursions", "map_log")
    if not causes:
        return list(health)
    text = "; cause: " + "; ".join(causes)
    return [
        replace(ln, value=ln.value + text)
        if ln.key in keys and ln.level in ("amber", "red")
        else ln
        for ln in health
    ]


def _accuracy_lines(facts: RunFacts, health: Sequence[Judgement]) -> list[Judgement]:
    """The main estimate against dead reckoning, and the online estimate against it."""
    lines = []
    main, err = facts.main, facts.translation_errors
    on = f" (on {facts.scored_on})" if facts.scored_on else ""
    ours = err.get(main)
    dr = err.get("dead_reckoning") if main != "dead_reckoning" else None
    if ours is not None and dr is not None and dr > 0:
        r = ours / dr
        lines.append(
            Judgement(
                f"{main} vs dead reckoning{on}",
                f"{_g(ours)} m / {_g(dr)} m = {_g(r)}",
                _level(r, 1.0, 1.5),
                "ratio of the mean abs relation errors in translation; with correct models the "
                "map only adds information: green ≤ 1, amber ≤ 1.5, red above",
                "accuracy",
                r,
            )
        )
    online = err.get("online") if main != "online" else None
    if online is not None and ours is not None and ours > 0:
        r = online / ours
        spread = max(r, 1.0 / r) if r > 0 else float("inf")
        # the online estimate worse: the filter's map as it was then, the recovery's final
        # map is better (healthy EKF-SLAM runs: r up to 4.2, docs/verdict.md); the recovered
        # worse than the online one: the final map or the recovery lost what the run had
        agree = _level(r, *ONLINE_WORSE) if r >= 1.0 else _level(spread, *RECOVERED_WORSE)
        judged = [ln for ln in health if ln.key in ("consistency", "online_consistency", "map_log")]
        level = _worst(agree, *(ln.level for ln in judged))
        why = (
            ""
            if level == agree
            else f" — they agree, but {', '.join(ln.what for ln in judged if ln.level == level)}"
            f" is {level}"
        )
        lines.append(
            Judgement(
                f"online vs {main}{on}",
                f"{_g(online)} m / {_g(ours)} m = {_g(r)}{why}",
                level,
                "ratio of the same errors; the online one worse (its map was the run's map at "
                f"the time): green within a factor {ONLINE_WORSE[0]:g}, amber within "
                f"{ONLINE_WORSE[1]:g}; the {main} one worse: green within "
                f"{RECOVERED_WORSE[0]:g}, amber within {RECOVERED_WORSE[1]:g}; red beyond; never "
                "greener than the consistency and map–log lamps (two equally broken estimates "
                "agree)",
                "online",
                spread,
            )
        )
    return lines


def _not_judged_lines(facts: RunFacts, judged: Sequence[Judgement]) -> list[Judgement]:
    """Without ground truth: each lamp that needs it, said not to be judged and why, and the
    online estimate's difference from the recovered one (information) when it is not
    judged on reference relations."""
    have = {ln.key for ln in judged}
    main = facts.main
    needs = "needs ground truth (groundtruth.csv)"
    out = []
    if "accuracy" not in have and main != "dead_reckoning":
        out.append(
            (f"{main} vs dead reckoning", "accuracy",
             f"{needs} or reference relations (--relations)")
        )  # fmt: skip
    difference = []
    if facts.has_online and "online" not in have and main != "online":
        out.append(
            (f"online vs {main}", "online", f"{needs} or reference relations (--relations)")
        )  # fmt: skip
        if facts.online_difference is not None and facts.online_difference_relations:
            d = facts.online_difference
            difference.append(
                Judgement(
                    f"online vs {main} (difference)",
                    f"{_g(d)} m mean abs translation difference over "
                    f"{facts.online_difference_relations} relations drawn from the {main} "
                    "trajectory",
                    INFO,
                    "the online estimate scored on relations drawn from the recovered "
                    "trajectory: how far the two differ, not an error of either; no rule says "
                    "how far two estimates may differ, so not a lamp",
                    "online_difference",
                    d,
                )
            )
    return [*_not_judged(out), *difference, *_not_judged(_truth_lamps(facts, needs))]


def _truth_lamps(facts: RunFacts, needs: str) -> list[tuple[str, str, str]]:
    """The lamps that need the ground truth whatever else is given: the NEES's."""
    out = [
        (f"consistency ({facts.main})", "consistency", f"the NEES {needs}"),
        ("NEES excursions", "excursions", f"the NEES {needs}"),
    ]
    if facts.has_online:
        out.append(("consistency (online)", "online_consistency", f"the NEES {needs}"))
    if facts.map_nees is None:
        out.append(
            ("map consistency", "map_consistency",
             "the map's NEES needs the true landmarks in the ground truth's frame")
        )  # fmt: skip
    return out


def _not_judged(lines: Sequence[tuple[str, str, str]]) -> list[Judgement]:
    """``(what, key, why)`` as lines at the level :data:`NOT_JUDGED`."""
    return [
        Judgement(what, f"not judged: {why}", NOT_JUDGED, "not judged without ground truth", key)
        for what, key, why in lines
    ]


def _chi2_level(q: float, dof: int, n: float) -> tuple[str, str]:
    """The level of ``q`` (a mean of ``n`` χ²(dof) values over dof) and its direction."""
    lo99, hi99 = mean_chi2_interval(dof, max(n, 1.0), 0.99)
    lo4, hi4 = mean_chi2_interval(dof, max(n, 1.0), 0.9999)
    if q > hi99 and q > OVERCONFIDENT[0]:
        return ("red" if q > hi4 and q > OVERCONFIDENT[1] else "amber"), "overconfident"
    if q < CONSERVATIVE[1]:
        return "red", "conservative"
    if q < lo99 and q < CONSERVATIVE[0]:
        return "amber", "conservative"
    if q > hi99 or q < lo99:
        direction = "overconfident" if q > 1 else "conservative"
        return "green", f"{direction}, within the allowance"
    return "green", "consistent"


_CHI2_RULE = (
    "q = mean NEES / dof against the χ² interval of a mean of n_eff independent values; "
    "amber above the 99 % interval and q > 1.5, red above the 99.99 % one and q > 3 "
    "(overconfident); amber below the 99 % interval and q < 0.5, red q < 0.1 (conservative)"
)


def _nees_line(
    what: str,
    key: str,
    n: NeesSummary,
    values: NDArray[np.float64] | None,
    law: NeesLaw | None = None,
    *,
    borrowed: bool = False,
) -> Judgement:
    """The consistency lamp of one estimate; ``n_eff`` from ``law`` (the map's error shared
    by every pose) when given, else the NEES sequence's (:func:`effective_sample_size`).
    ``borrowed``: ``law`` is another estimate's of the same run (the online estimate judged
    with the recovered poses' law): the smaller of the two ``n_eff``."""
    v = None if values is None else np.asarray(values, dtype=np.float64)
    v = None if v is None else v[np.isfinite(v)]
    n_eff = effective_sample_size(v) if v is not None and v.size else 1.0
    shared = ""
    if law is not None and math.isfinite(law.n_eff) and law.n_eff > 0:
        if not borrowed:
            n_eff, shared = law.n_eff, " (the map's error shared by every pose)"
        elif law.n_eff < n_eff:
            n_eff = law.n_eff
            shared = " (the recovered poses' law: the map's error shared by every pose)"
    q = n.mean / n.dof
    level, direction = _chi2_level(q, n.dof, n_eff)
    return Judgement(
        what,
        f"NEES mean {_g(n.mean)} (dof {n.dof}): q = {_g(q)}, {direction}; n_eff {n_eff:.3g} "
        f"of {0 if v is None else v.size} steps{shared}; {100 * n.inside:.0f} % of steps "
        f"inside [{_g(n.band[0])}, {_g(n.band[1])}]",
        level,
        _CHI2_RULE,
        key,
        q,
    )


def _consistency_lines(facts: RunFacts) -> list[Judgement]:
    """NEES of the main estimate (and of the online one), and excursions above the band."""
    n, main = facts.nees, facts.main
    lines = []
    if n is not None:
        lines.append(
            _nees_line(
                f"consistency ({main})", "consistency", n, facts.nees_values, facts.nees_law
            )  # fmt: skip
        )
    if facts.online_nees is not None:
        lines.append(
            _nees_line(
                "consistency (online)",
                "online_consistency",
                facts.online_nees,
                facts.online_nees_values,
                facts.nees_law,
                borrowed=True,
            )  # fmt: skip
        )
    if n is not None and facts.placement is not None:
        lines[0] = replace(lines[0], value=lines[0].value + _placement_words(facts.placement))
    if n is not None and main == "recovered" and lines[0].level != "green":
        lines[0] = replace(lines[0], value=lines[0].value + _whose(lines[0], lines[1:2]))
    if n is not None and facts.nees_values is not None:
        v = np.asarray(facts.nees_values, dtype=np.float64)
        v = v[np.isfinite(v)]
        scale = _excursion_scale(lines[0])
        runs = nees_excursions(v, scale * float(n.band[1]))
        cover = sum(runs) / v.size if v.size else 0.0
        scaled = (
            f"; band × q = {_g(scale)}, the overconfidence the consistency lamp judges amber"
            if scale != 1.0
            else ""
        )
        lines.append(
            Judgement(
                "NEES excursions",
                f"{len(runs)} (longest {max(runs, default=0)} steps, "
                f"{100 * cover:.0f} % of {v.size}{scaled})",
                _level(cover, 0.05, 0.2),
                f"share of the steps in runs of ≥ {MIN_EXCURSION} steps with NEES above the 95 % "
                "band (a consistent estimator is above it 2.5 % of the time; where the "
                "consistency lamp is amber for overconfidence, the band × its q: the excursions "
                "judge what is local, not that scale again); green ≤ 5 %, amber ≤ 20 %, red above",
                "excursions",
                cover,
            )
        )
    return lines


def _placement_words(p: Placement) -> str:
    """What the recovered NEES leaves out: the map's placement, with its size and NEES."""
    sp = p.split
    nees = "" if sp.nees_rigid is None else f", NEES {_g(sp.nees_rigid)} for 3 dof"
    return (
        f"; in the map's frame: the map's placement (a rigid motion of the whole map, which "
        f"no relation sees: {math.degrees(sp.dtheta):.2g}°, {math.hypot(sp.dx, sp.dy):.2g} m"
        f"{nees}, on {p.landmarks} landmarks) taken out of each pose and its covariance"
    )


def _excursion_scale(consistency: Judgement) -> float:
    """``q`` of a consistency lamp that is amber for overconfidence (``q > 1``), else 1: the
    factor on the excursions' band, so that a uniform overconfidence already judged amber
    is not judged again, step by step, by the excursions (a red consistency lamp keeps it)."""
    q = consistency.measure
    if consistency.level == "amber" and q is not None and math.isfinite(q) and q > 1.0:
        return float(q)
    return 1.0


def _whose(recovered: Judgement, online: Sequence[Judgement]) -> str:
    """Whose computation a recovered NEES that is not green judges: the run's (the online
    filter is off the same way) or slamrel's recovery (the online one is consistent)."""
    if not online:
        return (
            "; judges the recovered covariance, slamrel's computation from the map's stated "
            "covariance and the run's models (no online covariances tell the filter's share)"
        )
    on = online[0]
    if on.level == "green":
        return (
            f"; the online filter is consistent (q = {_g(on.measure)}): this judges slamrel's "
            "recovery in the final map, not the filter's online estimate"
        )
    return (
        f"; the filter's own online NEES is off too (q = {_g(on.measure)}): the run's "
        "filter is inconsistent, and the recovery inherits its map's covariance"
    )


@dataclass(frozen=True)
class MapLogStats:
    """What the map–log lamp judges (:func:`map_log_stats`).

    Attributes
    ----------
    q : float
        Mean NIS over 2, or, with a stated share of gross errors, the mean within the bound
        over its expectation there (:func:`inlier_nis_ratio`); NaN without any NIS.
    tail, count : int
        Innovations beyond the 99.9 % bound (gated ones included), of ``count``.
    expected : float
        The tail a consistent filter has, the stated gross errors counted.
    level : str
        The lamp's level: the worse of ``q``'s and the tail's.
    """

    q: float
    tail: int
    count: int
    expected: float
    level: str

    @property
    def share(self) -> float:
        return self.tail / self.count


def map_log_stats(nis: ArrayLike, gated: int, outlier_share: float) -> MapLogStats | None:
    """The map–log lamp's rule on the recovery filter's NIS ``nis`` (J,) (NaN: none), with
    ``gated`` measurements gated and the bundle's stated share of gross errors. None without
    any innovation. The one home of the rule: the lamp, and the pipeline's question whether
    to look for a clock offset (:func:`slamrel.pipeline.score_bundle`)."""
    v = np.asarray(nis, dtype=np.float64)
    v = v[np.isfinite(v)]
    n = v.size + gated
    if n == 0:
        return None
    p = outlier_share
    bound = chi2_quantile(NIS_TAIL, 2)
    if p > 0:
        q = inlier_nis_ratio(v, bound)
    else:
        q = float(v.mean()) / 2.0 if v.size else float("nan")
    tail = int((v > bound).sum()) + gated
    (g_lo, g_hi), (a_lo, a_hi) = NIS_RANGES
    q_level = (
        "green" if g_lo <= q <= g_hi else "amber" if a_lo <= q <= a_hi else "red"
    ) if math.isfinite(q) else "amber"  # fmt: skip
    tail_level = nis_tail_level(tail, n, NIS_TAIL, p)
    return MapLogStats(q, tail, n, nis_tail_expected(NIS_TAIL, p) * n, _worst(q_level, tail_level))


def _map_log_lines(facts: RunFacts) -> list[Judgement]:
    """The recovery filter's NIS: its mean over the dof and its tail beyond the 99.9 % bound.

    With a stated share of gross errors the tail is judged against them too
    (:func:`~relation_metric.consistency.nis_tail_level`), and ``q`` is the mean NIS of the
    innovations within the bound over its expectation there (:func:`inlier_nis_ratio`): the
    stated gross errors are not the Gaussian bulk the mean judges."""
    if facts.nis is None:
        return []
    gated = 0 if facts.counts is None else facts.counts.gated
    st = map_log_stats(facts.nis, gated, facts.outlier_share)
    if st is None:
        return []
    p, q = facts.outlier_share, st.q
    mean = (
        f"mean NIS within the bound {_g(q)}× its expectation there (q); the bundle states "
        f"{100 * p:.2g} % gross errors (sensor_model.outlier_share), each counted in the tail "
        "expected"
        if p > 0
        else f"mean NIS {_g(2 * q)} (expected 2): q = {_g(q)}"
    )
    return [
        Judgement(
            "map–log agreement (NIS)",
            f"{mean}; {st.tail} of {st.count} innovations ({100 * st.share:.2g} %) beyond the "
            f"99.9 % bound (expected {_g(st.expected)})"
            + (f", {gated} gated among them" if gated else ""),
            st.level,
            "the recovery filter's innovations against χ²(2): green q in [0.75, 1.25], amber in "
            "[0.5, 1.5], red outside; the tail red above its Poisson 99.99 % quantile and 0.5 %, "
            "amber above the 99.9 % quantile and 0.2 % (with a stated share of gross errors: "
            "counted in the tail and added to both margins, q the mean within the bound over "
            "E[χ²(2) | within])",
            "map_log",
            q,
        )
    ]


def inlier_nis_ratio(v: NDArray[np.float64], bound: float) -> float:
    """Mean of the NIS ``v`` within ``bound`` over its expectation for χ²(2) innovations,
    ``E[χ²₂ | ≤ b] = 2 − b e^{−b/2} / (1 − e^{−b/2})`` (χ²₂ is exponential of mean 2); 1 for
    a consistent filter whatever lies beyond. NaN when none is within."""
    inside = v[v <= bound]
    if not inside.size:
        return float("nan")
    p = math.exp(-bound / 2)
    return float(inside.mean()) / (2 - bound * p / (1 - p))


def _agreement_lines(facts: RunFacts) -> list[Judgement]:
    """The recovery's filter against its smoother: ``d = x̂_f − x̂_s`` against
    ``P_f − P_s`` (:mod:`relation_metric.agreement`), judged as a NEES. Needs no truth."""
    a = facts.agreement
    if a is None or not a.dof.any():
        return []
    per = a.per_dof
    n_eff = effective_sample_size(per) if per.size > 1 else 1.0
    q = a.q
    level, direction = _chi2_level(q, 3, n_eff)
    if q < 1.0:  # one-sided: see the rule
        level, direction = "green", "closer than P_f − P_s allows (not judged)"
    elif q <= AGREEMENT_ALLOWANCE:
        level, direction = "green", "within the allowance"
    neg = f"; {a.negative} directions where the smoother is less certain" if a.negative else ""
    return [
        Judgement(
            "filter vs smoother agreement",
            f"q = {_g(q)}, {direction}; n_eff {n_eff:.0f} of {per.size} poses{neg}",
            level,
            "the recovery's filter minus its smoother, d, against P_filter − P_smoother (its "
            "covariance for consistent estimates, docs/verdict.md): q = mean dᵀ(P_f − P_s)⁻¹d "
            f"over its dof; amber above the 99 % interval of a mean of n_eff χ²(3) values and "
            f"q > {_g(AGREEMENT_ALLOWANCE)}, red above the 99.99 % one; one-sided: "
            "estimates closer than stated are no finding (a map made from the log itself "
            "correlates them, and its smoother's P_s is then too small: docs/recovery.md)",
            "agreement",
            q,
        )
    ]


def _map_consistency_lines(facts: RunFacts) -> list[Judgement]:
    m = facts.map_nees
    if m is None:
        return []
    q = m.value / m.dof
    if q < SAME_MAP_Q:  # the "true" landmarks are the map's own numbers (a surveyed map)
        return [
            Judgement(
                "map consistency",
                f"not judged: map NEES {_g(m.value)} over {m.dof} dof ({m.landmarks} landmarks): "
                "the reference landmarks are the map itself (a surveyed map scored against its "
                "own survey), so nothing independent judges its stated covariance",
                NOT_JUDGED,
                f"q below {SAME_MAP_Q:g}: the map's error against its reference is rounding only",
                "map_consistency",
                q,
            )
        ]
    level, direction = _chi2_level(q, 2, m.landmarks)
    split = ""
    if m.placement is not None:  # which part is over- or under-stated, said, not judged apart
        shape, dof = m.value - m.placement, m.dof - 3
        split = (
            f"; of it the shape {_g(shape)} over {dof} dof (q {_g(shape / dof)}) and the "
            f"placement, a rigid motion of the whole map which no relation sees, "
            f"{_g(m.placement)} over 3 dof (q {_g(m.placement / 3)})"
        )
    return [
        Judgement(
            "map consistency",
            f"map NEES {_g(m.value)} over {m.dof} dof ({m.landmarks} landmarks, {m.covariance} "
            f"covariance): q = {_g(q)}, {direction}{split}",
            level,
            "the matched landmarks' error against the map's stated covariance, in the NEES "
            "frame; " + _CHI2_RULE.replace("n_eff independent values", "K landmarks"),
            "map_consistency",
            q,
        )
    ]


def _measurement_lines(facts: RunFacts) -> list[Judgement]:
    """The information the robust weights took, against its expectation."""
    counts, robust = facts.counts, facts.robust
    if counts is None or robust is None:
        return []
    loss = counts.downweight_loss
    value = (
        f"{100 * loss:.1f} % of the information ({100 * counts.downweighted_fraction:.0f} % of "
        "the measurements down-weighted)"
    )
    if robust.kind != "redescending":
        return [
            Judgement(
                "down-weighted information",
                value,
                INFO,
                f"{robust.kind} weights are iterated: no closed expectation to judge against",
                "measurements",
                loss,
            )  # fmt: skip
        ]
    out = facts.outlier_share  # stated gross errors: each loses its whole information
    expected = (1.0 - out) * expected_downweight_loss(robust.threshold) + out
    r = loss / expected if expected > 0 else float("inf")
    n = counts.used + counts.gated
    taken = loss * n  # in measurements
    bounds = [
        downweight_loss_bound(robust.threshold, n - round(out * n), p) + round(out * n)
        for p in (0.999, 0.9999)
    ]
    level = (
        "green"
        if r <= 1.5 or taken <= bounds[0]
        else "red"
        if r > 3.0 and taken > bounds[1]
        else "amber"
    )
    return [
        Judgement(
            "down-weighted information",
            f"{value}; expected {100 * expected:.2g} % for consistent innovations"
            + (f" with {100 * out:.2g} % gross errors stated" if out else "")
            + f": {_g(r)}×; "
            f"{_g(taken)} measurements' worth of {n} (99.9 % bound {_g(bounds[0])})",
            level,
            f"share of the information the robust weights took, over its expectation for χ²(2) "
            f"innovations at c = {_g(robust.threshold)} (a stated share of gross errors counted "
            "as wholly down-weighted); green ≤ 1.5× or within the 99.9 % "
            "quantile of its sampling law, red > 3× and beyond the 99.99 % quantile, amber "
            "between",
            "measurements",
            r,
        )
    ]


def _map_lines(m: MapSummary) -> list[Judgement]:
    """Map edge error and OSPA (information: accuracies, judged by the map consistency)."""
    c, edge = m.cutoff, m.edge.mean
    return [
        Judgement(
            "map edge error",
            f"{_g(edge)} m (c = {_g(c)} m)",
            INFO,
            "mean abs edge-length error of the Delaunay mesh; an accuracy, not a lamp",
            "map_edge",
            edge,
        ),
        Judgement(
            "map OSPA",
            f"{_g(m.ospa)} m (c = {_g(c)} m)",
            INFO,
            "OSPA of the maps after the SE(2) fit on the associated pairs, over the reference "
            "landmarks the sensor could see; an accuracy, not a lamp",
            "map_ospa",
            m.ospa,
        ),
    ]


def _evidence(facts: RunFacts) -> str:
    """The evidence sentence: relations (scored, and unassociated when known), poses and
    matched landmarks counted."""
    evidence = [f"{facts.relations} relations"]
    made = "given" if facts.scored_on else "generated"
    if not facts.has_truth and not facts.scored_on:
        evidence = ["no relations (no ground truth, no reference relations)"]
    elif facts.unassociated is not None:
        evidence[0] = (
            f"{facts.relations} scored relations"
            + (f" of {facts.scored_on}" if facts.scored_on else "")
            + (
                f" ({facts.unassociated} more {made} but unassociated, not scored)"
                if facts.unassociated
                else f" (all {made} relations associated)"
            )
        )
    if facts.poses:
        evidence.append(f"{facts.poses} poses")
    m = facts.map
    if m is not None:
        unseen = m.unobserved
        evidence.append(
            f"{m.matched} matched landmarks ({m.missed} missed, {m.spurious} spurious"
            + (f", {unseen} never in the sensor's reach" if unseen else "")
            + ")"
        )
    return "Based on " + ", ".join(evidence) + "."
