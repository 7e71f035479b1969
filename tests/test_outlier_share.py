"""A share of gross errors stated in the bundle (``sensor_model.outlier_share``): read and
written by the one bundle reader, and judged by the verdict's map–log lamp — runs with the
gross errors they state agree with their log, runs with more than they state (or wrong
associations, which look the same) do not."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from scipy.stats import poisson

from relation_metric import se2
from relation_metric.consistency import nis_tail_expected, nis_tail_level, outlier_share_of_tail
from relation_metric.errors import InputError
from slamrel.formats.bundle import read_bundle, write_bundle
from slamrel.pipeline import RunInput, score_bundle
from slamrel.report.verdict import RunFacts, gaussian_breaks, run_verdict
from slamrel.simulation.healthy import healthy_bundle

BOUND = -2.0 * np.log(1e-3)  # χ²₂'s 99.9 % quantile


def test_round_trip_and_refusals(tmp_path):
    b = healthy_bundle("simple1", 0, "marginal", odometry=None)
    write_bundle(tmp_path / "b", replace(b, sensor=replace(b.sensor, outlier_share=0.031)))
    assert read_bundle(tmp_path / "b").sensor.outlier_share == 0.031
    write_bundle(tmp_path / "w", b)  # not stated: no key written, read as not stated
    doc = json.loads((tmp_path / "w" / "bundle.json").read_text())
    assert "outlier_share" not in doc["sensor_model"]
    assert read_bundle(tmp_path / "w").sensor.outlier_share is None
    refused = (
        (0.5, r"\[0, 0.5\)"),
        (-0.01, "expected a number >= 0"),
        ("2 %", "expected a finite number"),
        (True, "expected a finite number"),
    )
    for bad, what in refused:
        doc["sensor_model"]["outlier_share"] = bad
        (tmp_path / "w" / "bundle.json").write_text(json.dumps(doc, indent=1))
        with pytest.raises(InputError, match=what) as info:
            read_bundle(tmp_path / "w")
        assert info.value.line is not None and "outlier_share" in str(info.value)


def test_tail_rule_without_a_stated_share_is_the_poisson_rule():
    """``outlier_share = 0`` is the rule as it was: red above the Poisson 99.99 % quantile of
    ``0.001 n`` and 0.5 % of ``n``, amber above the 99.9 % one and 0.2 % (scipy's quantiles)."""
    for n in (200, 1000, 5000):
        for tail in range(0, n // 50):
            want = (
                "red"
                if tail > poisson.ppf(0.9999, 1e-3 * n) and tail / n > 0.005
                else "amber"
                if tail > poisson.ppf(0.999, 1e-3 * n) and tail / n > 0.002
                else "green"
            )
            assert nis_tail_level(tail, n) == nis_tail_level(tail, n, 0.999, 0.0) == want


def test_tail_rule_with_a_stated_share_on_drawn_innovations(rng):
    """Innovations drawn from the contamination the bundle states (``p`` of them gross,
    beyond the bound; the rest χ²₂) are green; twice the stated share is red."""
    n, p = 3000, 0.03
    levels, doubled = [], []
    for _ in range(200):
        gross = rng.random(n) < p
        tail = int(gross.sum() + (rng.chisquare(2, n)[~gross] > BOUND).sum())
        levels.append(nis_tail_level(tail, n, 0.999, p))
        gross2 = rng.random(n) < 2 * p
        tail2 = int(gross2.sum() + (rng.chisquare(2, n)[~gross2] > BOUND).sum())
        doubled.append(nis_tail_level(tail2, n, 0.999, p))
    assert levels.count("green") >= 198
    assert doubled.count("red") == 200


def test_share_measured_at_the_bound_is_the_stated_contamination(rng):
    """``outlier_share_of_tail`` inverts ``nis_tail_expected`` (hand formula on a grid, 0 for
    a tail lighter than a Gaussian's), and measured on residuals drawn from a contamination
    (``p`` gross, the rest χ²₂) it recovers ``p`` within its sampling error; the tail rule is
    then green on the very residuals the share was measured on."""
    for p in (0.0, 0.001, 0.0084, 0.03, 0.2, 0.49):
        for q in (0.99, 0.999):
            assert outlier_share_of_tail(nis_tail_expected(q, p), q) == pytest.approx(p, abs=1e-12)
    assert outlier_share_of_tail(0.0) == 0.0 and outlier_share_of_tail(0.001) == 0.0
    with pytest.raises(ValueError):
        outlier_share_of_tail(0.1, 1.0)
    n, p = 20000, 0.02
    est = []
    for _ in range(50):
        gross = rng.random(n) < p
        d2 = np.where(gross, BOUND * (1.0 + rng.exponential(3.0, n)), rng.chisquare(2, n))
        tail = int((d2 > BOUND).sum())
        share = outlier_share_of_tail(tail / n)
        est.append(share)
        assert nis_tail_level(tail, n, 0.999, share) == "green"
    sd = np.sqrt(p * (1 - p) / n)  # the binomial sampling error of the share
    assert np.mean(est) == pytest.approx(p, abs=3 * sd / np.sqrt(50) + 1e-4)
    assert np.std(est) == pytest.approx(sd, rel=0.35)


def _facts(nis, share):
    return RunFacts(main="recovered", translation_errors={}, relations=0, nis=nis,
                    outlier_share=share)  # fmt: skip


def test_map_log_lamp_judges_the_bulk_within_the_bound(rng):
    """NIS of a consistent filter with 4 % gross innovations (NIS 30–300): stated, the lamp
    is green and its q is the mean within the 99.9 % bound over E[χ²₂ | within] (a Monte
    Carlo of χ²₂ gives that expectation: the ratio of the inliers' mean to it ≈ 1); unstated
    it is red (tail and mean); stated 1 % it is red (the tail beyond what is stated). A bulk
    half as wide as stated is caught either way (q ≈ 0.25, red)."""
    from slamrel.report.verdict import _map_log_lines

    n = 4000
    v = rng.chisquare(2, n)
    gross = rng.choice(n, size=160, replace=False)
    v[gross] = rng.uniform(30, 300, size=160)
    (stated,) = _map_log_lines(_facts(v, 0.04))
    draws = rng.chisquare(2, 2_000_000)
    truncated = draws[draws <= BOUND].mean()
    assert stated.level == "green"
    assert stated.measure == pytest.approx(v[v <= BOUND].mean() / truncated, rel=1e-3)
    assert stated.measure == pytest.approx(1.0, abs=0.06)
    assert "states 4 % gross errors" in stated.value
    (unstated,) = _map_log_lines(_facts(v, 0.0))
    assert unstated.level == "red" and "gross" not in unstated.value
    (too_few,) = _map_log_lines(_facts(v, 0.01))
    assert too_few.level == "red"
    assert gaussian_breaks(_facts(v, 0.04)) == []
    assert gaussian_breaks(_facts(v, 0.01))[0].startswith("heavy tails: ")
    (narrow,) = _map_log_lines(_facts(v / 4, 0.04))
    assert narrow.level == "red" and narrow.measure == pytest.approx(0.25, abs=0.03)


def _with_gross_errors(share: float, seed: int):
    """simple1's healthy bundle (true noise, true map marginals) with ``share`` of its
    measurements replaced by gross errors: range off by 1–3 m, bearing by 0.3–1 rad (either
    sign), as a misread or a reflection gives."""
    b = healthy_bundle("simple1", seed, "marginal", odometry=None)
    rng = np.random.default_rng([38, seed])
    z = b.measurements.copy()
    k = rng.random(len(z)) < share
    sign = rng.choice([-1.0, 1.0], size=(int(k.sum()), 2))
    z[k, 0] = np.abs(z[k, 0] + sign[:, 0] * rng.uniform(1.0, 3.0, int(k.sum())))
    z[k, 1] = se2.wrap_angle(z[k, 1] + sign[:, 1] * rng.uniform(0.3, 1.0, int(k.sum())))
    return replace(b, measurements=z), float(k.mean())


def _map_log(bundle, stated):
    b = replace(bundle, sensor=replace(bundle.sensor, outlier_share=stated))
    verdict = run_verdict(RunFacts.of(score_bundle(RunInput(b, name="gross"))))
    return next(ln for ln in verdict.lines if ln.key == "map_log"), verdict


@pytest.mark.parametrize("seed", [0, pytest.param(1, marks=pytest.mark.slow)])
def test_a_run_with_the_gross_errors_it_states_agrees_with_its_log(seed):
    """3 % gross errors: stated as measured, the map–log lamp is green and no heavy tail is
    named; unstated, or stated as a sixth of what is there, it is red with heavy tails named."""
    b, measured = _with_gross_errors(0.03, seed)
    line, verdict = _map_log(b, measured)
    assert line.level == "green", line.value
    assert not any("heavy tails" in ln.value for ln in verdict.lines)
    for stated in (None, measured / 6):
        line, _ = _map_log(b, stated)
        assert line.level == "red" and "cause: heavy tails" in line.value, line.value
