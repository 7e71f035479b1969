"""Reference EKF-SLAM: Jacobians, consistency on simulated worlds, association bookkeeping."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.stats import chi2

from recovery.models import SensorModel
from recovery.steps import build_steps
from relation_metric import se2
from relation_metric.errors import DivergenceError, InputError
from slamrel.backends.ekf_slam import ekf_slam, ekf_slam_bundle
from slamrel.simulation.bundles import world_bundle
from slamrel.simulation.worlds import make_world


def run(world, **kw):
    return ekf_slam_bundle(world_bundle(world), **kw)[1]


@pytest.mark.slow  # 20 EKF-SLAM runs: Monte Carlo, the full tier's
def test_online_pose_is_consistent_over_monte_carlo_runs():
    """Average NEES of the online pose over 20 seeded runs lies in the 95% χ² band."""
    runs = 20
    nees = []
    for seed in range(runs):
        w = make_world("simple1", noise="a", seed=seed)
        r = run(w)
        e = r.online.poses - w.truth.poses
        e[:, 2] = se2.wrap_angle(e[:, 2])
        nees.append(np.einsum("ka,kab,kb->k", e[1:], np.linalg.inv(r.online_covariance[1:]), e[1:]))
    avg = np.mean(nees, axis=0)  # per time step, averaged over runs
    lo, hi = chi2.ppf([0.025, 0.975], 3 * runs) / runs
    inside = np.mean((avg >= lo) & (avg <= hi))
    # EKF-SLAM turns mildly over-confident late in a run (linearisation; Huang & Dissanayake):
    # most steps, and the overall mean, stay inside the band
    assert inside > 0.75, inside
    assert lo < avg.mean() < hi


def test_map_matches_truth_and_beats_dead_reckoning():
    w = make_world("complex1", noise="a", seed=3)
    r = run(w)
    assert set(r.landmark_ids.tolist()) == set(np.unique(w.observations.landmark).tolist())
    truth = w.landmarks[r.landmark_ids]
    err = np.hypot(*(r.map_xy - truth).T)
    sig = np.sqrt(np.diagonal(r.map_covariance).reshape(-1, 2).sum(axis=1))
    assert np.median(err / sig) < 2.0  # errors of the size the covariance states
    assert r.map_covariance.shape == (2 * len(r.landmark_ids),) * 2
    np.testing.assert_allclose(r.map_covariance, r.map_covariance.T)
    assert np.linalg.eigvalsh(r.map_covariance).min() > -1e-9
    slam_err = np.hypot(*(r.online.poses[:, :2] - w.truth.poses[:, :2]).T).mean()
    dr_err = np.hypot(*(w.odometry.poses[:, :2] - w.truth.poses[:, :2]).T).mean()
    assert slam_err < 0.3 * dr_err


def test_corrupted_associations_are_recorded():
    w = make_world("simple2", noise="a", seed=1)
    r = run(w, corrupt_fraction=0.1, seed=5)
    frac = r.wrong_association.mean()
    assert 0.07 < frac < 0.13
    assert np.all(
        r.association[r.wrong_association] != w.observations.landmark[r.wrong_association]
    )
    assert np.all(
        r.association[~r.wrong_association] == w.observations.landmark[~r.wrong_association]
    )


@pytest.mark.slow
def test_outlier_gate_rejects_gross_outliers_and_keeps_good_data():
    """Injected 3 m range outliers are rejected; good data is rejected at about 1 − p."""
    w = make_world("complex1", noise="a", seed=4)
    b = world_bundle(w)
    rng = np.random.default_rng(11)
    z = b.measurements.copy()
    bad = rng.random(z.shape[0]) < 0.03
    z[bad, 0] += 3.0
    b = replace(b, measurements=z)
    plain = ekf_slam_bundle(b)[1]
    gated = ekf_slam_bundle(b, outlier_gate=0.999)[1]
    rejected = gated.association < 0
    first = np.zeros(z.shape[0], dtype=bool)  # a landmark's first sighting initialises it
    first[np.unique(b.measurement_landmarks, return_index=True)[1]] = True
    # landmarks initialised from an outlier are wrong from the start; judge the others
    clean = ~np.isin(b.measurement_landmarks, b.measurement_landmarks[first & bad])
    assert rejected[bad & ~first & clean].all()
    assert rejected[~bad & clean].mean() < 0.01  # 1 − p = 0.001 if consistent, plus margin
    assert not rejected[~bad & first].any()
    truth = w.landmarks[gated.landmark_ids]
    err_gated = np.hypot(*(gated.map_xy - truth).T).mean()
    err_plain = np.hypot(*(plain.map_xy - w.landmarks[plain.landmark_ids]).T).mean()
    assert err_gated < 0.5 * err_plain
    # no gate: every measurement is used, as before
    assert (plain.association >= 0).all()
    with pytest.raises(InputError, match="outlier_gate"):
        ekf_slam_bundle(b, outlier_gate=1.0)


@pytest.mark.slow
def test_gated_filter_recovers_from_an_unmodelled_turn():
    """A 1 rad bump the odometry never saw: without the rejected-run rule the gated filter
    rejects the measurements that would correct it and stays lost."""
    w = make_world("complex1", noise="a", seed=2)
    b = world_bundle(w)
    steps = build_steps(b)
    u = steps.u.copy()
    k_bump = u.shape[0] // 2
    u[k_bump, 2] += 1.0  # the estimate turns, the robot did not
    bumped = replace(steps, u=u)
    ids = b.measurement_landmarks.astype(float)

    def final_error(max_run, steps=bumped):
        r = ekf_slam(
            steps,
            b.measurements,
            ids,
            sensor=b.sensor,
            initial_pose=b.initial_pose,
            initial_covariance=b.initial_covariance,
            outlier_gate=0.999,
            max_rejected_run=max_run,
        )
        e = r.online.poses[-1] - w.truth.poses[-1]
        return np.hypot(e[0], e[1]), abs(se2.wrap_angle(e[2])), (r.association < 0).mean()

    pos_ok, th_ok, _ = final_error(10, steps)  # the same filter without the bump
    pos_rule, th_rule, rej_rule = final_error(10)
    pos_none, th_none, rej_none = final_error(10**9)
    assert th_rule < th_ok + 0.05 and pos_rule < pos_ok + 0.2
    assert th_none > 0.3  # lost: the correcting measurements were all rejected
    assert rej_none > 0.3 > 0.05 > rej_rule
    with pytest.raises(InputError, match="max_rejected_run"):
        final_error(0)


def test_nearest_neighbour_with_well_separated_landmarks():
    # few, far-apart landmarks: nearest neighbour must find the true associations
    w = make_world("simple1", noise="a", seed=2)
    b = world_bundle(w)
    keep = np.zeros(225, dtype=bool)
    keep[::15] = True
    sel = keep[b.measurement_landmarks]
    b = replace(
        b,
        measurement_times=b.measurement_times[sel],
        measurements=b.measurements[sel],
        measurement_landmarks=b.measurement_landmarks[sel],
        measurement_associated=b.measurement_associated[sel],
        measurement_lines=None,
    )
    out, r = ekf_slam_bundle(b, association="nn")
    assert r.wrong_association.mean() < 0.02
    assert (r.association >= 0).mean() > 0.9


def test_velocity_driven_world():
    w = make_world("simple2", noise="a", seed=4, rate=10)
    out, r = ekf_slam_bundle(world_bundle(w))
    assert len(r.online) == 10 * (len(w.truth) - 1)  # one pose per control step
    at = np.searchsorted(r.online.timestamps, w.truth.timestamps[:-1])
    err = np.hypot(*(r.online.poses[at, :2] - w.truth.poses[:-1, :2]).T).mean()
    dr = np.hypot(*(w.odometry.poses[:, :2] - w.truth.poses[:, :2]).T).mean()
    assert err < 0.3 * dr


def test_bad_input():
    w = make_world("simple1", seed=0)
    b = world_bundle(w)
    steps = build_steps(b)
    with pytest.raises(InputError, match="grid indices"):
        ekf_slam(
            steps,
            b.measurements[:-1],
            b.measurement_landmarks[:-1],
            sensor=b.sensor,
            initial_pose=b.initial_pose,
            initial_covariance=b.initial_covariance,
        )
    with pytest.raises(DivergenceError, match=r"t=.*measurement"):
        ekf_slam(
            steps,
            b.measurements,
            b.measurement_landmarks,
            sensor=SensorModel(0.0, 0.0),
            initial_pose=b.initial_pose,
            initial_covariance=np.zeros((3, 3)),
            noise_scale=0.0,
        )


def _update_full_product(
    mu, cov, n, slot, meas, r_cov, t, m, gate=np.inf, lin=None, heading_from=None, iterations=1
):
    """The update as it was before the blocked in-place form (full ``K Hᵀ`` product +
    ``0.5·(P + Pᵀ)`` pass); the standard Jacobians and one iteration only (no ``lin``/
    ``heading_from``)."""
    assert lin is None and heading_from is None and iterations == 1
    from recovery.models import range_bearing

    h, hx, hl = range_bearing(mu[:3], mu[slot : slot + 2])
    nu = meas - h
    nu[1] = se2.wrap_angle(nu[1])
    pht = cov[:n, :3] @ hx.T + cov[:n, slot : slot + 2] @ hl.T
    s = hx @ pht[:3] + hl @ pht[slot : slot + 2] + r_cov
    s_inv = np.linalg.inv(s)
    np.linalg.cholesky(s)
    if gate < np.inf and float(nu @ s_inv @ nu) > gate:
        return False
    gain = pht @ s_inv
    mu[:n] += gain @ nu
    mu[2] = se2.wrap_angle(mu[2])
    cov[:n, :n] -= gain @ pht.T
    cov[:n, :n] = 0.5 * (cov[:n, :n] + cov[:n, :n].T)
    return True


@pytest.mark.slow
@pytest.mark.parametrize("world, gate", [("complex1", None), ("simple2", 0.999)])
def test_symmetric_update_equals_the_old_formula(monkeypatch, world, gate):
    """The in-place symmetric update gives the old formula's results to 1e-12 (seeded run)."""
    import slamrel.backends.ekf_slam as ekfslam

    b = world_bundle(make_world(world, noise="b", seed=7))
    new = ekf_slam_bundle(b, outlier_gate=gate)[1]
    monkeypatch.setattr(ekfslam, "_update", _update_full_product)
    old = ekf_slam_bundle(b, outlier_gate=gate)[1]
    np.testing.assert_array_equal(new.association, old.association)
    np.testing.assert_allclose(new.map_xy, old.map_xy, rtol=0, atol=1e-12)
    np.testing.assert_allclose(new.map_covariance, old.map_covariance, rtol=0, atol=1e-12)
    np.testing.assert_allclose(new.online.poses, old.online.poses, rtol=0, atol=1e-12)
    np.testing.assert_allclose(new.online_covariance, old.online_covariance, rtol=0, atol=1e-12)


def test_symmetric_update_keeps_the_covariance_exactly_symmetric():
    """One update on a random symmetric P (in a larger buffer): P stays bit-symmetric."""
    from slamrel.backends.ekf_slam import _update

    rng = np.random.default_rng(5)
    n, cap = 203, 240  # more rows than one block, a view into a larger buffer
    a = rng.normal(size=(n, n))
    cov = np.zeros((cap, cap))
    cov[:n, :n] = a @ a.T / n + np.eye(n)
    mu = np.zeros(cap)
    mu[3:n] = rng.uniform(-10, 10, n - 3)
    ref_mu, ref_cov = mu.copy(), cov.copy()
    r_cov = np.diag([0.1, 0.01])
    assert _update(mu, cov, n, 41, np.array([5.0, 0.3]), r_cov, 0.0, 0)
    _update_full_product(ref_mu, ref_cov, n, 41, np.array([5.0, 0.3]), r_cov, 0.0, 0)
    p = cov[:n, :n]
    assert np.array_equal(p, p.T)
    np.testing.assert_allclose(p, ref_cov[:n, :n], rtol=0, atol=1e-12)
    np.testing.assert_allclose(mu, ref_mu, rtol=0, atol=1e-12)
    assert not cov[n:].any() and not cov[:, n:].any()  # the unused buffer is untouched
