"""The guess-independent aligner (issue 37): exact branch and bound, ambiguity along a
corridor, failed relations left out, the window rule, and the corridor worlds' properties."""

from __future__ import annotations

import numpy as np
import pytest

from relation_metric.errors import InputError
from relation_metric.se2 import between
from slamrel.scans.global_align import align_scans_global, pinned
from slamrel.scans.matching import Alignment, align, prepare_scan
from slamrel.scans.proposals import Proposals
from slamrel.scans.search import SearchOptions, _score, branch_and_bound, likelihood_grid
from slamrel.simulation.corridors import corridor_log, corridor_world, grid_walls, true_pairs
from slamrel.simulation.laser import laser_world, simulate_laser_log


def _proposals(pairs, times, kind="given"):
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    n = pairs.shape[0]
    return Proposals(pairs, times[pairs[:, 0]], times[pairs[:, 1]], np.full(n, kind), np.zeros(n))


def test_grid_walls_hand_square():
    free = np.zeros((4, 4), dtype=bool)
    free[1:3, 1:3] = True  # a 0.2 m square room at [0.1, 0.3]²
    walls = grid_walls(free, 0.1)
    assert walls.shape == (4, 4)
    lengths = np.hypot(walls[:, 2] - walls[:, 0], walls[:, 3] - walls[:, 1])
    np.testing.assert_allclose(lengths, 0.2)
    np.testing.assert_allclose(np.sort(np.unique(walls[:, [0, 2]])), [0.1, 0.3])


def test_corridor_world_is_a_pure_function_of_its_seed():
    a, b, c = corridor_world(11), corridor_world(11), corridor_world(12)
    np.testing.assert_array_equal(a.walls, b.walls)
    assert a.walls.shape != c.walls.shape or not np.array_equal(a.walls, c.walls)
    # the corridor graph's nodes lie in free space
    cells = np.floor(a.nodes / 0.1).astype(int)
    assert a.free[cells[:, 0], cells[:, 1]].all()


def test_branch_and_bound_finds_the_brute_force_maximum():
    rng = np.random.default_rng(4)
    ref = rng.uniform(-4, 4, (300, 2))
    cur = ref[::2] + rng.normal(0, 0.01, (150, 2))
    opt = SearchOptions(levels=3, keep=0.5)
    grid = likelihood_grid(ref, ref.min(0) - 2, ref.max(0) + 2, opt)
    centre = np.array([0.13, -0.08, 0.02])
    res = branch_and_bound(grid, cur, centre, 0.4, 0.05, opt)
    # brute force: every cell and rotation of the same window at full resolution
    r = opt.resolution
    rho = float(np.percentile(np.hypot(cur[:, 0], cur[:, 1]), 90))
    dth = r / rho
    nth = int(np.ceil(0.05 / dth))
    thetas = centre[2] + dth * np.arange(-nth, nth + 1)
    c, s = np.cos(thetas)[:, None], np.sin(thetas)[:, None]
    rot = np.stack(
        (c * cur[None, :, 0] - s * cur[None, :, 1], s * cur[None, :, 0] + c * cur[None, :, 1]), -1
    )
    base = np.floor((rot + centre[:2] - grid.lo) / r).astype(np.int64)
    half = int(np.ceil(0.4 / r))
    off = np.arange(-half, half + 1)
    k, u, v = (a.ravel() for a in np.meshgrid(np.arange(thetas.size), off, off, indexing="ij"))
    brute = _score(grid, base, 0, k, u, v)
    assert res.score == pytest.approx(float(brute.max()), abs=1e-6)
    assert abs(res.delta[0]) < 0.06 and abs(res.delta[1]) < 0.06 and abs(res.delta[2]) < 0.01


def test_a_featureless_corridor_is_flagged_ambiguous_along_it():
    walls = laser_world("corridor")
    x = np.arange(0.0, 12.0, 0.2)
    truth = np.column_stack((x, np.zeros_like(x), np.zeros_like(x)))
    log = simulate_laser_log(walls, truth, odometry_sigma=(0.003, 0.001, 0.0005), seed=3)
    s = log.scans
    res, _ = align_scans_global(s, _proposals([[0, 50]], s.timestamps), s.laser_pose)
    assert "ambiguous" in res.flags[0]
    second = res.second[0] - res.delta[0]
    assert abs(second[0]) > 0.25 and abs(second[1]) < 0.1  # the second hypothesis: along x


def _degenerate(delta, cov, weak):
    return Alignment(delta, delta, cov, 0.9, 0.01, 0.01, 300, 10, True, 1e-4, weak, True, "")


def test_pinned_takes_the_weak_direction_from_the_prior_hand_oracle():
    """Along ``w`` the prior's value; across it ICP's; the rotation minimises
    ``(x − x*)ᵀ Σ⁻¹ (x − x*)`` with the translation fixed (found here by a dense scan)."""
    info = np.array([[4.0, 1.0, 0.5], [1.0, 900.0, 30.0], [0.5, 30.0, 400.0]])
    cov = np.linalg.inv(info)
    w = np.array([np.cos(0.3), np.sin(0.3)])
    icp = np.array([1.20, 0.40, 0.05])
    prior = np.array([1.00, 0.10, -0.2])
    got = pinned(_degenerate(icp, cov, w), prior, 0.02)
    across = np.array([-w[1], w[0]])
    assert got.delta[:2] @ w == pytest.approx(prior[:2] @ w, abs=1e-12)
    assert got.delta[:2] @ across == pytest.approx(icp[:2] @ across, abs=1e-12)
    th = np.linspace(-0.5, 0.5, 200001)
    dx = np.column_stack((np.broadcast_to(got.delta[:2] - icp[:2], (th.size, 2)), th - icp[2]))
    best = th[np.argmin(np.einsum("ni,ij,nj->n", dx, info, dx))]
    assert got.delta[2] == pytest.approx(best, abs=1e-5)
    move = got.delta - icp
    np.testing.assert_allclose(
        got.covariance - cov, 0.02**2 * np.outer(move, move) / (move[:2] @ move[:2]), atol=1e-15
    )
    clear = Alignment(icp, icp, cov, 0.9, 0.01, 0.01, 300, 10, True, 0.5, w, False, "")
    assert pinned(clear, prior, 0.02) is clear  # not degenerate: unchanged


def test_a_featureless_corridor_keeps_the_odometry_along_it():
    """1 m pairs in a corridor without features: ICP of the two scans slides along it
    (here by up to 4 cm); the relation keeps the odometry's motion along the corridor
    (composed links, each pinned to the given motion) and ICP's across it."""
    walls = laser_world("corridor")
    x = np.arange(0.0, 12.0, 0.2)
    truth = np.column_stack((x, np.zeros_like(x), np.zeros_like(x)))
    log = simulate_laser_log(walls, truth, odometry_sigma=(0.003, 0.001, 0.0005), seed=3)
    s = log.scans
    i, j = np.array([10, 20, 30]), np.array([15, 25, 35])
    res, _ = align_scans_global(s, _proposals(np.column_stack((i, j)), s.timestamps), s.laser_pose)
    odo = between(s.laser_pose[i], s.laser_pose[j])
    raw = [
        align(prepare_scan(s.points(a)), prepare_scan(s.points(b)), g) for a, b, g in zip(i, j, odo)
    ]
    assert all(r.degenerate for r in raw)
    assert max(abs(r.delta[0] - 1.0) for r in raw) > 0.03  # ICP alone slides
    np.testing.assert_allclose(res.delta[:, 0], odo[:, 0], atol=1e-3)
    np.testing.assert_allclose(res.delta[:, 1:], 0.0, atol=0.005)  # across and θ: ICP's
    assert not any("degenerate" in f for f in res.flags)


@pytest.mark.slow
def test_an_absurd_window_is_refused():
    """Poses that jump 100 km between two scans: the chain keeps the jump (no alignment
    bridges it), and a window growing with that travel would need an absurd grid."""
    _, log = corridor_log(7, length=30.0)
    s = log.scans
    poses = s.laser_pose.copy()
    poses[150:, 0] += 1e5
    with pytest.raises(InputError, match="grid cells"):
        align_scans_global(s, _proposals([[0, 250]], s.timestamps), poses)


def test_a_failed_relation_is_left_out_of_the_relations():
    _, log = corridor_log(7, length=30.0)
    s = log.scans
    ranges = s.ranges.copy()
    ranges[40] = np.inf  # a scan without a single return
    from dataclasses import replace

    s = replace(s, ranges=ranges)
    res, _ = align_scans_global(
        s, _proposals([[30, 40], [40, 50], [30, 50]], s.timestamps), s.laser_pose
    )
    assert res.failed.tolist() == [True, True, False]
    assert len(res.relation_set()) == 1


def _corridor_errors(seed, loops):
    _, log = corridor_log(seed, length=120.0)
    s = log.scans
    pairs, kind = true_pairs(log.truth, s.timestamps, seed=seed, max_loops=loops)
    res, _ = align_scans_global(s, _proposals(pairs, s.timestamps), s.laser_pose)
    e = between(between(log.truth[pairs[:, 0]], log.truth[pairs[:, 1]]), res.delta)
    et, er = np.hypot(e[:, 0], e[:, 1]), np.abs(e[:, 2])
    return et, er, (et > 0.10) | (er > np.radians(2.0)), ~res.flagged, kind == "loop"


@pytest.mark.slow
def test_corridor_world_from_odometry_meets_loose_bounds():
    """Seed 8 (not used to calibrate), a 120 m drive, 15 loop pairs: the unflagged relations
    are right (at most 1 % gross), millimetre-accurate, and at most 10 % are flagged."""
    et, er, gross, ok, loop = _corridor_errors(8, 15)
    assert loop.sum() >= 10
    assert (gross & ok).sum() <= 0.01 * ok.sum()
    assert np.median(et[ok]) < 0.005 and np.degrees(np.median(er[ok])) < 0.1
    assert ok.mean() >= 0.9  # flagged at most 10 % (measured 6 %)


@pytest.mark.slow
def test_corridor_world_loops_become_usable():
    """80 loop pairs of seed 8: today's aligner (``--aligner icp``) leaves 0–4 % of loop pairs
    of such worlds usable; the global one at least 10 % here (measured 19 %)."""
    et, er, gross, ok, loop = _corridor_errors(8, 80)
    assert (gross & ok).sum() <= 0.01 * ok.sum()
    assert (ok & ~gross & loop).sum() >= 0.1 * loop.sum()
