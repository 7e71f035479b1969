"""Issue 23, acceptance 1: on bundles healthy by construction the recovery is consistent.

The bundles (:mod:`slamrel.simulation.healthy`) are what a correct SLAM run with exact models
could leave behind: a simulated log, the true associations, and a map whose error is drawn
from exactly the covariance it states — a correlated joint ``map_covariance`` (form
``joint``) or independent landmarks given only as marginals (form ``marginal``). On them,
for ``method`` filter, smoother and batch with the default map mode, both with the plain EKF
(``robust=None``) and the default robust update:

* the mean pose NEES (3 dof) lies in its χ² band (below);
* the three methods' mean NEES agree within 10 % (:func:`test_acceptance_mean_nees_in_band`,
  which says how this is judged on six seeds);
* smoother error ≤ filter error and batch error ≤ 1.05 × smoother error, the error being the
  mean translational error of 500 global relations
  (``generate_relations(groundtruth, "global", count=500, seed=0)``).

History: at a6060df the smoother's NEES was about twice the filter's and the batch's 10–80 ×
(as if it ignored ``map_covariance``); with marginals only every method was over-confident.
The map-augmented smoother/batch fixed that; the smoother's single Gauss–Newton step then left
it over-confident on hu-complex1 (mean NEES 3.52 ± 0.16 over 12 seeds, marginal form, against
3.0 for the filter and the batch) until it stepped to the data's statistical resolution
(:data:`recovery.constants.SMOOTHER_CHI2_RESOLUTION`). Over 20 seeds (0–19, plain EKF) the
mean NEES of filter / smoother / batch are now: simple1 joint 2.79 / 2.51 / 2.51 (± 0.25,
± 0.21, ± 0.21), simple1 marginal 3.14 / 3.03 / 3.03 (± 0.14, ± 0.11), complex1 joint
2.92 / 2.93 / 2.93 (± 0.27, ± 0.20), complex1 marginal 2.955 / 2.947 / 2.947 (± 0.09,
± 0.08). The ``test_control_*`` tests show that the band admits a consistent recovery and
that the tests can fail.

**The band.** A run's NEES values are far from independent in time: the map's error (its
common-mode translation and rotation above all) persists along the whole run, so one run's
mean NEES is worth only a few independent χ²₃ draws. We model a run's mean NEES as
``χ²(3 n_eff) / n_eff`` (the scaled χ² with the right mean, 3, and variance ``6 / n_eff``)
with :data:`N_EFF` per form, measured as ``6 / var`` of the run means over 100 seeds
(1000–1099, disjoint from the tests' seeds) with a recovery that is consistent on these
bundles — the filter's Schmidt update with the joint covariance, for the marginal form with
the marginals as a block-diagonal joint — on all four worlds (``python
tests/healthy_consistency.py --neff 100``), rounded down below the smallest world's
value (a smaller n_eff widens the band: the conservative side). Measured at a6060df:

========  ===========  ==============  ==============  =================
world     joint n_eff  joint mean      marginal n_eff  marginal mean
========  ===========  ==============  ==============  =================
simple1   2.5          3.08            20.9            2.96
simple2   2.1          3.26            16.2            2.96
complex1  2.4          3.18            39.9            3.05
complex2  2.8          3.14            29.0            3.02
========  ===========  ==============  ==============  =================

(the means, 100 runs each, are 3 within their standard error: that recovery is consistent).
Independent seeds add up:

* per world × form (``test_acceptance_mean_nees_in_band``): the mean over the :data:`SEEDS`
  of the run means lies in the 95 % band ``nees_band(3, len(SEEDS) · n_eff)`` of
  :func:`relation_metric.consistency.nees_band` (with ``runs = len(SEEDS) · n_eff``, which is
  the band of ``χ²(3 · runs) / runs``);
* per run (``test_acceptance_run``): the run's mean lies in the 99.9 % band ``nees_band(3,
  n_eff, 0.999)`` (wide: ~70 per-run checks, each at 0.1 %, would otherwise fail by chance).

That these bands can fail is checked by the controls: a map whose error is drawn 3 × larger
than it states, and the healthy bundles recovered with ``map_mode="ignore"``, give mean NEES
well above the band (with the default robust update: the one that could weight a bad map
away; the plain EKF's numbers are in the benchmark's table, and higher).
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
from scipy.linalg import block_diag

import slamrel
from recovery.constants import DEFAULT_ROBUST
from recovery.recover import recover
from relation_metric.consistency import nees_band
from slamrel.runs.nees import recovery_nees
from slamrel.simulation.healthy import FORMS, healthy_bundle

WORLDS = ("simple1", "complex1")  # 85 poses / 10 m and 391 poses / 25 m, ~220 landmarks
SEEDS = (0, 1, 2, 3, 4, 5)
METHODS = ("filter", "smoother", "batch")
ROBUST = (None, DEFAULT_ROBUST)
#: The agreement asked of the methods' mean NEES (issue 23: within 10 % of each other).
AGREEMENT = 0.10
#: z of the paired test of that agreement (99 %, two-sided).
AGREEMENT_Z = 2.576
#: Effective number of independent χ²₃ draws in one run's mean NEES, per form (module doc).
N_EFF = {"joint": 2, "marginal": 12}
#: How far above the band the controls must be ("clearly above").
CLEARLY = 1.5

# Tiers: the default runs one run's acceptance (simple1, seed 0, both forms) and the cheap
# control that the band can fail (simple1, map error ignored). The full tier (``--full``)
# adds complex1, the other seeds, the pooled acceptance over all seeds with the controls of
# its band and agreement, and the 3 x map-error control (the slowest: its smoother and batch
# work against a map 3 x worse than stated): minutes of recoveries, hence not by default.
FULL = pytest.mark.slow
WORLD_TIERS = [pytest.param(w, marks=FULL if w != "simple1" else ()) for w in WORLDS]
SEED_TIERS = [pytest.param(s, marks=FULL if s else ()) for s in SEEDS]


@cache
def _bundle(world: str, seed: int, form: str, scale: float = 1.0):  # type: ignore[no-untyped-def]
    return healthy_bundle(world, seed, form, error_scale=scale)


@cache
def _relations(world: str, seed: int):  # type: ignore[no-untyped-def]
    gt = _bundle(world, seed, "joint").groundtruth  # the same truth for both forms
    return slamrel.generate_relations(gt, "global", count=500, seed=0)


@cache
def _run(
    world: str,
    seed: int,
    form: str,
    method: str,
    robust: str | None,
    scale: float = 1.0,
    map_mode: str = "joint",
) -> tuple[float, float]:
    """(mean NEES, mean translational error of the 500 global relations) of one recovery."""
    b = _bundle(world, seed, form, scale)
    r = recover(b, method=method, robust=robust, map_mode=map_mode)
    err = slamrel.evaluate(_relations(world, seed), r.trajectory).translation.abs.mean
    return _mean_nees(b, r), float(err)


def _mean_nees(b, r) -> float:  # type: ignore[no-untyped-def]
    """The recovery's mean pose NEES against the truth, as slamrel run computes it."""
    got = recovery_nees(b, r)
    assert got is not None
    return float(got[0].summary.mean)


def _pooled_band(form: str, probability: float = 0.95) -> tuple[float, float]:
    return nees_band(3, len(SEEDS) * N_EFF[form], probability)


# ------------------------------------------------------------------- acceptance (issue 23)


@pytest.mark.parametrize("form", FORMS)
@pytest.mark.parametrize("seed", SEED_TIERS)
@pytest.mark.parametrize("world", WORLD_TIERS)
def test_acceptance_run(world: str, seed: int, form: str) -> None:
    """ACCEPTANCE (issue 23): one run, every method, both robust settings:
    NEES in the wide per-run band, smoother error ≤ filter's, batch ≤ 1.05 × smoother's."""
    lo, hi = nees_band(3, N_EFF[form], 0.999)
    failures = []
    for robust in ROBUST:
        nees, err = {}, {}
        for m in METHODS:
            nees[m], err[m] = _run(world, seed, form, m, robust)
            if not lo <= nees[m] <= hi:
                failures.append(
                    f"{m} robust={robust}: NEES {nees[m]:.2f} outside {lo:.2f}-{hi:.2f}"
                )
        if err["smoother"] > err["filter"]:
            failures.append(
                f"robust={robust}: smoother error {err['smoother']:.4f} > filter "
                f"{err['filter']:.4f}"
            )
        if err["batch"] > 1.05 * err["smoother"]:
            failures.append(
                f"robust={robust}: batch error {err['batch']:.4f} > 1.05 x smoother "
                f"{err['smoother']:.4f}"
            )
    assert not failures, "\n".join(failures)


def _disagreement(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """How far two methods' mean NEES over paired seeds are apart beyond the agreement asked:
    ``(|mean(a − b)| − AGREEMENT · 3, AGREEMENT_Z · SE)``, SE that of the paired mean difference.

    Why paired and with its standard error: a run's mean NEES is worth only ``n_eff`` χ²₃ draws
    (2 for the joint form), and two consistent methods' run means are only weakly correlated
    (0.18–0.26 between filter and smoother over 20 seeds). Resampling those 20 seeds, six of
    them put the largest / smallest of the three means above 1.10 in 57–79 % of draws, while
    all three means over the 20 seeds are 3 within their standard errors (module doc): a plain
    10 % threshold on six seeds would fail consistent methods most of the time. The methods
    fail the agreement when the data show, at 99 %, that their means differ by more than 10 %
    of the dof.
    """
    d = np.asarray(a) - np.asarray(b)
    se = float(np.std(d, ddof=1) / np.sqrt(d.size))
    return abs(float(d.mean())) - AGREEMENT * 3.0, AGREEMENT_Z * se


@FULL
@pytest.mark.parametrize("form", FORMS)
@pytest.mark.parametrize("world", WORLDS)
def test_acceptance_mean_nees_in_band(world: str, form: str) -> None:
    """ACCEPTANCE (issue 23): the mean over seeds in the 95 % band; the three methods' means
    agree within 10 % (:func:`_disagreement`: not shown to differ by more, at 99 %)."""
    lo, hi = _pooled_band(form)
    failures = []
    for robust in ROBUST:
        runs = {m: np.array([_run(world, s, form, m, robust)[0] for s in SEEDS]) for m in METHODS}
        for m, v in runs.items():
            if not lo <= v.mean() <= hi:
                failures.append(
                    f"{m} robust={robust}: mean NEES {v.mean():.2f} outside {lo:.2f}-{hi:.2f}"
                )
        for a, b in (("filter", "smoother"), ("smoother", "batch"), ("filter", "batch")):
            beyond, margin = _disagreement(runs[a], runs[b])
            if beyond > margin:
                failures.append(
                    f"robust={robust}: {a} {runs[a].mean():.2f} vs {b} {runs[b].mean():.2f}: "
                    f"{beyond:.2f} beyond 10 % of the dof, more than {margin:.2f} (99 %)"
                )
    assert not failures, "\n".join(failures)


#: The disagreement the agreement test must catch on six seeds, per form: the smoother's
#: covariance divided by this (its NEES multiplied). Six seeds resolve little on the joint form
#: (a run is worth ~2 χ²₃ draws): measured, the 99 % margin of the paired difference there is
#: 2.3 NEES units (a method at 2 × the filter's NEES is not told apart: 1.98 beyond 10 % against
#: the margin 2.32); on the marginal form (~12 draws a run) 2 × is caught. The 20-seed means in
#: the module doc are the finer measurement.
CAUGHT_FACTOR = {"joint": 3.0, "marginal": 2.0}


@FULL
@pytest.mark.parametrize("form", FORMS)
def test_control_the_agreement_test_catches_a_method_whose_covariance_is_too_small(
    form: str,
) -> None:
    """The agreement of :func:`test_acceptance_mean_nees_in_band` can fail: the smoother's
    runs with their NEES multiplied by :data:`CAUGHT_FACTOR` against the filter's, on the same
    six seeds of simple1, are told apart; the real pair is not."""
    f = np.array([_run("simple1", s, form, "filter", None)[0] for s in SEEDS])
    sm = np.array([_run("simple1", s, form, "smoother", None)[0] for s in SEEDS])
    k = CAUGHT_FACTOR[form]
    beyond, margin = _disagreement(f, k * sm)
    assert beyond > margin, (f.mean(), k * sm.mean(), beyond, margin)
    beyond, margin = _disagreement(f, sm)
    assert beyond <= margin, (f.mean(), sm.mean(), beyond, margin)


# ----------------------------------------------------------------- controls (pass on main)


@FULL
@pytest.mark.parametrize("form", FORMS)
@pytest.mark.parametrize("world", WORLDS)
def test_control_band_admits_a_consistent_recovery(world: str, form: str) -> None:
    """The filter's Schmidt update (the marginal form's marginals as a block-diagonal joint)
    is consistent on these bundles: its mean over the seeds lies in the band."""
    lo, hi = _pooled_band(form)
    for robust in ROBUST:
        v = []
        for s in SEEDS:
            b = _bundle(world, s, form)
            if b.map_covariance is None:
                b = b.with_map(b.map_xy, b.map_marginals, block_diag(*b.map_marginals))
            r = recover(b, method="filter", robust=robust)
            assert r.map_mode == "joint"
            v.append(_mean_nees(b, r))
        assert lo <= np.mean(v) <= hi, (robust, np.mean(v), (lo, hi), v)


@FULL
@pytest.mark.parametrize("form", FORMS)
@pytest.mark.parametrize("world", WORLDS)
def test_control_map_error_three_times_stated_is_caught(world: str, form: str) -> None:
    """A map whose error is 3 × what it states: every method's mean NEES above the band, the
    filter's clearly (1.5 ×). The smoother and the batch estimate the map's error from the log
    (the map correction ``L η``), so a map worse than stated hurts them less: measured, with
    the default robust update, their means are 7.9 / 7.6 (simple1 joint / marginal) and
    6.05 / 6.45 (complex1) against the band's top 4.54; the filter's 16–27."""
    hi = _pooled_band(form)[1]
    for m in METHODS:
        mean = np.mean([_run(world, s, form, m, DEFAULT_ROBUST, scale=3.0)[0] for s in SEEDS])
        assert mean > (CLEARLY * hi if m == "filter" else hi), (m, mean, hi)


@pytest.mark.parametrize("form", FORMS)
@pytest.mark.parametrize("world", WORLD_TIERS)
def test_control_ignoring_the_map_error_is_caught(world: str, form: str) -> None:
    """Healthy bundles taken as exact maps (``map_mode="ignore"``): clearly above the band."""
    hi = _pooled_band(form)[1]
    for m in METHODS:
        mean = np.mean(
            [_run(world, s, form, m, DEFAULT_ROBUST, map_mode="ignore")[0] for s in SEEDS]
        )
        assert mean > CLEARLY * hi, (m, mean, hi)
