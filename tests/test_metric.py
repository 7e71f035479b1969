"""The relation metric: definitions, invariances, the seed's early-vs-late example."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from relation_metric import se2
from relation_metric.alignment import absolute_trajectory_error, umeyama
from relation_metric.errors import InputError
from relation_metric.evaluate import evaluate
from relation_metric.metric import parse_weights, relation_errors
from relation_metric.relations import RelationSet, generate_relations
from relation_metric.stats import summarize
from relation_metric.trajectory import Trajectory


def random_walk(rng, n=300):
    steps = np.column_stack(
        (rng.uniform(0.1, 0.5, n - 1), rng.normal(0, 0.05, n - 1), rng.normal(0, 0.2, n - 1))
    )
    return Trajectory.from_poses(se2.cumulative_compose(steps), dt=0.1)


def all_pairs_relations(reference, rng, m=400):
    i = rng.integers(0, len(reference), m)
    j = rng.integers(0, len(reference), m)
    return RelationSet.from_trajectory_pairs(reference, i, j)


def test_zero_for_identical_trajectories(rng):
    ref = random_walk(rng)
    rel = all_pairs_relations(ref, rng)
    ev = evaluate(rel, ref)
    assert ev.translation.abs.max < 1e-12
    assert ev.rotation.abs.max < 1e-12
    assert ev.translation.abs.count == len(rel)


@settings(max_examples=40, deadline=None)
@given(
    st.floats(-1e3, 1e3),
    st.floats(-1e3, 1e3),
    st.floats(-math.pi, math.pi, exclude_max=True),
    st.integers(0, 2**32 - 1),
)
def test_invariant_to_rigid_transform_of_the_estimate(tx, ty, th, seed):
    rng = np.random.default_rng(seed)
    ref = random_walk(rng, 60)
    noisy = Trajectory(ref.timestamps, ref.poses + rng.normal(0, [0.05, 0.05, 0.02], (60, 3)))
    rel = all_pairs_relations(ref, rng, 100)
    a = evaluate(rel, noisy)
    b = evaluate(rel, noisy.transformed([tx, ty, th]))
    np.testing.assert_allclose(b.errors.translation, a.errors.translation, atol=1e-8)
    np.testing.assert_allclose(b.errors.rotation, a.errors.rotation, atol=1e-10)


def test_hand_computed_relation_error():
    # reference: 1 m straight ahead; estimate: 1 m ahead and 0.1 m left, turned by 0.2 rad
    rel = RelationSet([0.0], [1.0], [[1.0, 0.0, 0.0]])
    est = Trajectory([0.0, 1.0], [[0.0, 0.0, 0.0], [1.0, 0.1, 0.2]])
    ev = evaluate(rel, est)
    assert ev.errors.translation[0] == pytest.approx(0.1)
    assert ev.errors.rotation[0] == pytest.approx(0.2)
    assert ev.epsilon == pytest.approx(0.01 + 0.04)
    # the same with the estimate's first pose rotated: δ is unchanged
    est2 = Trajectory(
        [0.0, 1.0], [[5.0, 5.0, 1.0], list(se2.compose([5.0, 5.0, 1.0], [1.0, 0.1, 0.2]))]
    )
    assert evaluate(rel, est2).errors.translation[0] == pytest.approx(0.1)


def test_paper_and_metricevaluator_agree_on_planar_data(rng):
    d = se2.wrap_last(rng.normal(size=(500, 3)))
    r = se2.wrap_last(rng.normal(size=(500, 3)))
    a = relation_errors(d, r, mode="paper")
    b = relation_errors(d, r, mode="metricevaluator")
    np.testing.assert_allclose(a.translation, b.translation, rtol=1e-12)
    np.testing.assert_allclose(a.rotation, b.rotation, rtol=1e-12)
    # ... but their per-axis components differ (reference frame vs frame of pose i)
    assert not np.allclose(a.vector[:, 0], b.vector[:, 0])


def test_weights_combine_like_metricevaluator():
    d = np.array([[1.0, 2.0, 0.5]])
    r = np.array([[0.0, 0.0, 0.0]])
    e = relation_errors(d, r, mode="metricevaluator", weights="{1,1,0,0,0,0}")
    assert e.combined[0] == pytest.approx(math.sqrt(5.0))
    e = relation_errors(d, r, mode="metricevaluator", weights="0,0,0,0,0,1")
    assert e.combined[0] == pytest.approx(0.5)
    e = relation_errors(
        d, r, mode="metricevaluator", weights=[1, 1, 1, 1, 1, 1], out_of_plane=[[0.3, 0.1, -0.2]]
    )
    assert e.combined[0] == pytest.approx(math.sqrt(5 + 0.25 + 0.09 + 0.01 + 0.04))
    with pytest.raises(InputError, match="out-of-plane"):
        relation_errors(d, r, mode="paper", out_of_plane=[[0.3, 0.0, 0.0]])
    with pytest.raises(InputError, match="six"):
        parse_weights("1,1,1")


def test_summary_against_hand_computation():
    s = summarize([1.0, 2.0, 3.0, 4.0])
    assert (s.mean, s.min, s.max, s.median, s.count) == (2.5, 1.0, 4.0, 2.5, 4)
    assert s.std == pytest.approx(math.sqrt(5.0 / 3.0))  # n − 1
    assert s.rmse == pytest.approx(math.sqrt(7.5))
    assert math.isnan(summarize([]).mean) and summarize([]).as_dict()["mean"] is None


def test_seed_example_rotation_error_early_vs_late():
    """One 0.1 rad heading error early or late: same relation error, very different ATE."""
    n = 200
    steps = np.tile([0.5, 0.0, 0.0], (n - 1, 1))  # straight line
    ref = Trajectory.from_poses(se2.cumulative_compose(steps))
    ests = []
    for k in (10, 180):
        bad = steps.copy()
        bad[k, 2] = 0.1
        ests.append(Trajectory.from_poses(se2.cumulative_compose(bad)))
    rel = generate_relations(ref, "consecutive")
    early, late = (evaluate(rel, e) for e in ests)
    np.testing.assert_allclose(
        np.sort(early.errors.rotation), np.sort(late.errors.rotation), atol=1e-12
    )
    assert early.rotation.abs.mean == pytest.approx(late.rotation.abs.mean)
    assert early.translation.abs.mean == pytest.approx(late.translation.abs.mean, abs=1e-12)
    ate_early, ate_late = (absolute_trajectory_error(e, ref, align="none") for e in ests)
    assert ate_early.translation_stats.rmse > 10 * ate_late.translation_stats.rmse
    # alignment rescues the early error (one rotation explains it) but not the late one:
    # the aligned ATE still depends on *where* the same error happened
    al_early, al_late = (absolute_trajectory_error(e, ref, align="se2") for e in ests)
    assert al_late.translation_stats.rmse > 1.5 * al_early.translation_stats.rmse


def test_umeyama_recovers_similarity(rng):
    x = rng.normal(size=(50, 2)) * 10
    ang, t, c = 0.7, np.array([3.0, -4.0]), 1.7
    r = np.array([[math.cos(ang), -math.sin(ang)], [math.sin(ang), math.cos(ang)]])
    y = c * x @ r.T + t
    al = umeyama(x, y, with_scale=True)
    assert al.angle == pytest.approx(ang)
    assert al.scale == pytest.approx(c)
    np.testing.assert_allclose(al.translation, t, atol=1e-9)
    assert umeyama(x, y).scale == 1.0


def test_ate_zero_after_alignment_of_a_moved_copy(rng):
    ref = random_walk(rng, 100)
    moved = ref.transformed([10.0, -3.0, 2.0])
    res = absolute_trajectory_error(moved, ref, align="se2")
    assert res.translation_stats.max < 1e-9 and res.rotation_stats.max < 1e-9
    assert absolute_trajectory_error(moved, ref, align="none").translation_stats.min > 1.0


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.sampled_from(["paper", "metricevaluator"]))
def test_vectorised_equals_looped(seed, mode):
    rng = np.random.default_rng(seed)
    d = se2.wrap_last(rng.normal(size=(40, 3)) * [5, 5, 3])
    r = se2.wrap_last(rng.normal(size=(40, 3)) * [5, 5, 3])
    w = rng.uniform(0, 2, 6)
    vec = relation_errors(d, r, mode=mode, weights=w)
    for k in range(40):
        one = relation_errors(d[k : k + 1], r[k : k + 1], mode=mode, weights=w)
        assert one.translation[0] == vec.translation[k]
        assert one.rotation[0] == vec.rotation[k]
        assert one.combined[0] == vec.combined[k]


def test_poses_at_is_the_constant_twist_interpolation() -> None:
    """Trajectory.poses_at: stored poses at their own times, the constant-twist midpoint of a
    turn on a circle (hand computation: the arc through both poses), ends clamped."""
    import numpy as np

    from relation_metric.trajectory import Trajectory

    r, phi = 2.0, np.pi / 2  # a quarter circle of radius 2 about (0, 2), from (0, 0) heading +x
    a = np.array([0.0, 0.0, 0.0])
    b = np.array([r * np.sin(phi), r * (1 - np.cos(phi)), phi])
    traj = Trajectory(np.array([10.0, 12.0]), np.vstack((a, b)))
    got = traj.poses_at(np.array([9.0, 10.0, 11.0, 12.0, 13.0]))
    mid = np.array([r * np.sin(phi / 2), r * (1 - np.cos(phi / 2)), phi / 2])
    np.testing.assert_allclose(got, np.vstack((a, a, mid, b, b)), atol=1e-12)
