"""Guesses from the scans' own chain (:mod:`slamrel.scans.own_guesses`).

Oracles: the simulated log's true poses (the chain drifts less than the odometry it starts
from), and the placement rule written out by hand for one scan between two chain nodes.
"""

from __future__ import annotations

import numpy as np

from relation_metric import se2
from slamrel.scans.own_guesses import chain_guesses
from slamrel.simulation.laser import laser_world, loop_path, simulate_laser_log

CORNERS = np.array([[1.5, 1.5], [28.5, 1.5], [28.5, 18.5], [1.5, 18.5]])


def _drift(poses: np.ndarray, truth: np.ndarray) -> float:
    """Largest position error of ``poses`` relative to their first pose [m]."""
    d = se2.between(se2.between(truth[0], truth), se2.between(poses[0], poses))
    return float(np.hypot(d[:, 0], d[:, 1]).max())


def test_chain_drifts_far_less_than_the_odometry_and_places_every_scan():
    truth = loop_path(CORNERS, 0.3)
    log = simulate_laser_log(laser_world("loop"), truth, seed=2)
    odo = log.scans.laser_pose
    got = chain_guesses(log.scans, odo)
    assert got.poses.shape == odo.shape
    assert got.chain.fallback == 0
    # measured: odometry 2.0 m, chain 0.09 m on this seed
    assert _drift(got.poses, log.truth) < 0.25 * _drift(odo, log.truth)
    nodes = got.chain.nodes
    np.testing.assert_allclose(got.poses[nodes], got.chain.poses, atol=1e-12)
    # a scan between two nodes: the node's chain pose, then the odometry's motion since it
    k = int(np.flatnonzero(np.diff(nodes) > 1)[0])
    a, s = int(nodes[k]), int(nodes[k]) + 1
    c, p, q = got.chain.poses[k], odo[a], odo[s]
    dx, dy = q[0] - p[0], q[1] - p[1]
    cs, sn = np.cos(p[2]), np.sin(p[2])
    rel = (cs * dx + sn * dy, -sn * dx + cs * dy, q[2] - p[2])
    want = (
        c[0] + np.cos(c[2]) * rel[0] - np.sin(c[2]) * rel[1],
        c[1] + np.sin(c[2]) * rel[0] + np.cos(c[2]) * rel[1],
    )
    np.testing.assert_allclose(got.poses[s, :2], want, atol=1e-12)
    assert abs(se2.wrap_angle_float(got.poses[s, 2] - c[2] - rel[2])) < 1e-12


def test_a_single_scan_is_its_own_guess():
    truth = loop_path(CORNERS, 0.3)[:1]
    log = simulate_laser_log(laser_world("loop"), truth, seed=0)
    got = chain_guesses(log.scans, log.scans.laser_pose)
    np.testing.assert_array_equal(got.poses, log.scans.laser_pose)
