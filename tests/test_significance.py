"""The block bootstrap of paired differences against hand computation, theory and a naive loop."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import lfilter

from relation_metric.errors import InputError
from relation_metric.significance import (
    MIN_BLOCKS,
    block_length,
    circular_block_means,
    holm_adjust,
    paired_difference,
    politis_white_block_length,
)


def consecutive(n: int, step: int = 1) -> tuple[np.ndarray, np.ndarray]:
    t1 = np.arange(n, dtype=float)
    return t1, t1 + step


def naive_block_means(x, length, starts):
    """The resamples written out: blocks of indices mod n, cut to n values, one by one."""
    n = x.size
    out = []
    for row in starts:
        idx = np.concatenate([(s + np.arange(length)) % n for s in row])[:n]
        out.append(x[idx].mean())
    return np.array(out)


@pytest.mark.parametrize(("n", "length"), [(10, 3), (12, 4), (7, 7), (50, 1), (31, 6)])
def test_block_means_equal_the_resamples_written_out(n, length):
    x = np.random.default_rng(n).normal(size=n)
    fast = circular_block_means(x, length, 40, np.random.default_rng(5))
    starts = np.random.default_rng(5).integers(0, n, size=(40, -(-n // length)))
    np.testing.assert_allclose(fast, naive_block_means(x, length, starts), rtol=0, atol=1e-13)


def test_block_means_of_whole_circles_are_the_mean():
    # L = n: every resample is x turned round its circle, so its mean is x's mean
    x = np.random.default_rng(1).normal(size=25)
    np.testing.assert_allclose(
        circular_block_means(x, 25, 50, np.random.default_rng(0)), x.mean(), atol=1e-15
    )


def test_blocks_of_one_are_the_iid_bootstrap():
    # L = 1: the resampled mean has variance σ²/n with σ² the population variance of x
    x = np.random.default_rng(2).gamma(2.0, 1.0, 200)
    means = circular_block_means(x, 1, 40000, np.random.default_rng(3))
    assert means.mean() == pytest.approx(x.mean(), abs=3 * x.std() / math.sqrt(200 * 40000))
    assert means.var() == pytest.approx(x.var() / 200, rel=0.03)


def test_overlap_range_by_hand():
    # relations (k, k+2), k = 0..4: later relations starting by each one's end (closed
    # intervals): 2, 2, 2, 1, 0 -> m̄ = 7/5; 3 (m̄ + 1) = 7.2 -> 8, cut to the 5 relations
    t1, t2 = consecutive(5, step=2)
    b = block_length(t1, t2, np.zeros(5))
    assert b.overlap == pytest.approx(1.4)
    assert b.from_overlap == 8 and b.length == 5 and b.blocks == 1.0
    # the order of the two ends does not matter (Freiburg files have t2 < t1 too)
    assert block_length(t2, t1, np.zeros(5)).overlap == pytest.approx(1.4)


def test_overlap_of_a_long_relation_set_is_long():
    # every relation spans the middle of the run: each overlaps all later ones
    t1 = np.arange(100.0)
    t2 = t1 + 500.0
    assert block_length(t1, t2, np.zeros(100)).overlap == pytest.approx(99 / 2)


def test_politis_white_against_the_ar1_formula():
    # AR(1), coefficient φ: R(k) ∝ φ^|k|, G = Σ|k|R = 2φ/(1−φ)², g = ΣR = (1+φ)/(1−φ)
    # (times Var x), so b = (2G² / (4/3 g²))^(1/3) n^(1/3) = (6φ² / (1−φ²)²)^(1/3) n^(1/3)
    phi, n = 0.5, 20000
    x = lfilter([1.0], [1.0, -phi], np.random.default_rng(0).normal(size=n))
    expected = (6 * phi**2 / (1 - phi**2) ** 2) ** (1 / 3) * n ** (1 / 3)  # 37.6
    assert politis_white_block_length(x) == pytest.approx(expected, rel=0.2)
    # independent values: blocks of one
    assert politis_white_block_length(np.random.default_rng(1).normal(size=5000)) < 2.0
    assert politis_white_block_length(np.ones(50)) == 1.0  # constant: no dependence to keep


def test_constant_difference_is_certain_never_p_zero():
    t1, t2 = consecutive(400)
    b = np.random.default_rng(4).gamma(2.0, 0.01, 400)
    r = paired_difference(t1, t2, b + 0.01, b, resamples=999)
    assert r.tested and r.mean_difference == pytest.approx(0.01)
    assert r.exceedances == 0 and r.p_at_floor
    assert r.p_value == pytest.approx(1 / 1000) and r.p_value > 0
    assert r.ci_low == pytest.approx(0.01) and r.ci_high == pytest.approx(0.01)
    assert r.relative_difference == pytest.approx(100 * 0.01 / b.mean())


def test_direction_interval_and_symmetry_in_a_deterministic_case():
    # A worse by 0.01 on average: d = 0.01 + (e − ē), so the mean difference is 0.01 by
    # construction; its spread, std 0.004 over 400 relations, puts d̄ ~ 50 σ/√n from 0
    t1, t2 = consecutive(400)
    rng = np.random.default_rng(9)
    b = rng.gamma(4.0, 0.0125, 400)
    e = rng.normal(0.0, 0.004, 400)
    a = b + 0.01 + (e - e.mean())
    r = paired_difference(t1, t2, a, b, resamples=999, seed=7)
    assert r.mean_difference == pytest.approx(0.01, abs=1e-15) and r.mean_difference > 0
    assert r.ci_low <= 0.01 <= r.ci_high
    # its half-width is about 1.96 σ/√n = 3.9e-4 (independent values: blocks change little)
    assert (r.ci_high - r.ci_low) / 2 == pytest.approx(1.96 * 0.004 / math.sqrt(400), rel=0.2)
    assert r.p_at_floor  # B is better beyond doubt
    # B − A: the same test mirrored
    s = paired_difference(t1, t2, b, a, resamples=999, seed=7)
    assert s.mean_difference == pytest.approx(-r.mean_difference)
    assert (s.ci_low, s.ci_high) == pytest.approx((-r.ci_high, -r.ci_low))
    assert s.p_value == r.p_value


def test_identical_errors_differ_by_nothing():
    t1, t2 = consecutive(200)
    e = np.random.default_rng(5).gamma(2.0, 0.01, 200)
    r = paired_difference(t1, t2, e, e, resamples=199)
    assert r.p_value == 1.0 and r.ci_low == 0.0 == r.ci_high and r.mean_difference == 0.0


def test_the_input_order_of_relations_does_not_matter():
    t1, t2 = consecutive(300, step=3)
    rng = np.random.default_rng(6)
    a, b = rng.gamma(2.0, 0.01, 300), rng.gamma(2.0, 0.01, 300)
    shuffle = rng.permutation(300)
    r = paired_difference(t1, t2, a, b, resamples=499, seed=1)
    s = paired_difference(t1[shuffle], t2[shuffle], a[shuffle], b[shuffle], resamples=499, seed=1)
    assert r.block == s.block
    assert r.p_value == s.p_value and r.ci_low == pytest.approx(s.ci_low, abs=1e-15)
    # seeded: the same seed gives the same numbers, another seed other resamples
    assert paired_difference(t1, t2, a, b, resamples=499, seed=1) == r
    assert paired_difference(t1, t2, a, b, resamples=499, seed=2).ci_low != r.ci_low


def test_the_interval_has_its_level_on_independent_pairs():
    # n independent pairs, true mean difference 0.003: the 95 % interval covers it in
    # about 95 % of 300 draws (binomial: within 3 standard errors)
    t1, t2 = consecutive(300)
    rng = np.random.default_rng(8)
    cover = []
    for k in range(300):
        a = rng.normal(0.103, 0.02, 300)
        b = rng.normal(0.100, 0.02, 300)
        r = paired_difference(t1, t2, a, b, resamples=299, seed=k)
        cover.append(r.ci_low <= 0.003 <= r.ci_high)
    assert np.mean(cover) == pytest.approx(0.95, abs=3 * math.sqrt(0.95 * 0.05 / 300))


def test_too_few_blocks_is_no_test_and_says_why():
    # 100 relations each spanning 500 s: they all overlap: one block
    t1 = np.arange(100.0)
    r = paired_difference(t1, t1 + 500.0, np.full(100, 1.0), np.zeros(100))
    assert not r.tested and math.isnan(r.p_value) and math.isnan(r.ci_low)
    assert not r.p_at_floor and r.mean_difference == 1.0
    assert r.reason == (
        f"100 relations in blocks of 100 make 1 < {MIN_BLOCKS} blocks: each relation "
        "overlaps 49.5 later ones in time on average"
    )
    # 30 relations apart from one another, (2k, 2k + 1): blocks of ⌈30^(1/3)⌉ = 4
    t1 = 2.0 * np.arange(30)
    few = paired_difference(t1, t1 + 1, np.ones(30), np.zeros(30))
    assert (few.block.overlap, few.block.length) == (0.0, 4)
    assert not few.tested and "too few relations" in few.reason


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"a": np.ones(3)}, "one shape"),
        ({"a": np.array([1.0, np.nan, 1.0, 1.0])}, "finite"),
        ({"confidence": 1.0}, "confidence"),
        ({"resamples": 0}, "resamples"),
    ],
)
def test_bad_input_is_refused(kwargs, match):
    args = {"first": np.arange(4.0), "second": np.arange(4.0) + 1, "a": np.ones(4),
            "b": np.zeros(4)} | kwargs  # fmt: skip
    with pytest.raises(InputError, match=match):
        paired_difference(**args)


@pytest.mark.parametrize(
    ("p", "adjusted"),
    [
        # m = 3: sorted (0.01, 0.03, 0.04) x (3, 2, 1) = (0.03, 0.06, 0.04), running max
        # (0.03, 0.06, 0.06), back in the input's order
        ([0.04, 0.01, 0.03], [0.06, 0.03, 0.06]),
        # m = 4: sorted (0.005, 0.01, 0.03, 0.04) x (4, 3, 2, 1) = (0.02, 0.03, 0.06, 0.04)
        ([0.01, 0.04, 0.03, 0.005], [0.03, 0.06, 0.06, 0.02]),
        # the larger p-value's own product 0.6 exceeds the running max 0.4
        ([0.6, 0.2], [0.6, 0.4]),
        # clipped to 1: (0.5, 0.9) x (2, 1) = (1.0, 0.9), max 1.0 for both
        ([0.5, 0.9], [1.0, 1.0]),
        ([0.7, 0.9], [1.0, 1.0]),
        # ties: (0.02, 0.02, 0.5) x (3, 2, 1) = (0.06, 0.04, 0.5): both tied get 0.06
        ([0.02, 0.5, 0.02], [0.06, 0.5, 0.06]),
        ([0.0, 1.0], [0.0, 1.0]),
        ([0.037], [0.037]),  # one test: nothing to adjust
        ([], []),
    ],
)
def test_holm_against_hand_values(p, adjusted):
    got = holm_adjust(np.array(p))
    assert got.shape == (len(p),)
    np.testing.assert_allclose(got, adjusted, rtol=1e-15, atol=0)


@pytest.mark.parametrize("p", [[0.1, float("nan")], [0.1, 1.5], [-0.01], [[0.1, 0.2]]])
def test_holm_refuses_what_is_not_p_values(p):
    with pytest.raises(InputError, match="p-values must"):
        holm_adjust(np.array(p))
