"""Laser scans from CARMEN logs, point-to-line ICP, correlative matching, on simulated worlds.

The oracle of the simulated tests is the simulator's exact truth: the true laser poses give
the true relation ``between(truth[i], truth[j])`` of every pair.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import require_data

from relation_metric.errors import InputError
from relation_metric.se2 import between, compose
from slamrel.formats.laser import read_laser_scans
from slamrel.scans.correlative import correlative_match
from slamrel.scans.matching import align, prepare_scan
from slamrel.scans.proposals import consecutive_pairs, loop_pairs, pairs_at_times
from slamrel.scans.relations import AlignOptions, QualityLimits, align_scans, guesses_from_poses
from slamrel.simulation.laser import (
    LaserSensor,
    laser_world,
    loop_path,
    ray_cast,
    simulate_laser_log,
)

# --------------------------------------------------------------------------- the reader


def _flaser(ranges: list[float], laser: tuple, odom: tuple, t: float) -> str:
    r = " ".join(f"{v:.2f}" for v in ranges)
    poses = " ".join(map(str, laser + odom))
    return f"FLASER {len(ranges)} {r} {poses} {t} host 0.1\n"


def test_flaser_config_and_offset_as_carmen_guesses_them(tmp_path):
    path = tmp_path / "a.clf"
    ranges = [1.0] * 361
    path.write_text(
        "PARAM robot_front_laser_max 80\n"
        + _flaser(ranges, (1.0, 2.0, 0.5), (0.9, 2.1, 0.4), 10.0)
        + _flaser(ranges, (1.5, 2.0, 0.5), (1.4, 2.1, 0.4), 10.2)
    )
    s = read_laser_scans(path)
    assert len(s) == 2 and s.record == "FLASER" and s.guessed_config
    assert s.skipped == {"PARAM": 1}
    a = s.angles(0)
    assert a[0] == pytest.approx(-math.pi / 2) and a[-1] == pytest.approx(math.pi / 2)
    assert a[1] - a[0] == pytest.approx(math.radians(0.5))
    # offset o = odom⁻¹ ∘ laser by hand: Δ = (0.1, −0.1) rotated by −0.4, Δθ = 0.1
    c, sn = math.cos(0.4), math.sin(0.4)
    expect = [c * 0.1 + sn * -0.1, -sn * 0.1 + c * -0.1, 0.1]
    np.testing.assert_allclose(s.laser_offset[0], expect, atol=1e-12)
    pts = s.points(0)
    np.testing.assert_allclose(np.hypot(pts[:, 0], pts[:, 1]), 1.0)
    np.testing.assert_allclose(s.nearest(np.array([10.09, 10.11])), [0, 1])


def test_robotlaser_and_rawlaser_layouts(tmp_path):
    rl = (
        "ROBOTLASER1 0 -1.0 2.0 0.5 30.0 0.01 0 5 1 2 3 40 5 2 7 8 "
        "1.0 2.0 0.3 1.1 2.0 0.3 0 0 0 0 0 12.5 host 0.2\n"
    )
    path = tmp_path / "b.log"
    path.write_text(rl + "ODOM 1 2 3 0 0 0 12.6 host 0.3\n")
    s = read_laser_scans(path)
    assert s.beams.tolist() == [5] and s.max_range[0] == 30.0
    np.testing.assert_allclose(s.angles(0), [-1.0, -0.5, 0.0, 0.5, 1.0])
    pts = s.points(0)
    assert np.isnan(pts[3]).all() and np.isfinite(pts[[0, 1, 2, 4]]).all()  # 40 m ≥ 30 m
    np.testing.assert_allclose(s.laser_pose[0], [1.0, 2.0, 0.3])
    np.testing.assert_allclose(s.odometry_pose[0], [1.1, 2.0, 0.3])
    raw = tmp_path / "c.log"
    raw.write_text("RAWLASER1 0 -1.0 2.0 0.5 30.0 0.01 0 3 1 2 3 0 5.0 host 0.1\n")
    r = read_laser_scans(raw)
    assert r.timestamps.tolist() == [5.0] and np.isnan(r.laser_pose).all()


def test_bad_laser_lines_are_named(tmp_path):
    ranges = [1.0] * 10
    good = _flaser(ranges, (0, 0, 0), (0, 0, 0), 1.0)
    bad = good.replace("1.00 1.00 1.00", "1.00 x 1.00", 1)
    path = tmp_path / "bad.clf"
    path.write_text(good + bad)
    with pytest.raises(InputError, match=r"bad\.clf:2: FLASER range reading 2: expected a number"):
        read_laser_scans(path)
    path.write_text(good + "FLASER 10 1 2 3\n")
    with pytest.raises(InputError, match=r":2: FLASER record: expected 21 fields, got 5"):
        read_laser_scans(path)
    path.write_text(good + good.replace("FLASER", "RLASER"))
    with pytest.raises(InputError, match=r"FLASER \(1\), RLASER \(1\); choose one"):
        read_laser_scans(path)
    assert len(read_laser_scans(path, record="RLASER")) == 1


def test_mit_csail_log():
    s = read_laser_scans(require_data("freiburg", "mit-csail.clf"))
    assert len(s) == 1988 and set(s.beams.tolist()) == {361}
    np.testing.assert_array_equal(s.laser_offset, 0.0)  # the data README: laser = odometry


# --------------------------------------------------------------------------- matching


def _errors(delta: np.ndarray, truth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    e = between(truth, delta)
    return np.hypot(e[:, 0], e[:, 1]), np.degrees(np.abs(e[:, 2]))


def _assert_targets(et: np.ndarray, er: np.ndarray) -> None:
    assert np.median(et) <= 0.015 and np.median(er) <= 0.2, (np.median(et), np.median(er))
    assert np.percentile(et, 95) <= 0.05 and np.percentile(er, 95) <= 1.0


def _room_log(seed: int = 3):
    walls = laser_world("room")
    corners = np.array([[1.5, 1.5], [10.5, 1.5], [10.5, 4.5], [1.5, 4.5]])
    truth = loop_path(corners, 0.25)
    return simulate_laser_log(walls, truth, seed=seed)


def test_ray_cast_hand_geometry():
    walls = laser_world("corridor")
    sensor = LaserSensor(beams=3, start=-math.pi / 2, resolution=math.pi / 2)
    r = ray_cast(walls, np.array([0.0, 0.5, 0.0]), sensor)
    assert r[0] == pytest.approx(1.5) and r[2] == pytest.approx(0.5)
    assert r[1] == np.inf  # along the corridor: 100 m, beyond nothing... no wall ahead


def test_consecutive_pairs_meet_targets_from_drifting_odometry():
    log = _room_log()
    s = log.scans
    prop = consecutive_pairs(s.laser_pose, s.timestamps, distance=0.4, angle=0.3)
    assert len(prop) > 40
    res = align_scans(s, prop, guesses_from_poses(s.laser_pose, prop))
    et, er = _errors(res.delta, guesses_from_poses(log.truth, prop))
    _assert_targets(et, er)
    assert not res.flagged.any(), res.flags[res.flagged]
    # the covariance is not absurd: the errors are within 5 σ of it for most pairs
    sd = np.sqrt(res.covariance[:, 0, 0] + res.covariance[:, 1, 1])
    assert np.mean(et < 5 * sd + 0.005) > 0.8


@pytest.mark.slow
def test_loop_pairs_meet_targets_with_the_global_initialiser():
    walls = laser_world("loop")
    corners = np.array([[1.5, 1.5], [28.5, 1.5], [28.5, 18.5], [1.5, 18.5]])
    truth = loop_path(corners, 0.3)
    truth = np.vstack((truth, truth[:40]))  # drive on past the start: a loop closure
    log = simulate_laser_log(walls, truth, odometry_sigma=(0.005, 0.002, 0.001), seed=5)
    s = log.scans
    prop = loop_pairs(log.truth, s.timestamps, radius=0.4, min_travel=20.0, distance=0.3, angle=0.3)
    assert len(prop) >= 30
    keep = np.arange(0, len(prop), 3)  # a third of them keeps the test short
    prop = type(prop)(*(getattr(prop, f)[keep] for f in prop.__dataclass_fields__))
    guess = guesses_from_poses(s.laser_pose, prop)
    true = guesses_from_poses(log.truth, prop)
    g_et, _ = _errors(guess, true)
    assert np.median(g_et) > 0.3  # the odometry guess after the loop is poor
    # the user knows the guess may be 1 m off after the loop: corrections up to that are normal
    limits = QualityLimits(max_correction=1.0, max_correction_angle=0.1)
    res = align_scans(s, prop, guess, AlignOptions(global_search="always", limits=limits))
    et, er = _errors(res.delta, true)
    assert np.median(et) <= 0.015 and np.median(er) <= 0.2
    ok = ~res.flagged
    assert ok.sum() >= 0.6 * len(prop)
    _assert_targets(et[ok], er[ok])
    # what is wrong is flagged: here, stretches of bare corridor (degenerate)
    assert res.flagged[(et > 0.05) | (er > 1.0)].all()
    assert all("degenerate" in f or "weak geometry" in f for f in res.flags[et > 0.05])


def test_corridor_pair_is_flagged_degenerate_along_the_corridor():
    walls = laser_world("corridor")
    truth = np.array([[0.0, 0.2, 0.05], [0.5, 0.1, 0.0]])
    log = simulate_laser_log(walls, truth, sensor=LaserSensor(max_range=30.0), seed=1)
    a_pts, b_pts = (prepare_scan(log.scans.points(k)) for k in (0, 1))
    true = between(truth[0], truth[1])
    a = align(a_pts, b_pts, true + [0.05, 0.0, 0.0])
    assert a.degenerate and a.condition < 0.02
    # the weak direction is the corridor's axis seen from scan 0 (heading 0.05 rad)
    axis = np.array([math.cos(-0.05), math.sin(-0.05)])
    assert abs(a.weak_direction @ axis) > 0.99
    # and the constrained parts are right: across the corridor and the rotation
    across = np.array([-axis[1], axis[0]])
    assert abs((a.delta[:2] - true[:2]) @ across) < 0.01 and abs(a.delta[2] - true[2]) < 0.005
    pair = pairs_at_times(log.scans.timestamps, np.array([0.0]), np.array([0.2]), tolerance=0.01)
    res = align_scans(log.scans, pair, true[None])
    assert "degenerate" in res.flags[0]


def test_a_relation_far_from_its_guess_is_flagged():
    log = _room_log(seed=4)
    s = log.scans
    prop = pairs_at_times(s.timestamps, s.timestamps[[10]], s.timestamps[[12]], tolerance=0.01)
    true = guesses_from_poses(log.truth, prop)
    near = align_scans(s, prop, compose(true, np.array([0.03, 0.0, 0.01])))
    far = align_scans(s, prop, compose(true, np.array([0.2, 0.1, 0.0])))
    assert near.flags[0] == "" and np.hypot(*(near.delta[0, :2] - true[0, :2])) < 0.01
    # from 0.22 m off the matcher still finds the truth, but says it moved far
    assert np.hypot(*(far.delta[0, :2] - true[0, :2])) < 0.01
    assert "large correction" in far.flags[0] and far.suspicion[0] > 2.0


def test_correlative_search_recovers_a_poor_guess():
    log = _room_log(seed=11)
    s = log.scans
    i, j = 10, 14
    ref, cur = (prepare_scan(s.points(k)).points for k in (i, j))
    true = between(log.truth[i], log.truth[j])
    guess = compose(true, np.array([0.8, -0.6, 0.25]))
    m = correlative_match(ref, cur, guess)
    assert m.score > m.guess_score
    assert np.hypot(*(m.delta[:2] - true[:2])) < 0.08 and abs(m.delta[2] - true[2]) < 0.02
    # ICP from the guess alone lands in a wrong basin; from the search it is right
    a = align(prepare_scan(s.points(i)), prepare_scan(s.points(j)), m.delta)
    assert np.hypot(*(a.delta[:2] - true[:2])) < 0.02


def test_pairs_at_times_refuses_times_without_scans():
    t = np.array([0.0, 0.2, 0.4])
    p = pairs_at_times(t, np.array([0.0, 0.41]), np.array([0.2, 0.2]), tolerance=0.02)
    assert p.pairs.tolist() == [[0, 1], [2, 1]]
    with pytest.raises(InputError, match="1 relation\\(s\\) name times with no scan within 0.02 s"):
        pairs_at_times(t, np.array([0.0, 0.5]), np.array([0.2, 0.2]), tolerance=0.02)


def test_coarse_phase_reaches_the_truth_in_fewer_full_steps():
    """``coarse_stride``: converge on every second return, then polish with all of them; the
    oracle is the simulator's truth, as for the one-phase ICP, from the same guesses."""
    from slamrel.scans.matching import IcpOptions

    log = _room_log()
    s = log.scans
    prop = consecutive_pairs(s.laser_pose, s.timestamps, distance=0.4, angle=0.3)
    truth = guesses_from_poses(log.truth, prop)
    guess = guesses_from_poses(s.laser_pose, prop)
    coarse = IcpOptions(coarse_stride=2, polish_iterations=2)
    got, one = [], []
    for (i, j), g in zip(prop.pairs.tolist(), guess, strict=True):
        a, b = prepare_scan(s.points(i)), prepare_scan(s.points(j))
        c = align(a, b, g, coarse)
        assert not c.failed and c.converged
        got.append(c.delta)
        one.append(align(a, b, g).delta)
    et, er = _errors(np.array(got), truth)
    _assert_targets(et, er)
    et1, _ = _errors(np.array(one), truth)
    assert np.median(et) <= np.median(et1) + 0.002  # within 2 mm of the one-phase ICP


@pytest.mark.parametrize("dense", [True, False])
def test_grid_lookup_is_the_exact_nearest(monkeypatch, dense):
    """``NearestGrid`` against scipy's cKDTree and brute force: the nearest anchor strictly
    within the gate (the same distance, an anchor at that distance), none beyond it, at
    every gate ICP uses, for points near walls, between them and far from every anchor; also
    with only the reached cells kept (a wide scan), no anchors, and a NaN query."""
    from scipy.spatial import cKDTree

    from slamrel.scans import matching
    from slamrel.scans.matching import NearestGrid

    if not dense:
        monkeypatch.setattr(matching, "_GRID_DENSE", 16)
    log = _room_log()
    s = log.scans
    rng = np.random.default_rng(11)
    for i, j in ((0, 3), (2, 9)):
        ref = prepare_scan(s.points(i))
        cur = prepare_scan(s.points(j)).points
        grid, tree = NearestGrid(ref.anchors), cKDTree(ref.anchors)
        for gate, spread in ((0.05, 0.01), (0.06, 0.05), (0.3, 0.2), (0.5, 0.3), (0.5, 2.0)):
            q = cur + rng.normal(0.0, spread, cur.shape)
            dist, k = grid.query(q, gate)
            d_t, k_t = tree.query(q, distance_upper_bound=gate)
            np.testing.assert_array_equal(dist, d_t)
            found = np.isfinite(dist)
            assert np.all(k[~found] == ref.anchors.shape[0])
            np.testing.assert_array_equal(ref.anchors[k[found]], ref.anchors[k_t[found]])
            d_all = np.hypot(*(q[:, None, :] - ref.anchors[None, :, :]).transpose(2, 0, 1))
            best = d_all.min(axis=1)
            assert np.array_equal(found, best < gate)
            assert found.any() and not found.all()
    none = NearestGrid(np.zeros((0, 2))).query(np.ones((3, 2)), 0.5)
    assert np.all(np.isinf(none[0])) and np.all(none[1] == 0)
    with np.errstate(invalid="ignore"):
        d_nan, k_nan = grid.query(np.array([[np.nan, 0.0], [0.0, 0.0]]), 0.5)
    assert np.isinf(d_nan[0]) and k_nan[0] == ref.anchors.shape[0]


def test_raster_lookup_finds_anchors_near_the_nearest():
    """``NearestRaster`` against brute force (every anchor's distance): the same points find an
    anchor within the gate, and the one found is at most a raster cell farther than the
    nearest."""
    from slamrel.scans.matching import NearestRaster

    log = _room_log()
    s = log.scans
    ref = prepare_scan(s.points(0))
    cur = prepare_scan(s.points(3)).points
    rng = np.random.default_rng(5)
    for gate in (0.05, 0.1, 0.3):
        q = cur + rng.normal(0.0, 0.02, cur.shape)
        d_all = np.hypot(*(q[:, None, :] - ref.anchors[None, :, :]).transpose(2, 0, 1))
        best = d_all.min(axis=1)
        dist, k = NearestRaster(ref.anchors, 0.1, 0.3).query(q, gate)
        found = np.isfinite(dist)
        assert np.all(d_all[found, k[found]] == pytest.approx(dist[found]))
        assert np.all(k[~found] == ref.anchors.shape[0])
        assert np.all(dist[found] <= best[found] + 0.1 + 1e-12)
        # nearly every point with an anchor within the gate finds one
        assert found.sum() >= 0.95 * (best <= gate).sum()
