"""Full vs. pose-only least squares (Hu, Huang & Dissanayake): accuracy and consistency."""

from __future__ import annotations

import numpy as np
import pytest

import slamrel.backends.pose_only as po_mod
from relation_metric.consistency import nees_band, pose_nees
from relation_metric.evaluate import evaluate
from relation_metric.relations import generate_relations
from relation_metric.trajectory import Trajectory
from slamrel.backends.graph import PoseGraph, initial_landmarks, pose_covariances
from slamrel.backends.pose_only import (
    LandmarkLog,
    cartesian_observations,
    full_least_squares,
    pose_only_least_squares,
)
from slamrel.worlds import make_world


def log_of(world):
    nt = world.noise_params
    o = world.observations
    return LandmarkLog(
        world.odometry, o.pose, o.range, o.bearing, o.landmark,
        (nt.sigma_dx, nt.sigma_dy, nt.sigma_dtheta), nt.sigma_range, nt.sigma_bearing,
    )  # fmt: skip


def test_cartesian_observation_covariance_matches_sampling(rng):
    log = LandmarkLog(
        Trajectory.from_poses(np.zeros((1, 3))), np.array([0]), np.array([3.0]), np.array([0.7]),
        np.array([0]), (0.1, 0.1, 0.1), 0.05, 0.02,
    )  # fmt: skip
    _, info = cartesian_observations(log)
    r = 3.0 + rng.normal(0, 0.05, 200_000)
    b = 0.7 + rng.normal(0, 0.02, 200_000)
    sample = np.cov(np.vstack((r * np.cos(b), r * np.sin(b))))
    np.testing.assert_allclose(np.linalg.inv(info[0]), sample, rtol=0.03)


@pytest.mark.slow
def test_full_is_consistent_and_pose_only_is_overconfident_and_less_accurate():
    runs = 3
    nees_full, nees_po, err_full, err_po = [], [], [], []
    for seed in range(runs):
        w = make_world("simple1", noise="a", seed=seed)
        log = log_of(w)
        full, _ = full_least_squares(log)
        po = pose_only_least_squares(log, max_loop_pairs=300)
        z, info = cartesian_observations(log)
        ids, li = np.unique(log.landmark, return_inverse=True)
        i, u, oi = po_mod._odometry_factors(log)
        p0 = log.odometry.poses
        g_full = PoseGraph(
            p0,
            initial_landmarks(p0, log.pose, li, z, ids.size),
            i,
            i + 1,
            u,
            oi,
            log.pose,
            li,
            z,
            info,
        )
        g_po = PoseGraph(
            p0,
            np.empty((0, 2)),
            po.pairs[:, 0],
            po.pairs[:, 1],
            po.delta,
            np.linalg.inv(po.covariance),
        )
        nees_full.append(
            pose_nees(full.poses[1:], w.truth.poses[1:], pose_covariances(g_full, full)[1:])
        )
        nees_po.append(
            pose_nees(
                po.solution.poses[1:], w.truth.poses[1:], pose_covariances(g_po, po.solution)[1:]
            )
        )
        rel = generate_relations(w.truth, "global", count=1000, seed=seed)
        err_full.append(
            evaluate(rel, Trajectory(w.truth.timestamps, full.poses)).translation["abs"].mean
        )
        err_po.append(
            evaluate(rel, Trajectory(w.truth.timestamps, po.solution.poses)).translation["abs"].mean
        )
    steps = len(nees_full[0])
    lo, hi = nees_band(3, runs * steps)  # pooled over runs and steps (correlated in time: loose)
    assert np.mean(nees_full) < 2 * hi
    assert np.mean(nees_po) > 2 * np.mean(nees_full)  # pose-only is over-confident
    assert np.mean(err_full) < np.mean(err_po)  # and less accurate
