"""Reference EKF-SLAM: Jacobians, consistency on simulated worlds, association bookkeeping."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from relation_metric import se2
from relation_metric.errors import DivergenceError, InputError
from slamrel.backends.ekfslam import _observe, compose_jacobians, ekf_slam
from slamrel.worlds import make_world


def run(world, **kw):
    nt = world.noise_params
    o = world.observations
    meas = np.column_stack((o.t, o.range, o.bearing, o.landmark))
    return ekf_slam(
        world.odometry,
        meas,
        sigma_odometry=(nt.sigma_dx, nt.sigma_dy, nt.sigma_dtheta),
        sigma_range=nt.sigma_range,
        sigma_bearing=nt.sigma_bearing,
        true_ids=o.landmark,
        **kw,
    )


def numeric_jacobian(f, x, h=1e-7):
    cols = []
    for k in range(x.size):
        d = np.zeros_like(x)
        d[k] = h
        diff = f(x + d) - f(x - d)
        if diff.size == 3:
            diff[2] = se2.wrap_angle(diff[2])
        cols.append(diff / (2 * h))
    return np.column_stack(cols)


def test_compose_jacobians_finite_differences(rng):
    for _ in range(10):
        x = se2.wrap_last(rng.normal(size=3) * 3)
        u = se2.wrap_last(rng.normal(size=3))
        fx, fu = compose_jacobians(x, u)
        np.testing.assert_allclose(
            fx, numeric_jacobian(lambda v, u=u: se2.compose(v, u), x), atol=1e-6
        )
        np.testing.assert_allclose(
            fu, numeric_jacobian(lambda v, x=x: se2.compose(x, v), u), atol=1e-6
        )


def test_sensor_jacobians_finite_differences(rng):
    for _ in range(10):
        x = se2.wrap_last(rng.normal(size=3) * 3)
        lm = x[:2] + rng.uniform(1, 5, 2)
        _, hx, hl = _observe(x, lm)
        fx = numeric_jacobian(lambda v, lm=lm: _observe(v, lm)[0], x)
        fl = numeric_jacobian(lambda v, x=x: _observe(x, v)[0], lm)
        np.testing.assert_allclose(hx, fx, atol=1e-6)
        np.testing.assert_allclose(hl, fl, atol=1e-6)


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
    assert inside > 0.85, inside
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


def test_nearest_neighbour_with_well_separated_landmarks():
    # few, far-apart landmarks: nearest neighbour must find the true associations
    w = make_world("simple1", noise="a", seed=2)
    keep = np.zeros(225, dtype=bool)
    keep[::15] = True
    o = w.observations
    sel = keep[o.landmark]
    meas = np.column_stack((o.t[sel], o.range[sel], o.bearing[sel], np.full(sel.sum(), np.nan)))
    nt = w.noise_params
    r = ekf_slam(
        w.odometry,
        meas,
        sigma_odometry=(nt.sigma_dx, nt.sigma_dy, nt.sigma_dtheta),
        sigma_range=nt.sigma_range,
        sigma_bearing=nt.sigma_bearing,
        association="nn",
        true_ids=o.landmark[sel],
    )
    assert r.wrong_association.mean() < 0.02


def test_bad_input():
    w = make_world("simple1", seed=0)
    o = w.observations
    meas = np.column_stack((o.t + 0.5, o.range, o.bearing, o.landmark))
    with pytest.raises(InputError, match="not at an odometry time"):
        ekf_slam(
            w.odometry, meas, sigma_odometry=(0.1, 0.1, 0.05), sigma_range=0.1, sigma_bearing=0.04
        )
    with pytest.raises(DivergenceError, match=r"t=.*measurement"):
        meas = np.column_stack((o.t, o.range, o.bearing, o.landmark))
        ekf_slam(
            w.odometry,
            meas,
            sigma_odometry=(0.1, 0.1, 0.05),
            sigma_range=0.0,
            sigma_bearing=0.0,
            initial_covariance=np.zeros((3, 3)),
        )
