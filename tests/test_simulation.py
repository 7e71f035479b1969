"""The simulator's sensors, bundles and example pair, and the association-corruption knob,
against brute force and hand values."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from recovery.steps import build_steps
from relation_metric import se2
from relation_metric.errors import InputError
from slamrel.backends.ekf_slam import corrupt_associations, ekf_slam, ekf_slam_bundle
from slamrel.simulation.bundles import simulate_bundle
from slamrel.simulation.example import example_pair
from slamrel.simulation.sensors import (
    AllAroundSensor,
    FieldOfViewSensor,
    observe_all_around,
    observe_field_of_view,
)


def _scene(seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    poses = np.column_stack((rng.uniform(-6, 6, (15, 2)), rng.uniform(-np.pi, np.pi, 15)))
    return poses, rng.uniform(-10, 10, (30, 2))


def _brute(poses, lms, keep):  # type: ignore[no-untyped-def]
    """Every (pose, landmark) pair, by loops, with true range and bearing, where keep(r, b)."""
    rows = []
    for k, (x, y, th) in enumerate(poses):
        for j, (lx, ly) in enumerate(lms):
            r = float(np.hypot(lx - x, ly - y))
            b = float(se2.wrap_angle(np.arctan2(ly - y, lx - x) - th))
            if keep(r, b):
                rows.append((k, j, r, b))
    return np.array(rows).reshape(-1, 4)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 10_000), st.floats(1.0, 9.0), st.floats(0.0, 0.9), st.floats(0.5, 6.3))
def test_field_of_view_sensor_sees_exactly_the_pairs_in_its_window(seed, rmax, rmin, fov):
    poses, lms = _scene(seed)
    sensor = FieldOfViewSensor(0.0, 0.0, max_range=rmax, min_range=rmin, fov=fov)
    got = observe_field_of_view(poses, lms, sensor, np.random.default_rng(0))
    want = _brute(poses, lms, lambda r, b: rmin <= r <= rmax and abs(b) <= fov / 2)
    np.testing.assert_array_equal(np.column_stack((got.pose, got.landmark)), want[:, :2])
    np.testing.assert_allclose(got.range, want[:, 2], atol=1e-9)
    np.testing.assert_allclose(se2.wrap_angle(got.bearing - want[:, 3]), 0.0, atol=1e-9)
    cart = sensor._replace(cartesian_sigma=0.0)
    same = observe_field_of_view(poses, lms, cart, np.random.default_rng(0))
    np.testing.assert_allclose(same.range, want[:, 2], atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 10_000), st.floats(1.0, 9.0), st.floats(0.0, 0.9))
def test_all_around_sensor_sees_exactly_the_pairs_in_its_window(seed, rmax, rmin):
    poses, lms = _scene(seed)
    sensor = AllAroundSensor(0.0, 0.0, max_range=rmax, min_range=rmin)
    at = np.arange(0, 15, 2)
    got = observe_all_around(poses, lms, at, sensor, np.random.default_rng(0))
    want = _brute(poses, lms, lambda r, b: rmin < r < rmax)
    want = want[np.isin(want[:, 0], at)]
    np.testing.assert_array_equal(np.column_stack((got.pose, got.landmark)), want[:, :2])
    np.testing.assert_allclose(got.range, want[:, 2], atol=1e-9)
    np.testing.assert_allclose(se2.wrap_angle(got.bearing - want[:, 3]), 0.0, atol=1e-9)


def test_all_around_sensor_measures_from_part_of_the_next_increment():
    """Offset ½ of a straight 1 m step: the landmark 3 m ahead is seen at 2.5 m."""
    truth = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    u = se2.between(truth[:-1], truth[1:])
    sensor = AllAroundSensor(0.0, 0.0, max_range=8.0)
    got = observe_all_around(
        truth, np.array([[3.0, 0.0]]), np.array([0]), sensor, np.random.default_rng(0),
        increments=u, offset=0.5,
    )  # fmt: skip
    np.testing.assert_allclose(got.range, [2.5])
    np.testing.assert_allclose(got.bearing, [0.0], atol=1e-15)
    with pytest.raises(InputError, match="offset needs the increments"):
        observe_all_around(truth, truth[:, :2], np.array([0]), sensor, None, offset=0.5)


def test_simulate_bundle_rejects_an_unknown_motion_model():
    with pytest.raises(InputError, match="motion must be 'velocity' or 'odometry'"):
        simulate_bundle(0, steps=20, motion="Velocity")


def test_example_pair_relations_are_the_references_motions():
    ex = example_pair(3)
    assert ex.consecutive == len(ex.reference) - 1 and ex.loops > 0
    assert len(ex.relations) == ex.consecutive + ex.loops
    t, p = ex.reference.timestamps, ex.reference.poses
    i, j = np.searchsorted(t, ex.relations.first), np.searchsorted(t, ex.relations.second)
    np.testing.assert_allclose(ex.relations.delta, se2.between(p[i], p[j]), atol=1e-12)
    loop = slice(ex.consecutive, None)
    assert np.all(np.abs(t[j[loop]] - t[i[loop]]) >= 60.0)
    assert np.hypot(*(p[i[loop], :2] - p[j[loop], :2]).T).max() <= 2.0


def test_corrupt_associations_changes_the_share_it_is_asked_to():
    rng = np.random.default_rng(4)
    ids = rng.integers(100, 140, 5000).astype(float)
    used = rng.random(5000) < 0.9
    out = corrupt_associations(ids, used, 0.2, seed=9)
    changed = out != ids
    assert not changed[~used].any()
    assert changed[used].mean() == pytest.approx(0.2, abs=0.02)
    assert set(out[changed]) <= set(ids[used])  # replaced by ids that are in the log
    np.testing.assert_array_equal(out, corrupt_associations(ids, used, 0.2, seed=9))
    np.testing.assert_array_equal(corrupt_associations(ids, used, 0.0, seed=9), ids)
    with pytest.raises(InputError, match=r"corrupt_fraction must be in \[0, 1\)"):
        corrupt_associations(ids, used, 1.0, seed=9)


def test_ekf_slam_records_the_corrupted_associations_as_wrong():
    b = simulate_bundle(5, steps=120)
    steps = build_steps(b)
    used = steps.measurement_grid >= 0
    truth = b.measurement_landmarks
    ids = corrupt_associations(truth, used, 0.1, seed=2)
    common = dict(sensor=b.sensor, initial_pose=b.initial_pose)
    r = ekf_slam(steps, b.measurements, ids, initial_covariance=b.initial_covariance, **common,
                 true_ids=truth)  # fmt: skip
    np.testing.assert_array_equal(r.wrong_association, used & (ids != truth))
    assert r.wrong_association.any()
    # through the bundle: the same filter, the same record
    _, rb = ekf_slam_bundle(b, corrupt_fraction=0.1, seed=2)
    np.testing.assert_array_equal(rb.wrong_association, r.wrong_association)
    np.testing.assert_array_equal(rb.map_xy, r.map_xy)
