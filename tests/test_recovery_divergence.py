"""Divergence is a finding: re-entry of the filter, stretches of map/log disagreement, their
report through the CLI, and the robust (M-estimator) update shared by filter, smoother and
batch. Oracles: the injected interval, the clean run, hand-computed NIS medians and weights."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

from recovery.batch_refinement import normal_equations
from recovery.ekf import GATED, REENTRY, ROBUST_C, USED, run_filter
from recovery.recover import filter_input, recover
from relation_metric.consistency import NeesBlowup, flag_runs, nees_blowups
from relation_metric.errors import DivergenceError
from slamrel.cli import main
from slamrel.formats.bundle import read_bundle, write_bundle
from slamrel.formats.trajectories import read_trajectory
from slamrel.runs.nees import blowups, recovery_nees
from slamrel.simulation.bundles import simulate_bundle


def _inject(b, t0: float, t1: float, seed: int):  # type: ignore[no-untyped-def]
    """Associate every measurement in [t0, t1) with another (wrong) landmark."""
    rng = np.random.default_rng(seed)
    lm = b.measurement_landmarks.copy()
    w = (b.measurement_times >= t0) & (b.measurement_times < t1)
    idx = np.searchsorted(b.map_ids, lm[w])
    lm[w] = b.map_ids[(idx + rng.integers(1, len(b.map_ids), w.sum())) % len(b.map_ids)]
    return replace(b, measurement_landmarks=lm), int(w.sum())


def _position_error(rec, truth):  # type: ignore[no-untyped-def]
    k = np.searchsorted(rec.trajectory.timestamps, truth.timestamps)
    d = rec.trajectory.poses[k, :2] - truth.poses[:, :2]
    return truth.timestamps, np.hypot(d[:, 0], d[:, 1])


def _shifted(tmp_path: Path) -> Path:
    """A broken map: every other landmark moved by (3, −2) m (the map disagrees with itself,
    so no pose agrees with all of it; a map moved as a whole would agree after one jump)."""
    b = simulate_bundle(51, steps=300)
    xy = b.map_xy.copy()
    xy[::2] += [3.0, -2.0]
    write_bundle(tmp_path / "b", replace(b, map_xy=xy))
    return tmp_path / "b"


@pytest.mark.parametrize("seed", [3, 4, 5])
def test_injected_two_second_disagreement_is_found_and_reentered(seed: int) -> None:
    clean = simulate_bundle(seed, steps=600)
    bad, n_bad = _inject(clean, 20.0, 22.0, seed)
    assert n_bad >= 10
    r = recover(bad, method="filter")
    r0 = recover(clean, method="filter")
    assert r0.stretches == () and not r0.diverged
    # one stretch, starting at the injection, ending within 2.5 s after it
    assert len(r.stretches) == 1
    s = r.stretches[0]
    assert s.t0 == pytest.approx(20.0) and 21.5 <= s.t1 <= 24.5
    assert s.reentries >= 1 and r.divergence.fraction_of_log == pytest.approx(
        (s.t1 - s.t0) / (clean.controls[-1, 0] - clean.controls[0, 0])
    )
    # re-entered: after the stretch the filter is back on the clean run's track
    t, e = _position_error(r, clean.groundtruth)
    _, e0 = _position_error(r0, clean.groundtruth)
    after = t > s.t1 + 3.0
    assert e[after].max() < e0.max() + 0.1
    assert len(r.trajectory) == len(r0.trajectory)


def test_reentry_inflates_by_the_median_nis_of_the_run() -> None:
    bad, _ = _inject(simulate_bundle(4, steps=600), 20.0, 22.0, 4)
    inp = filter_input(bad, map_mode="marginal")
    n = 6
    fr = run_filter(inp, max_outlier_run=n)
    ev = fr.events
    assert (ev.kind == REENTRY).sum() >= 1
    # oracle: walk the processing order, restart the count after each re-entry
    v = np.asarray(fr.nis)[fr.order]
    expected, run = [], []
    for j, x in zip(fr.order.tolist(), v.tolist()):
        if x > fr.outlier_bound:
            run.append(x)
            if len(run) == n:
                upper_median = sorted(run)[n // 2]
                expected.append((j, max(1.0, upper_median / chi2.ppf(0.9999, 2))))
                run = []
        else:
            run = []
    assert ev.measurement[ev.kind == REENTRY].tolist() == [j for j, _ in expected]
    np.testing.assert_allclose(ev.inflation[ev.kind == REENTRY], [a for _, a in expected])
    # the posterior covariance after the last measurement of the epoch includes the inflation
    assert fr.outlier_bound == pytest.approx(chi2.ppf(0.9999, 2))


def test_runs_bridges_short_gaps() -> None:
    f = np.array([0, 1, 1, 1, 0, 1, 1, 1, 0, 0, 0, 1, 1, 1, 1, 0, 1], dtype=bool)
    st, en = flag_runs(f, 3, max_gap=1)
    assert st.tolist() == [1, 11] and en.tolist() == [7, 14]
    st, en = flag_runs(f, 4, max_gap=1)
    assert st.tolist() == [11] and en.tolist() == [14]
    assert [a.tolist() for a in flag_runs(np.zeros(5, dtype=bool), 1)] == [[], []]


@pytest.mark.slow
def test_diverging_bundle_exits_0_with_trajectory_and_intervals(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    b = _shifted(tmp_path)
    out, rep = tmp_path / "t.txt", tmp_path / "r.json"
    rc = main(["recover", str(b), "-o", str(out), "--report", str(rep), "--method", "batch"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "DISAGREE" in text and "np.float64" not in text and "[" in text
    bundle = read_bundle(b)
    traj = read_trajectory(out).trajectory
    # the whole log: first to last control time
    assert traj.timestamps[0] == pytest.approx(bundle.controls[0, 0])
    assert traj.timestamps[-1] == pytest.approx(bundle.controls[-1, 0])
    assert np.isfinite(traj.poses).all()
    d = json.loads(rep.read_text())["divergence"]
    # the default (redescending weights) follows one half of the self-contradicting map and
    # reports the other: 48% of the log measured; the plain filter (+ re-entry) over 50%
    assert d["diverged"] and d["count"] >= 1 and 0.4 < d["fraction_of_log"] <= 1.0
    for s in d["stretches"]:
        assert s["t0"] <= s["t1"] and s["outlying"] <= s["measurements"]
        assert s["nis_median"] > d["outlier_bound"]
    argv = ["recover", str(b), "-o", str(out), "--report", str(rep), "--robust", "none", "-q"]
    assert main(argv) == 0
    d = json.loads(rep.read_text())["divergence"]
    assert d["diverged"] and d["count"] >= 1 and 0.5 < d["fraction_of_log"] <= 1.0
    # opt-in failure restores the error
    rc = main(["recover", str(b), "-o", str(tmp_path / "u.txt"), "-q", "--fail-on-divergence"])
    assert rc == 3
    err = capsys.readouterr().err
    assert "consecutive innovations" in err and "measurements.csv:" in err
    assert "np.float64" not in err


def test_healthy_bundle_reports_agreement(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    write_bundle(tmp_path / "h", simulate_bundle(8, steps=300))
    rep = tmp_path / "r.json"
    assert (
        main(["recover", str(tmp_path / "h"), "-o", str(tmp_path / "t"), "--report", str(rep)]) == 0
    )
    assert "map and log agree" in capsys.readouterr().out
    d = json.loads(rep.read_text())
    assert d["divergence"]["count"] == 0 and not d["divergence"]["diverged"]
    assert 1.0 < d["nis"]["mean"] < 3.0


def test_raise_mode_and_plain_mode_agree_with_reenter_before_the_first_run(tmp_path: Path) -> None:
    bad = read_bundle(_shifted(tmp_path))
    with pytest.raises(DivergenceError, match=r"t=.*consecutive"):
        recover(bad, method="filter", on_divergence="raise")
    a = recover(bad, method="filter", max_outlier_run=None)
    assert a.divergence.events and not any(a.divergence.events.values())
    assert a.stretches  # reported even without re-entry


# --- robust update ---------------------------------------------------------------------------


def test_robust_is_the_plain_filter_on_a_healthy_run() -> None:
    b = simulate_bundle(11, steps=250)
    inp = filter_input(b, map_mode="marginal")
    plain = run_filter(inp)
    for kind in ("huber", "cauchy", "redescending"):
        fr = run_filter(inp, robust=kind, robust_threshold=50.0)
        np.testing.assert_array_equal(fr.poses, plain.poses)
        assert (fr.weights == 1.0).all()


def test_redescending_weight_is_taken_at_the_filter_innovation() -> None:
    """Without re-entry: w = min(1, c²/NIS) exactly, NIS under the un-weighted S (the weight
    is not iterated); the pull w·d = c²/d of an outlier falls as it grows."""
    bad, _ = _inject(simulate_bundle(12, steps=400), 15.0, 16.0, 1)
    inp = filter_input(bad, map_mode="marginal")
    c = 2.0
    fr = run_filter(inp, robust="redescending", robust_threshold=c, max_outlier_run=None)
    used = np.asarray(fr.status) == USED
    v = np.asarray(fr.nis)[used]
    np.testing.assert_allclose(np.asarray(fr.weights)[used], np.minimum(1.0, c * c / v), rtol=1e-12)
    assert (v > 10 * c * c).sum() >= 5  # gross outliers were there, and weighted down
    plain = run_filter(inp, max_outlier_run=None)
    order = np.asarray(fr.order)
    first = int(np.argmax(np.asarray(fr.nis)[order] > c * c))  # the first weighted one
    before = order[: first + 1]  # identical to the plain filter up to and including it
    np.testing.assert_array_equal(np.asarray(fr.nis)[before], np.asarray(plain.nis)[before])
    assert (
        first > 0
        and np.asarray(fr.nis)[order[first + 1]] != np.asarray(plain.nis)[order[first + 1]]
    )


def test_robust_weights_are_suspended_while_reacquiring() -> None:
    """After a re-entry the filter re-acquires: every measurement from the next one up to the
    first within the outlier bound gets weight 1, whatever its NIS; the others get c²/NIS."""
    bad, _ = _inject(simulate_bundle(5, steps=600), 20.0, 22.0, 5)
    inp = filter_input(bad, map_mode="marginal")
    c = 1.5
    fr = run_filter(inp, robust="redescending", robust_threshold=c)
    order = np.asarray(fr.order)
    v, w = np.asarray(fr.nis)[order], np.asarray(fr.weights)[order]
    ok = np.asarray(fr.status)[order] == USED
    reentries = set(fr.events.measurement[fr.events.kind == REENTRY].tolist())
    assert reentries
    expected = np.ones_like(v)
    suspended = False
    for i, j in enumerate(order.tolist()):  # the rule, written out per measurement
        if not suspended and v[i] > c * c:
            expected[i] = c * c / v[i]
        suspended = (suspended and v[i] > fr.outlier_bound) or j in reentries
    np.testing.assert_allclose(w[ok], expected[ok], rtol=1e-12)
    assert (w[ok] == 1.0).sum() > (v[ok] <= c * c).sum()  # some outliers were not weighted


@pytest.mark.parametrize("kind", ["huber", "cauchy"])
def test_robust_weight_is_the_fixed_point(kind: str) -> None:
    from scipy.optimize import brentq

    from recovery.ekf import _robust_weight

    rng = np.random.default_rng(3)
    c = ROBUST_C
    for _ in range(50):
        a = rng.normal(size=(2, 2))
        reff = np.diag(rng.uniform(0.01, 1.0, 2))
        s = a @ a.T + reff
        y = rng.normal(size=2) * rng.uniform(3.0, 30.0)

        def d(w: float, y=y, s=s, reff=reff) -> float:  # type: ignore[no-untyped-def]
            return float(np.sqrt(y @ np.linalg.solve(s + (1 / w - 1) * reff, y)))

        if d(1.0) <= c:
            continue
        power = 2 if kind == "cauchy" else 1

        def eq(w: float, d=d, power=power) -> float:  # type: ignore[no-untyped-def]
            return float(np.log(w) - power * np.log(min(1.0, c / d(w))))

        oracle = brentq(eq, 1e-12, 1.0)
        got = _robust_weight(
            kind == "cauchy", c, y[0], y[1], s[0, 0], s[0, 1], s[1, 1],
            reff[0, 0], reff[0, 1], reff[1, 1],
        )  # fmt: skip
        assert got == pytest.approx(oracle, rel=1e-6)


def test_robust_weights_reach_filter_counts_and_batch() -> None:
    bad, _ = _inject(simulate_bundle(12, steps=400), 15.0, 16.0, 1)
    inp = filter_input(bad, map_mode="marginal")
    fr = run_filter(inp, robust="huber", max_outlier_run=None)
    w = np.asarray(fr.weights)
    down = np.flatnonzero(w < 1.0)
    assert down.size >= 3
    assert (np.asarray(fr.nis)[down] > ROBUST_C**2).all()
    used = np.flatnonzero(fr.status == USED)
    x = fr.poses
    h1, g1, c1, _ = normal_equations(inp, x, used)
    h2, g2, c2, _ = normal_equations(inp, x, used, robust=np.ones_like(w))
    assert c1 == pytest.approx(c2) and abs(h1 - h2).max() == 0.0
    # weight w scales the measurement's information: cost terms shrink by exactly w
    one = used[np.isin(used, down)][:1]
    _, _, c_one, _ = normal_equations(inp, x, one)
    _, _, c_one_w, _ = normal_equations(inp, x, one, robust=w)
    _, _, c_none, _ = normal_equations(inp, x, used[:0])
    assert c_one_w - c_none == pytest.approx(w[one[0]] * (c_one - c_none), rel=1e-6)
    r = recover(bad, method="batch", robust="huber", max_outlier_run=None,
                robust_threshold=ROBUST_C, robust_scale=1.0)  # fmt: skip
    assert r.counts.downweighted == int(((w < 1) & (fr.status == USED)).sum())
    assert 0.0 < r.counts.downweighted_fraction < 1.0
    assert (r.status != GATED).all()


def test_robust_scale_is_estimated_from_a_plain_pass() -> None:
    bad, _ = _inject(simulate_bundle(12, steps=400), 15.0, 16.0, 1)
    r = recover(bad, method="smoother", robust="cauchy")
    plain = recover(bad, method="filter", robust=None)
    v = np.asarray(plain.nis)
    v = v[np.isfinite(v)]
    scale = np.sqrt(np.median(v) / chi2.ppf(0.5, 2))
    rb = r.robust
    assert rb is not None and rb.kind == "cauchy"
    assert rb.scale == pytest.approx(scale) and rb.threshold == 1.5
    assert rb.effective == pytest.approx(1.5 * scale)
    # a uniformly mis-scaled filter (all covariances × 100) gets the same weights: the scale
    # absorbs the tuning, so a mis-tuned healthy run is not mistaken for one with outliers
    k = 100.0
    scaled = replace(
        bad,
        map_marginals=bad.map_marginals / k,
        initial_covariance=bad.initial_covariance / k,
        sensor=replace(bad.sensor, sigma_range=bad.sensor.sigma_range / 10,
                       sigma_bearing=bad.sensor.sigma_bearing / 10),
        motion=replace(bad.motion, sigma=tuple(s / 10 for s in bad.motion.sigma)),
    )  # fmt: skip
    r2 = recover(scaled, method="filter", robust="cauchy", max_outlier_run=None)
    r1 = recover(bad, method="filter", robust="cauchy", max_outlier_run=None)
    np.testing.assert_allclose(r2.weights, r1.weights, rtol=1e-6, atol=1e-9)
    assert r.report()["robust"]["kind"] == "cauchy"  # type: ignore[index]


def test_indefinite_smoothed_covariance_is_repaired_not_an_error() -> None:
    from recovery.recover import _check_finite

    rng = np.random.default_rng(5)
    a = rng.normal(size=(6, 3, 3))
    covs = a @ a.transpose(0, 2, 1)
    covs[2] -= 1.5 * np.linalg.eigvalsh(covs[2])[0] * np.eye(3)  # min eigenvalue −0.5 λ_min
    fixed, n = _check_finite(np.zeros((6, 3)), covs, np.arange(6.0), repair=True)
    assert n == 1 and np.linalg.eigvalsh(fixed[2])[0] >= -1e-12
    np.testing.assert_array_equal(fixed[[0, 1, 3, 4, 5]], covs[[0, 1, 3, 4, 5]])
    with pytest.raises(DivergenceError, match="non-PSD"):
        _check_finite(np.zeros((6, 3)), covs, np.arange(6.0))


def test_smoothed_covariance_check_is_the_one_of_relation_metric_checks() -> None:
    from recovery.recover import _check_finite

    # all-ones (eigenvalues 3, 0, 0) shifted by −2e-9: the smallest eigenvalue −2e-9 is below
    # −COV_RTOL · max |C_ij| = −1e-9 (though above −1e-9 × the largest eigenvalue, 3)
    c = np.ones((3, 3)) - 2e-9 * np.eye(3)
    ok = np.eye(3)
    fixed, n = _check_finite(np.zeros((2, 3)), np.stack([ok, c]), np.arange(2.0), repair=True)
    assert n == 1 and np.linalg.eigvalsh(fixed[1])[0] >= -1e-15
    np.testing.assert_array_equal(fixed[0], ok)
    # and an asymmetric one is symmetrised
    a = ok.copy()
    a[0, 1] = 1e-6
    fixed, n = _check_finite(np.zeros((1, 3)), a[None], np.arange(1.0), repair=True)
    assert n == 1 and fixed[0][0, 1] == pytest.approx(0.5e-6, rel=1e-9)
    assert fixed[0][1, 0] == pytest.approx(0.5e-6, rel=1e-9)


def test_nees_blowups_against_ground_truth(tmp_path: Path) -> None:
    t = np.arange(40.0)
    nees = np.full(40, 1.0)
    nees[5:20] = 1e3  # 15 poses beyond the bound
    nees[12] = 2.0  # one pose inside: bridged
    nees[30:33] = 1e4  # too short a run
    nees[25] = np.nan  # no ground truth there
    out = nees_blowups(t, nees, min_run=5)
    assert out == [NeesBlowup(t0=5.0, t1=19.0, poses=15, nees_max=1e3)]
    bad, _ = _inject(simulate_bundle(4, steps=600), 20.0, 22.0, 4)
    r = recover(bad, method="filter")
    got = recovery_nees(bad, r)
    assert got is not None
    ns = blowups(got[0], r.divergence.max_outlier_run)
    assert len(ns) == 1 and 19.0 <= ns[0].t0 <= 21.0 and ns[0].t1 <= 26.0
    # recover --report writes them in its divergence, as metrics.json does
    write_bundle(tmp_path / "b", bad)
    rep = tmp_path / "r.json"
    argv = ["recover", str(tmp_path / "b"), "-o", str(tmp_path / "t.txt"), "--method", "filter"]
    assert main([*argv, "--report", str(rep), "-q"]) == 0
    assert json.loads(rep.read_text())["divergence"]["nees_stretches"] == [ns[0].as_dict()]
