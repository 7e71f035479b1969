"""Simulated worlds (Hu, Huang & Dissanayake): geometry, sensing, noise, determinism."""

from __future__ import annotations

import numpy as np
import pytest

from relation_metric import se2
from relation_metric.errors import InputError
from slamrel.simulation.worlds import (
    NOISE_TYPES,
    SENSOR_MIN_RANGE,
    SENSOR_RANGE,
    WORLDS,
    make_world,
    path_of,
)


@pytest.mark.parametrize("name", WORLDS)
def test_path_geometry(name):
    p = path_of(name)
    steps = np.hypot(*np.diff(p[:, :2], axis=0).T)
    assert np.all(steps <= 0.5 + 1e-9) and np.all(steps > 0.49)  # 0.5 m a step (chords)
    simple = name.startswith("simple")
    assert (70 <= len(p) <= 100) if simple else (380 <= len(p) <= 460)
    # a return to the start (simple) / several revisits (complex): poses ≥ 20 steps apart in
    # time but within 1 m in space
    d = np.hypot(*(p[:, None, :2] - p[None, :, :2]).transpose(2, 0, 1))
    i, j = np.nonzero((d < 1.0) & (np.arange(len(p))[None, :] - np.arange(len(p))[:, None] > 20))
    assert i.size > 0
    if not simple:
        assert np.unique(i // 40).size >= 3  # closures in several places


def test_world_is_determined_by_name_noise_seed():
    a = make_world("simple1", noise="b", seed=5)
    b = make_world("simple1", noise="b", seed=5)
    np.testing.assert_array_equal(a.odometry.poses, b.odometry.poses)
    np.testing.assert_array_equal(a.observations.range, b.observations.range)
    c = make_world("simple1", noise="c", seed=5)
    np.testing.assert_array_equal(a.landmarks, c.landmarks)  # same features, other noise
    assert not np.array_equal(a.observations.range, c.observations.range)
    assert not np.array_equal(a.landmarks, make_world("simple1", noise="b", seed=6).landmarks)
    assert a.landmarks.shape == (225, 2)


def test_observations_respect_the_sensor_and_the_noise():
    w = make_world("complex1", noise="c", seed=1)
    o = w.observations
    true = se2.inverse_transform_points(w.truth.poses[o.pose], w.landmarks[o.landmark])
    r = np.hypot(true[:, 0], true[:, 1])
    b = np.arctan2(true[:, 1], true[:, 0])
    assert r.max() <= SENSOR_RANGE and r.min() >= SENSOR_MIN_RANGE and np.abs(b).max() <= np.pi / 2
    assert o.range.min() >= 0.0
    nt = NOISE_TYPES["c"]
    assert np.std(o.range - r) == pytest.approx(nt.sigma_range, rel=0.05)
    assert np.std(se2.wrap_angle(o.bearing - b)) == pytest.approx(nt.sigma_bearing, rel=0.05)
    # every landmark in range and field of view is observed (none silently dropped)
    k_p_l = se2.inverse_transform_points(w.truth.poses[:, None, :], w.landmarks[None])
    rr = np.hypot(k_p_l[..., 0], k_p_l[..., 1])
    bb = np.arctan2(k_p_l[..., 1], k_p_l[..., 0])
    visible = (rr <= SENSOR_RANGE) & (rr >= SENSOR_MIN_RANGE) & (np.abs(bb) <= np.pi / 2)
    assert o.t.size == int(visible.sum())


@pytest.mark.parametrize("noise", sorted(NOISE_TYPES))
def test_odometry_noise_statistics(noise):
    nt = NOISE_TYPES[noise]
    res = []
    for seed in range(5):
        w = make_world("complex2", noise=noise, seed=seed)
        res.append(
            se2.between(w.odometry.poses[:-1], w.odometry.poses[1:])
            - se2.between(w.truth.poses[:-1], w.truth.poses[1:])
        )
    res = np.concatenate(res)
    res[:, 2] = se2.wrap_angle(res[:, 2])
    np.testing.assert_allclose(
        res.std(axis=0), [nt.sigma_dx, nt.sigma_dy, nt.sigma_dtheta], rtol=0.08
    )


def test_velocity_driven_world_controls():
    rate, dt = 20, 1.0
    w = make_world("simple2", noise="a", seed=0, rate=rate, dt=dt)
    assert w.controls is not None and w.controls.shape[0] == rate * (len(w.truth) - 1)
    assert np.all(np.diff(w.controls[:, 0]) > 0)
    # true controls: the arc through consecutive poses, held over the step
    inc = se2.between(w.truth.poses[:-1], w.truth.poses[1:])
    half = inc[:, 2] / 2
    chord = np.hypot(inc[:, 0], inc[:, 1])
    arc = np.where(np.abs(half) > 1e-12, chord * half / np.sin(np.where(half == 0, 1, half)), chord)
    v_true = np.repeat(arc / dt, rate)
    w_true = np.repeat(inc[:, 2] / dt, rate)
    nt = NOISE_TYPES["a"]
    assert np.std(w.controls[:, 1] - v_true) == pytest.approx(nt.sigma_dx * np.sqrt(rate), rel=0.1)
    assert np.std(w.controls[:, 2] - w_true) == pytest.approx(
        nt.sigma_dtheta * np.sqrt(rate), rel=0.1
    )
    # integrating the true controls exactly reproduces the path (arc model is exact)
    h = dt / rate
    th = w_true * h
    small = np.abs(th) < 1e-12
    ww = np.where(small, 1.0, w_true)
    dx = np.where(small, v_true * h, v_true / ww * np.sin(th))
    dy = np.where(small, 0.0, v_true / ww * (1 - np.cos(th)))
    rebuilt = se2.cumulative_compose(np.column_stack((dx, dy, th)))[::rate]
    np.testing.assert_allclose(rebuilt[:, :2], w.truth.poses[:, :2], atol=1e-9)


def test_unknown_names():
    with pytest.raises(InputError, match="unknown world"):
        make_world("nowhere")
    with pytest.raises(InputError, match="noise"):
        make_world("simple1", noise="z")


# --- the paper's worlds ---------------------------------------------------------------------


@pytest.mark.parametrize("name", ["hu-simple1", "hu-simple2", "hu-complex1", "hu-complex2"])
def test_paper_worlds_have_the_papers_size_steps_and_sensor(name):
    from slamrel.simulation.worlds import PAPER_POSES

    w = make_world(name, noise="a", seed=2)
    p = w.truth.poses
    assert len(p) == PAPER_POSES["simple" if "simple" in name else "complex"]
    steps = np.hypot(*np.diff(p[:, :2], axis=0).T)
    assert np.all(steps <= 0.5 + 1e-9) and np.all(steps > 0.49)
    assert w.landmarks.shape == (225, 2)
    assert w.observation_model == "cartesian"
    np.testing.assert_allclose(w.observation_covariance, 0.01 * np.eye(2))
    # every feature within 5 m and ±90° is seen, also the close ones (no minimum range)
    k_p_l = se2.inverse_transform_points(p[:, None, :], w.landmarks[None])
    rr = np.hypot(k_p_l[..., 0], k_p_l[..., 1])
    bb = np.arctan2(k_p_l[..., 1], k_p_l[..., 0])
    assert w.observations.t.size == int(((rr <= 5.0) & (np.abs(bb) <= np.pi / 2)).sum())


@pytest.mark.parametrize("noise", sorted(NOISE_TYPES))
def test_cartesian_observation_noise_is_isotropic_with_the_papers_sigma(noise):
    errs = []
    for seed in range(3):
        w = make_world("hu-complex2", noise=noise, seed=seed)
        o = w.observations
        true = se2.inverse_transform_points(w.truth.poses[o.pose], w.landmarks[o.landmark])
        z = np.column_stack((o.range * np.cos(o.bearing), o.range * np.sin(o.bearing)))
        errs.append(z - true)
    e = np.concatenate(errs)
    sigma = NOISE_TYPES[noise].sigma_observation
    np.testing.assert_allclose(np.cov(e.T), sigma**2 * np.eye(2), atol=0.05 * sigma**2)
    # the range-bearing model can be chosen for a paper world too (and vice versa)
    assert make_world("hu-simple1", observation="range-bearing").observation_covariance is None
    assert make_world("simple1", observation="cartesian").observation_model == "cartesian"
    with pytest.raises(InputError, match="observation model"):
        make_world("simple1", observation="polar")
