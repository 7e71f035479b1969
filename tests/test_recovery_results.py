"""The recovery's typed results and their JSON: each record's ``as_dict()`` against the dict
the report wrote before the records existed, rebuilt here from the recovery's raw arrays
(status, weights, NIS, stretches) with scipy's χ² quantiles; the recovery's NEES against the
ground truth (computed outside the recovery, by slamrel.runs.nees) against a pose-by-pose
loop; and the one runs-of-flags helper on hand-computed cases."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from scipy.stats import chi2

from recovery.bundle import Bundle
from recovery.ekf import GATED, OUTSIDE, UNASSOCIATED, USED
from recovery.recover import recover
from recovery.results import NisStats, Recovery
from relation_metric.consistency import OUTLIER_PROBABILITY, flag_runs
from slamrel.runs.nees import blowups, recovery_nees
from slamrel.simulation.bundles import simulate_bundle

# ---------------------------------------------------------------------------- flag_runs


def _runs(flags: list[int], min_length: int, max_gap: int = 0) -> list[tuple[int, int]]:
    st, en = flag_runs(np.array(flags, dtype=bool), min_length, max_gap=max_gap)
    return list(zip(st.tolist(), en.tolist()))


def test_flag_runs_empty_and_all_false() -> None:
    assert _runs([], 1) == [] and _runs([], 3, max_gap=2) == []
    assert _runs([0, 0, 0], 1) == []


def test_flag_runs_all_true() -> None:
    assert _runs([1] * 5, 1) == [(0, 4)]
    assert _runs([1] * 5, 5) == [(0, 4)]
    assert _runs([1] * 5, 6) == []  # one run, too short


def test_flag_runs_without_bridging() -> None:
    f = [1, 1, 0, 1, 1, 1, 0, 0, 1, 0, 1, 1]
    assert _runs(f, 1) == [(0, 1), (3, 5), (8, 8), (10, 11)]
    assert _runs(f, 2) == [(0, 1), (3, 5), (10, 11)]
    assert _runs(f, 3) == [(3, 5)]


def test_flag_runs_bridges_gaps_up_to_max_gap() -> None:
    f = [1, 1, 0, 1, 1, 0, 0, 1, 1]  # gaps of 1 and 2
    assert _runs(f, 2) == [(0, 1), (3, 4), (7, 8)]
    assert _runs(f, 2, max_gap=1) == [(0, 4), (7, 8)]  # the gap of 2 is not bridged
    assert _runs(f, 2, max_gap=2) == [(0, 8)]


def test_flag_runs_drops_short_runs_before_bridging() -> None:
    f = [1, 1, 1, 0, 1, 0, 1, 1, 1]  # the lone 1 at 4 does not carry a bridge
    assert _runs(f, 3, max_gap=1) == [(0, 2), (6, 8)]
    assert _runs(f, 3, max_gap=3) == [(0, 8)]  # gap 3..5 (three values) bridged
    assert _runs(f, 1, max_gap=1) == [(0, 8)]


def test_flag_runs_agrees_with_a_loop() -> None:
    rng = np.random.default_rng(3)
    for _ in range(200):
        f = rng.random(int(rng.integers(0, 40))) < rng.random()
        m, g = int(rng.integers(1, 5)), int(rng.integers(0, 4))
        runs, k = [], 0  # oracle: walk the flags, then merge
        while k < f.size:
            if f[k]:
                j = k
                while j + 1 < f.size and f[j + 1]:
                    j += 1
                if j - k + 1 >= m:
                    runs.append([k, j])
                k = j + 1
            else:
                k += 1
        merged: list[list[int]] = []
        for a, b in runs:
            if merged and a - merged[-1][1] - 1 <= g:
                merged[-1][1] = b
            else:
                merged.append([a, b])
        assert _runs(f.astype(int).tolist(), m, g) == [tuple(r) for r in merged]


# ---------------------------------------------------------------------------- the records


@pytest.fixture(scope="module")
def broken_bundle() -> Bundle:
    """A simulated run whose associations are wrong for 2 s (stretches, NEES blow-ups)."""
    b = simulate_bundle(4, steps=400)
    rng = np.random.default_rng(4)
    lm = b.measurement_landmarks.copy()
    w = (b.measurement_times >= 15.0) & (b.measurement_times < 17.0)
    idx = np.searchsorted(b.map_ids, lm[w])
    lm[w] = b.map_ids[(idx + rng.integers(1, len(b.map_ids), w.sum())) % len(b.map_ids)]
    return replace(b, measurement_landmarks=lm)


@pytest.fixture(scope="module")
def broken(broken_bundle: Bundle) -> Recovery:
    return recover(broken_bundle, method="batch", robust="huber")


def _json_native(d: object) -> object:
    """``d`` through JSON and back: equal to ``d`` only if every value is JSON-native."""
    return json.loads(json.dumps(d))


def test_counts_as_dict_is_the_hand_count(broken: Recovery) -> None:
    st, w = broken.status, broken.weights
    assert w is not None
    used, gated = int((st == USED).sum()), int((st == GATED).sum())
    expected = {
        "measurements": st.size,
        "used": used,
        "gated": gated,
        "unassociated": int((st == UNASSOCIATED).sum()),
        "outside": int((st == OUTSIDE).sum()),
        "skipped_unknown": 0,
        "gated_fraction": gated / (used + gated),
        "downweighted": int(((w < 1) & (st == USED)).sum()),
        "downweighted_fraction": int(((w < 1) & (st == USED)).sum()) / (used + gated),
        "downweight_loss": float((1 - w[st == USED]).sum()) / (used + gated),
    }
    d = broken.counts.as_dict()
    assert list(d) == list(expected) and d == pytest.approx(expected, rel=1e-12)
    assert 0 < d["downweighted"] < d["used"]  # the records are not trivially zero
    assert all(type(d[k]) is int for k in list(expected)[:6] + ["downweighted"])
    assert _json_native(d) == d


def test_nis_stats_as_dict_from_the_nis(broken: Recovery) -> None:
    v = broken.nis[np.isfinite(broken.nis)]
    bound = broken.divergence.outlier_bound
    assert bound == pytest.approx(chi2.ppf(OUTLIER_PROBABILITY, 2))
    expected = {
        "count": v.size,
        "mean": v.mean(),
        "median": np.median(v),
        "expected_mean": 2.0,
        "fraction_beyond_95": (v > chi2.ppf(0.95, 2)).mean(),
        "outlier_bound": bound,
        "fraction_beyond_bound": (v > bound).mean(),
    }
    d = broken.nis_stats.as_dict()
    assert list(d) == list(expected) and d == pytest.approx(expected, rel=1e-12)
    assert 0 < d["fraction_beyond_bound"] < 1 and _json_native(d) == d  # type: ignore[operator]


def test_nis_stats_without_measurements_writes_three_keys() -> None:
    d = NisStats(0, None, None, None, 18.4, None).as_dict()
    assert d == {"count": 0, "mean": None, "median": None}


def test_recovery_nees_is_the_pose_by_pose_nees_after_the_prior(
    broken_bundle: Bundle, broken: Recovery
) -> None:
    got = recovery_nees(broken_bundle, broken)
    assert got is not None
    curve, unaligned = got
    truth = broken_bundle.groundtruth
    assert truth is not None
    # oracle: a loop over the grid poses at a ground-truth time, the first (the prior) left out
    t, poses, covs = broken.trajectory.timestamps, broken.trajectory.poses, broken.covariances
    expected, times = [], []
    for k in range(1, t.size):
        j = int(np.argmin(np.abs(truth.timestamps - t[k])))
        if abs(truth.timestamps[j] - t[k]) > 1e-6:
            continue
        e = truth.poses[j] - poses[k]
        e[2] = (e[2] + np.pi) % (2 * np.pi) - np.pi
        expected.append(float(e @ np.linalg.solve(covs[k], e)))
        times.append(t[k])
    assert curve.times is not None and curve.times.tolist() == times
    np.testing.assert_allclose(curve.values, expected, rtol=1e-9)
    assert curve.summary.mean == pytest.approx(np.mean(expected), rel=1e-12)
    assert curve.summary.band == pytest.approx(tuple(chi2.ppf([0.025, 0.975], 3)), rel=1e-9)
    # simulated runs start at the true pose: the frame is the truth frame, unaligned the same
    assert unaligned == curve.summary
    # the injection shows as a NEES blow-up too, beyond the single-pose bound
    ns = blowups(curve, broken.divergence.max_outlier_run)
    assert ns and all(15.0 <= b.t1 and b.t0 <= 25.0 for b in ns)
    bound = chi2.ppf(OUTLIER_PROBABILITY, 3)
    assert all(b.nees_max > bound and b.poses >= 10 for b in ns)
    assert _json_native([b.as_dict() for b in ns]) == [b.as_dict() for b in ns]


def test_divergence_as_dict_from_its_stretches(broken: Recovery) -> None:
    dv = broken.divergence
    st = dv.stretches
    assert st  # the injection shows
    d = dv.as_dict()
    assert list(d) == [
        "diverged", "rule", "max_outlier_run", "outlier_bound", "stretches", "count",
        "duration", "fraction_of_log", "fraction_of_measurements", "events", "event_times",
        "covariances_repaired",
    ]  # fmt: skip
    assert d["diverged"] is True and d["count"] == len(st) and d["max_outlier_run"] == 10
    assert d["duration"] == pytest.approx(sum(s.t1 - s.t0 for s in st))
    assert d["stretches"] == [
        {"t0": s.t0, "t1": s.t1, "duration": s.t1 - s.t0, "measurements": s.measurements,
         "outlying": s.outlying, "nis_median": s.nis_median, "nis_max": s.nis_max,
         "reentries": s.reentries}
        for s in st
    ]  # fmt: skip
    n_nis = int(np.isfinite(broken.nis).sum())
    assert d["fraction_of_measurements"] == pytest.approx(sum(s.measurements for s in st) / n_nis)
    span = broken.trajectory.timestamps[-1] - broken.trajectory.timestamps[0]
    assert d["fraction_of_log"] == pytest.approx(d["duration"] / span)  # type: ignore[operator]
    assert sum(d["events"].values()) == len(d["event_times"]) == dv.event_count  # type: ignore[attr-defined,arg-type]
    assert _json_native(d) == d


def test_report_is_the_parts_in_order(broken: Recovery) -> None:
    rep = broken.report()
    assert list(rep) == [
        "method", "map_uncertainty", "map_uncertainty_rule", "map_prior", "map_prior_rule",
        "map_prior_reason", "poses", "measurements", "divergence", "nis", "iterations", "robust",
        "batch",
    ] + (["persistence"] if broken.persistence_factor != 1.0 else [])  # fmt: skip
    if broken.persistence_factor != 1.0:  # the injected stretch persists along its tracks
        p = rep["persistence"]
        assert isinstance(p, dict)
        rho = broken.persistence_rho
        assert p["rho"] == rho and p["factor"] == pytest.approx((1 + rho) / (1 - rho))
    assert broken.map_uncertainty is not None
    assert rep["map_uncertainty_rule"] == broken.map_uncertainty.rule
    assert rep["measurements"] == broken.counts.as_dict()
    assert rep["divergence"] == broken.divergence.as_dict()
    rb, bc = broken.robust, broken.batch
    assert rb is not None and bc is not None
    assert rep["robust"] == {
        "kind": "huber", "threshold": rb.threshold, "scale": rb.scale,
        "effective": rb.threshold * rb.scale,
    }  # fmt: skip
    assert rep["batch"] == {"cost_initial": bc.cost_initial, "cost_final": bc.cost_final}
    assert bc.cost_final <= bc.cost_initial
    assert _json_native(rep) == rep


def test_without_ground_truth_or_robust_update_the_keys_are_absent() -> None:
    b = replace(simulate_bundle(5, steps=200), groundtruth=None)
    r = recover(b, method="smoother", robust=None)
    assert recovery_nees(b, r) is None
    rep = r.report()
    assert list(rep) == [
        "method", "map_uncertainty", "map_uncertainty_rule", "map_prior", "map_prior_rule",
        "map_prior_reason", "poses", "measurements", "divergence", "nis",
        "iterations",  # the smoother's Gauss-Newton steps
    ]  # fmt: skip
    assert 1 <= rep["iterations"] <= 10  # type: ignore[operator]
    assert "nees_stretches" not in rep["divergence"]  # type: ignore[operator]
    assert r.counts.downweighted == 0 and r.counts.downweight_loss == 0.0
    assert not r.diverged and r.divergence.as_dict()["count"] == 0
