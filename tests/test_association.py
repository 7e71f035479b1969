"""Timestamp association: nearest pose, odometry correction, interpolation, counting."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from relation_metric import se2
from relation_metric.errors import AssociationError
from relation_metric.evaluate import UnassociatedRelationsWarning, evaluate
from relation_metric.relations import RelationSet
from relation_metric.time_association import associate, nearest_index
from relation_metric.trajectory import Trajectory


def test_nearest_index_ties_and_edges():
    t = np.array([0.0, 1.0, 2.0])
    np.testing.assert_array_equal(
        nearest_index(t, np.array([-5, 0.4, 0.5, 0.6, 9])), [0, 0, 0, 1, 2]
    )


def test_tolerance_and_unassociated_are_counted():
    est = Trajectory([0.0, 1.0, 2.0, 3.0], np.zeros((4, 3)))
    rel = RelationSet([0.05, 1.0, 0.0], [1.0, 1.5, 9.0], np.zeros((3, 3)))
    a = associate(rel, est)
    np.testing.assert_array_equal(a.valid, [True, False, False])
    np.testing.assert_array_equal(a.index_first[:1], [0])
    with pytest.warns(
        UnassociatedRelationsWarning,
        match=r"2 of 3 relations .*#1 .*within the time tolerance.*#2 .*outside",
    ):
        ev = evaluate(rel, est)
    assert ev.translation.abs.count == 1
    assert ev.as_dict()["unassociated"] == 2
    with pytest.raises(AssociationError, match=r"\(strict=True\)$"):
        evaluate(rel, est, strict=True)


def test_no_relation_associated_shows_both_spans():
    est = Trajectory([100.0, 101.0], np.zeros((2, 3)))
    rel = RelationSet([1.5e9], [1.5e9 + 1], np.zeros((1, 3)))
    with pytest.raises(
        AssociationError,
        match=r"1500000000\.000000 \.\. 1500000001\.000000 s, "
        r"the estimate 100\.000000 \.\. 101\.000000",
    ):
        evaluate(rel, est)


def test_odometry_correction_matches_hand_composition():
    # SLAM poses every 1 s; a relation end at t = 1.4 lies 0.4 s from the nearest pose (t = 1)
    est = Trajectory([0.0, 1.0, 2.0], [[0, 0, 0], [1, 0, 0.5], [2, 1, 1.0]])
    odo = Trajectory(
        [0.0, 0.5, 1.0, 1.5, 2.0],
        [[0, 0, 0], [0.5, 0, 0], [1, 0, 0.1], [1.3, 0.2, 0.3], [2, 0, 0.4]],
    )
    rel = RelationSet([0.0], [1.4], np.zeros((1, 3)))
    a = associate(rel, est, odometry=odo)
    assert a.valid[0] and a.via_odometry[0]
    expected = se2.compose([1, 0, 0.5], se2.between(odo.poses[2], odo.poses[3]))
    np.testing.assert_allclose(a.pose_second[0], expected)


def test_interpolation_is_exact_for_constant_twist():
    xi = np.array([1.0, 0.2, 0.3])  # per second
    t = np.arange(0.0, 10.0, 1.0)
    poses = np.array([se2.exp(xi * k) for k in t])
    est = Trajectory(t, poses)
    rel = RelationSet([0.0], [4.37], np.zeros((1, 3)))
    a = associate(rel, est, interpolate=True)
    assert a.interpolated[0]
    np.testing.assert_allclose(a.pose_second[0], se2.exp(xi * 4.37), atol=1e-12)
    # gaps longer than the limit are not interpolated over
    assert not associate(rel, est, interpolate=True, max_interpolation_gap=0.5).valid[0]


def test_index_relations(rng):
    est = Trajectory.from_poses(se2.wrap_last(rng.normal(size=(10, 3))))
    rel = RelationSet([0, 3, 2], [5, 12, 9], np.zeros((3, 3)), key="index")
    a = associate(rel, est)
    np.testing.assert_array_equal(a.valid, [True, False, True])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert evaluate(rel, est).translation.abs.count == 2


def _evo_matching(query, times, max_diff):
    """evo.core.sync.matching_time_indices, as evo writes it (a loop over argmin)."""
    iq, it = [], []
    for i, q in enumerate(query):
        d = np.abs(times - q)
        j = int(np.argmin(d))
        if d[j] <= max_diff:
            iq.append(i)
            it.append(j)
    return np.array(iq, dtype=np.int64), np.array(it, dtype=np.int64)


@pytest.mark.parametrize("seed", range(20))
def test_match_nearest_times_is_evos_matching(seed):
    from relation_metric.time_association import match_nearest_times

    rng = np.random.default_rng(seed)
    times = np.unique(np.round(rng.uniform(0, 10, rng.integers(1, 60)), 2))
    query = np.concatenate((rng.uniform(-1, 11, 50), times[::3], times[:5] + 0.005))
    for max_diff in (0.0, 0.005, 0.01, 0.3):
        got = match_nearest_times(query, times, max_diff)
        want = _evo_matching(query, times, max_diff)
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])


def test_match_nearest_times_ties_and_repeated_times():
    from relation_metric.time_association import match_nearest_times

    t = np.array([0.0, 1.0, 1.0, 2.0])
    iq, it = match_nearest_times(np.array([0.5, 1.0, 0.875, 3.0]), t, 0.5)
    np.testing.assert_array_equal(iq, [0, 1, 2])  # 3.0 is 1 s from the last time
    # a tie goes to the earlier time; a query before repeated times to the first of them; an
    # exact hit to the last of them: evo 1.38.1's search on sorted times (searchsorted with
    # side="right"; its argmin is only the fallback for unsorted times), checked live in
    # tests/test_evo_cli.py (repeats/tum_*)
    np.testing.assert_array_equal(it, [0, 2, 1])
