"""The landmark–pose graph: pose–landmark relations and pose–pose relations through shared
landmarks, against hand values and brute force."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from landmark_graph.landmark_association import associate_by_id
from landmark_graph.maps import LandmarkMap
from landmark_graph.pose_landmark import pose_landmark_relations, shared_landmark_relations
from relation_metric import se2
from relation_metric.errors import InputError
from relation_metric.trajectory import Trajectory


def world(rng, n_poses=40, n_landmarks=12, n_obs=200):
    poses = se2.wrap_last(rng.normal(size=(n_poses, 3)) * [10, 10, 3])
    lms = rng.uniform(-15, 15, (n_landmarks, 2))
    pose = rng.integers(0, n_poses, n_obs)
    lm = rng.integers(0, n_landmarks, n_obs)
    return poses, lms, pose, lm


def test_pose_landmark_relations_rigid_copy_and_one_displaced_landmark(rng):
    poses, lms, pose, lm = world(rng)
    ref = LandmarkMap(np.arange(12), lms)
    g = np.array([7.0, -3.0, 2.5])
    est_poses = se2.compose(g, poses)
    est_xy = se2.transform_points(g, lms)
    est = LandmarkMap(np.arange(12) + 100, est_xy)
    assoc = associate_by_id(est, ref, {k + 100: k for k in range(12)})
    r = pose_landmark_relations(est_poses, poses, pose, lm + 100, est, ref, assoc)
    assert r.error.size == 200 and r.unassociated == 0
    assert r.error.max() < 1e-9  # the whole solution moved rigidly: no relation changes
    # landmark 103 displaced by δ: x_t⁻¹ (g l* + δ) = x*_t⁻¹ l* + R(θ_t)ᵀ δ, so every
    # observation of it has error ‖δ‖ and every other one 0
    moved = est_xy.copy()
    moved[3] += [0.3, 0.4]
    est2 = LandmarkMap(est.ids, moved)
    r = pose_landmark_relations(est_poses, poses, pose, lm + 100, est2, ref, assoc)
    np.testing.assert_allclose(r.error[r.landmark == 103], 0.5, rtol=1e-12)
    assert r.error[r.landmark != 103].max() < 1e-9
    d = r.as_dict()
    assert d["relations"] == 200 and d["translation"]["abs"]["max"] == pytest.approx(0.5)


def test_pose_landmark_relations_count_unassociated_and_reject_unknown(rng):
    poses, lms, pose, lm = world(rng)
    est = LandmarkMap(np.arange(12), lms)
    ref = LandmarkMap(np.arange(1, 12), lms[1:])  # landmark 0 has no reference
    assoc = associate_by_id(est, ref)
    r = pose_landmark_relations(poses, poses, pose, lm, est, ref, assoc)
    assert r.unassociated == int((lm == 0).sum()) > 0
    assert r.error.size == 200 - r.unassociated and r.error.max() < 1e-12
    bad = lm.copy()
    bad[17] = 99
    with pytest.raises(InputError, match="observation 17: landmark id 99"):
        pose_landmark_relations(poses, poses, pose, bad, est, ref, assoc)
    with pytest.raises(InputError, match="pose index 40"):
        pose_landmark_relations(poses, poses, np.append(pose[:-1], 40), lm, est, ref, assoc)


def test_shared_landmark_relations_equal_brute_force(rng):
    n = 30
    ref = Trajectory.from_poses(se2.wrap_last(rng.normal(size=(n, 3)) * [5, 5, 2]))
    pose = rng.integers(0, n, 300)
    lm = rng.integers(0, 25, 300) * 7  # arbitrary ids
    for min_common, min_gap in ((1, 1), (2, 1), (3, 4)):
        rel = shared_landmark_relations(ref, pose, lm, min_common=min_common, min_gap=min_gap)
        seen = [set(lm[pose == k].tolist()) for k in range(n)]
        expected = [
            (i, j)
            for i, j in itertools.combinations(range(n), 2)
            if j - i >= min_gap and len(seen[i] & seen[j]) >= min_common
        ]
        got = list(zip(rel.first.astype(int).tolist(), rel.second.astype(int).tolist()))
        assert got == expected and len(expected) > 0
        i, j = np.array(expected).T
        np.testing.assert_allclose(rel.delta, se2.between(ref.poses[i], ref.poses[j]))


def test_shared_landmark_relations_refuse_a_quadratic_blow_up():
    ref = Trajectory.from_poses(np.zeros((5000, 3)))
    pose = np.arange(5000)
    with pytest.raises(InputError, match="pose pairs share a landmark"):
        shared_landmark_relations(ref, pose, np.zeros(5000, int), min_common=1, max_pairs=1e6)
