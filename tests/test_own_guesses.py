"""Guesses from the scans' own chain (:mod:`slamrel.scans.own_guesses`).

Oracles: the simulated log's true poses (the chain drifts less than the odometry it starts
from), and the placement rule written out by hand for one scan between two chain nodes.
"""

from __future__ import annotations

import numpy as np
import pytest

from relation_metric import se2
from slamrel.scans.own_guesses import chain_guesses
from slamrel.simulation.laser import laser_world, loop_path, simulate_laser_log
from tests.test_cycles import _flaser_log

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


def _loop_pairs(path) -> np.ndarray:
    from slamrel.formats.relations import read_relations

    rel = read_relations(path)
    return np.abs(rel.second - rel.first) > 20.0  # > 20 s (10 m at 0.5 m/s: loop pairs)


@pytest.mark.slow
def test_cli_chain_guesses_find_the_loop_pairs_the_odometry_misses(tmp_path, capsys):
    """``relations align --loops --chain-guesses`` on the loop world's seed 2 (odometry
    > 1 m off at the closure): the odometry alone (no loop growth) proposes no loop pair, the
    chain the truth's 97, each within 10 cm / 2° of the true relation (keyframes by motion,
    the loop world's 0.6 m)."""
    from slamrel.cli import main

    truth = loop_path(CORNERS, 0.3)
    log = simulate_laser_log(laser_world("loop"), np.vstack((truth, truth[:60])), seed=2)
    path = tmp_path / "loop.clf"
    _flaser_log(path, log.scans)
    plain, chain = tmp_path / "odo.relations", tmp_path / "chain.relations"
    rule = ["--keyframes", "motion", "--loop-growth", "0"]
    assert main(["relations", "align", str(path), "--loops", *rule, "-o", str(plain), "-q"]) == 0
    args = ["relations", "align", str(path), "--loops", "--chain-guesses", *rule, "-o", str(chain)]
    assert main(args) == 0
    assert "pairs and guesses from the scans' chain of" in capsys.readouterr().out
    assert not _loop_pairs(plain).any()
    loops = _loop_pairs(chain)
    assert 90 <= loops.sum() <= 105
    from slamrel.formats.relations import read_relations

    rel = read_relations(chain)
    k1 = np.rint(rel.first / 0.2).astype(int)
    k2 = np.rint(rel.second / 0.2).astype(int)
    err = se2.between(se2.between(log.truth[k1], log.truth[k2]), rel.delta)
    assert np.hypot(err[loops, 0], err[loops, 1]).max() < 0.1
    assert np.abs(err[loops, 2]).max() < np.radians(2)


def test_cli_chain_guesses_on_a_short_log(tmp_path, capsys):
    """The option runs the chain and says so; its relations are as true as those made
    from the odometry (both within 1 cm / 0.2° of the true relations)."""
    from slamrel.cli import main
    from slamrel.formats.relations import read_relations

    corners = np.array([[1.5, 1.5], [10.5, 1.5], [10.5, 4.5], [1.5, 4.5]])
    log = simulate_laser_log(laser_world("room"), loop_path(corners, 0.25)[:40], seed=3)
    path = tmp_path / "room.clf"
    _flaser_log(path, log.scans)
    a, b = tmp_path / "a.relations", tmp_path / "b.relations"
    assert main(["relations", "align", str(path), "-o", str(a), "-q"]) == 0
    assert main(["relations", "align", str(path), "--chain-guesses", "-o", str(b)]) == 0
    assert "pairs and guesses from the scans' chain of" in capsys.readouterr().out
    for f in (a, b):
        rel = read_relations(f)
        assert len(rel.delta) >= 10
        k1, k2 = np.rint(rel.first / 0.2).astype(int), np.rint(rel.second / 0.2).astype(int)
        err = se2.between(se2.between(log.truth[k1], log.truth[k2]), rel.delta)
        assert np.hypot(err[:, 0], err[:, 1]).max() < 0.01
        assert np.abs(err[:, 2]).max() < np.radians(0.2)


@pytest.mark.slow
def test_cli_loop_growth_finds_the_loop_pairs_from_the_odometry(tmp_path, capsys):
    """``relations align --loops --loop-growth 0.02`` from the log's own odometry (no chain
    guesses) on the loop world's seed 2, where the odometry alone proposes no loop pair:
    candidates within 1 m + 2 cm per metre travelled, kept where the aligned motion lies
    within 1 m, are about the truth's 97 loop pairs, each within 10 cm / 2° of the true
    relation and 1 m of each other in truth."""
    from slamrel.cli import main
    from slamrel.formats.relations import read_relations

    truth = loop_path(CORNERS, 0.3)
    log = simulate_laser_log(laser_world("loop"), np.vstack((truth, truth[:60])), seed=2)
    path = tmp_path / "loop.clf"
    _flaser_log(path, log.scans)
    out = tmp_path / "grown.relations"
    args = ["relations", "align", str(path), "--loops", "--loop-growth", "0.02", "-o", str(out)]
    args += ["--keyframes", "motion"]  # the loop world's 0.6 m keyframes (97 loop pairs)
    assert main(args) == 0
    assert "loop candidate(s) aligned beyond reach, left out" in capsys.readouterr().out
    loops = _loop_pairs(out)
    assert 90 <= loops.sum() <= 105, loops.sum()
    rel = read_relations(out)
    k1 = np.rint(rel.first / 0.2).astype(int)
    k2 = np.rint(rel.second / 0.2).astype(int)
    apart = se2.between(log.truth[k1], log.truth[k2])
    err = se2.between(apart, rel.delta)
    assert np.hypot(err[loops, 0], err[loops, 1]).max() < 0.1
    assert np.abs(err[loops, 2]).max() < np.radians(2)
    assert np.hypot(apart[loops, 0], apart[loops, 1]).max() <= 1.05
