"""``slamrel compare``'s test holds its level on overlapping relations, and finds real effects.

The experiment: a ground-truth drive of N poses (1 s apart, 0.5 m a step, turning slowly, so
that it passes its own path again); two estimates, each the truth composed with an
independent world-frame random-walk drift ``x̂_k = D_k ∘ x_k``, ``D_k = w_1 ∘ ... ∘ w_k``,
``w ~ N(0, diag(σ²))``; scored with the relation metric on five relation sets that overlap
in different degrees — consecutive poses 1, 5 and 20 steps apart (a relation shares its
stretch with the next 1, 5, 20), loop closures and global pairs (each spans much of the run).

- Under the null (both drifts from one distribution) a calibrated test calls a difference
  significant in a fraction ``α`` of the repetitions. The old test (Wilcoxon signed-rank
  on the pairs, as if independent) does so on consecutive relations only; on overlapping
  relations it rejects far more often. Measured, R = 200 repetitions of a 2000-pose run,
  α = 0.05, translation / rotation:

  ==========  ===========  ==============
  relations   Wilcoxon     block bootstrap
  ==========  ===========  ==============
  1 step      0.055 0.050  0.050 0.045
  5 steps     0.220 0.245  0.055 0.050
  20 steps    0.535 0.620  0.070 0.040
  loops       0.825 0.830  no test
  global      0.850 0.825  no test
  ==========  ===========  ==============

  Pooled over the tests made, the bootstrap rejects in 0.052; a table (Holm over its six
  tests) calls something significant in 0.045 of the repetitions. Loop and global relations
  overlap one another nearly everywhere: too few independent blocks, no test (the table
  says so), never falsely significant.
- Power: B's drift 5 % larger in standard deviation (its errors 5 % larger), R = 60
  repetitions of an 8000-pose run: the table calls A better on 1-step relations in 0.87
  (translation) and 0.95 (rotation) of them, never B; the floor asserted is 0.75. Longer
  relations carry less evidence: 5 steps 0.33 / 0.35, 20 steps 0.10 / 0.10.

Everything is seeded; the numbers above are what these seeds give.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import wilcoxon

from relation_metric import se2
from relation_metric.evaluate import evaluate
from relation_metric.relations import RelationSet, generate_relations
from relation_metric.trajectory import Trajectory
from slamrel.report.tables import ResultErrors, compare_results

ALPHA = 0.05
SIGMA = np.array([0.02, 0.01, 0.004])  # drift step: x, y [m], θ [rad]
PARTS = ("translation", "rotation")
# Monte Carlo studies of the test's level and power (200 and 60 repetitions): the full tier;
# tests/test_significance.py and tests/test_compare.py check the test itself by default
pytestmark = pytest.mark.slow


def drive(n: int) -> Trajectory:
    """N poses 1 s apart: 0.5 m forward a step, a slow left turn with a wiggle."""
    k = np.arange(n - 1)
    turn = 0.08 * np.sin(2 * np.pi * k / 100) + 2 * np.pi / 500
    steps = np.column_stack((np.full(n - 1, 0.5), np.zeros(n - 1), turn))
    return Trajectory(np.arange(n, dtype=float), se2.cumulative_compose(steps))


def relation_sets(truth: Trajectory, *, long: bool = True) -> dict[str, RelationSet]:
    sets = {f"{s} steps": generate_relations(truth, "consecutive", step=s) for s in (1, 5, 20)}
    if long:
        loops = generate_relations(truth, "loops", radius=1.0, min_separation_time=20.0)
        pick = np.random.default_rng(0).choice(len(loops), min(400, len(loops)), replace=False)
        sets["loops"] = loops.subset(np.sort(pick))
        sets["global"] = generate_relations(truth, "global", count=300, seed=1)
    return sets


def drifting(truth: Trajectory, rng: np.random.Generator, scale: float = 1.0) -> Trajectory:
    """The truth composed with a world-frame random-walk drift (step std ``scale · σ``)."""
    w = rng.normal(0.0, SIGMA * scale, (len(truth) - 1, 3))
    drift = se2.cumulative_compose(w)  # D_0 = identity, D_k = D_{k-1} ∘ w_k
    return Trajectory(truth.timestamps, se2.compose(drift, truth.poses))


class Scorer:
    """Scores an estimate on all relation sets at once (one evaluation of their union)."""

    def __init__(self, sets: dict[str, RelationSet]):
        self.all = RelationSet(
            np.concatenate([r.first for r in sets.values()]),
            np.concatenate([r.second for r in sets.values()]),
            np.concatenate([r.delta for r in sets.values()]),
        )
        t1, t2 = self.all.first, self.all.second
        self.keys = np.char.add(np.char.add(t1.astype(str), " "), t2.astype(str))
        self.labels = np.repeat(list(sets), [len(r) for r in sets.values()])

    def __call__(self, name: str, est: Trajectory) -> ResultErrors:
        e = evaluate(self.all, est).errors
        return ResultErrors(
            "sim", name, self.keys, e.translation, e.rotation, "rad",
            t1=self.all.first, t2=self.all.second, relation_set=self.labels,
        )  # fmt: skip


def experiment(
    n: int, reps: int, scale: float, *, long: bool, seed: int, resamples: int, old: bool = True
):
    """Per repetition and test: the old Wilcoxon p (NaN unless ``old``), the table's test."""
    truth = drive(n)
    sets = relation_sets(truth, long=long)
    score = Scorer(sets)
    rng = np.random.default_rng(seed)
    rows = []
    for r in range(reps):
        a = score("A", drifting(truth, rng))
        b = score("B", drifting(truth, rng, scale))
        comp = compare_results([a, b], alpha=ALPHA, resamples=resamples, seed=r)
        for t in comp.tests:
            sel = score.labels == t.relation_set
            p_old = np.nan
            if old:
                p_old = wilcoxon(getattr(a, t.part)[sel], getattr(b, t.part)[sel]).pvalue
            rows.append((r, t.relation_set, t.part, p_old, t))
    return sets, rows


@pytest.fixture(scope="module")
def null():
    return experiment(2000, 200, 1.0, long=True, seed=11, resamples=499)


def test_null_rejects_at_the_level_where_wilcoxon_does_not(null):
    sets, rows = null
    reps = 1 + max(r for r, *_ in rows)
    se = math.sqrt(ALPHA * (1 - ALPHA) / reps)  # of a rejection rate over the repetitions
    report = []
    for name in sets:
        for part in PARTS:
            mine = [(old, t) for _, s, p, old, t in rows if s == name and p == part]
            assert len(mine) == reps
            old_rate = np.mean([old < ALPHA for old, _ in mine])
            tested = [t for _, t in mine if t.difference.tested]
            new_rate = np.mean([t.p_value < ALPHA for t in tested]) if tested else 0.0
            report.append(f"{name} {part}: Wilcoxon {old_rate:.3f}, bootstrap {new_rate:.3f} "
                          f"({len(tested)} of {reps} tested)")  # fmt: skip
            if name == "1 steps":  # independent pairs: both tests hold the level
                assert old_rate <= ALPHA + 3 * se
            else:  # overlapping relations: the independent-pairs test is far off
                assert old_rate >= 3 * ALPHA, report[-1]
            if name in ("loops", "global"):  # each spans much of the run: no test
                assert not tested
            else:
                assert len(tested) == reps
                assert new_rate <= ALPHA + 3 * se, report[-1]
            assert not any(t.significant for _, t in mine if not t.difference.tested)
    print("\n".join(report))
    # pooled over every test made: at most α + 2 standard errors of the repetitions
    made = [t for *_, t in rows if t.difference.tested]
    pooled = np.mean([t.p_value < ALPHA for t in made])
    assert pooled <= ALPHA + 2 * se, pooled
    # what the table calls significant (Holm over its tests): in at most α + 2 SE of tables
    called = {r for r, *_, t in rows if t.significant}
    assert len(called) / reps <= ALPHA + 2 * se, len(called) / reps
    print(f"pooled bootstrap {pooled:.3f}; tables with a significant test {len(called) / reps:.3f}")


def test_null_intervals_cover_zero_at_their_level(null):
    _, rows = null
    reps = 1 + max(r for r, *_ in rows)
    made = [t.difference for *_, t in rows if t.difference.tested]
    cover = np.mean([d.ci_low <= 0.0 <= d.ci_high for d in made])  # the true difference: 0
    assert cover >= 1 - ALPHA - 2 * math.sqrt(ALPHA * (1 - ALPHA) / reps), cover
    # the interval and the p-value agree: outside the interval exactly when p < 1 − level
    # (up to the resolution of B resamples)
    for d in made:
        if d.p_value < ALPHA - 2 / (d.resamples + 1):
            assert not d.ci_low <= 0.0 <= d.ci_high
        if d.p_value > ALPHA + 2 / (d.resamples + 1):
            assert d.ci_low <= 0.0 <= d.ci_high


def test_a_five_percent_difference_is_found():
    _, rows = experiment(8000, 60, 1.05, long=False, seed=12, resamples=499, old=False)
    for name in ("5 steps", "20 steps"):  # longer relations: less power, shown, not asserted
        for part in PARTS:
            mine = [t for _, s, p, _, t in rows if s == name and p == part]
            print(f"{name} {part}: power {np.mean([t.better == 'A' for t in mine]):.3f}")
    for part in PARTS:
        mine = [t for _, s, p, _, t in rows if s == "1 steps" and p == part]
        power = np.mean([t.better == "A" for t in mine])
        print(f"1 steps {part}: power {power:.3f} over {len(mine)} repetitions")
        assert power >= 0.75
        assert not any(t.better == "B" for t in mine)  # never the wrong direction
        rel = np.mean([t.difference.relative_difference for t in mine])
        assert rel == pytest.approx(-100 * (1 - 1 / 1.05), abs=1.0)  # A − B ≈ −4.8 % of B
