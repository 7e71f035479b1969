"""ICP of many pairs at once (issue 37, speed): :func:`align_many` against :func:`align` run
pair by pair (the oracle: the same iteration, written one pair at a time), for every
nearest-anchor lookup and for pairs that converge, stall, fail and have too few returns;
and the laser reader's one-pass parse against its record-by-record loop."""

from __future__ import annotations

import numpy as np
import pytest

from relation_metric.errors import InputError
from relation_metric.se2 import between
from slamrel.formats import laser
from slamrel.formats.laser import read_laser_scans
from slamrel.scans import batch_icp, matching
from slamrel.scans.batch_icp import align_many
from slamrel.scans.matching import IcpOptions, PreparedScan, align, prepare_scan
from slamrel.simulation.laser import laser_world, loop_path, simulate_laser_log

FAST = IcpOptions(
    tolerance=1e-4,
    stall_tolerance=5e-4,
    stall_iterations=2,
    coarse_stride=2,
    shrink_after=2,
    nearest="raster",
    raster_reach=0.3,
)


def _pairs(seed: int = 3):
    walls = laser_world("room")
    corners = np.array([[1.5, 1.5], [10.5, 1.5], [10.5, 4.5], [1.5, 4.5]])
    log = simulate_laser_log(walls, loop_path(corners, 0.25), seed=seed)
    s = log.scans
    k = np.arange(0, s.timestamps.size - 3, 2)
    preps = [prepare_scan(s.points(int(i))) for i in range(s.timestamps.size)]
    refs = [preps[int(i)] for i in k] + [preps[int(i)] for i in k[:10]]
    curs = [preps[int(i) + 1] for i in k] + [preps[int(i) + 3] for i in k[:10]]
    guess = np.concatenate(
        (
            between(s.laser_pose[k], s.laser_pose[k + 1]),
            between(s.laser_pose[k[:10]], s.laser_pose[k[:10] + 3]),
        )
    )
    rng = np.random.default_rng(seed)
    guess = guess + rng.normal(0.0, [0.05, 0.05, 0.03], guess.shape)
    # a guess far off (too few matches), a scan with too few returns, one too few lines
    guess[3] += [3.0, -2.0, 1.0]
    few = PreparedScan(curs[5].points[:10], curs[5].anchors[:10], curs[5].normals[:10])
    curs[5] = few
    refs[6] = few
    return refs, curs, guess


@pytest.mark.parametrize(
    "opt",
    [IcpOptions(), FAST, IcpOptions(nearest="tree"), IcpOptions(coarse_stride=2)],
    ids=["grid", "raster-fast", "tree", "grid-coarse"],
)
def test_align_many_is_align_pair_by_pair(opt, monkeypatch):
    if opt.nearest == "grid" and opt.coarse_stride == 1:
        monkeypatch.setattr(matching, "_GRID_DENSE", 64)  # the sparse tables too
    if opt.coarse_stride > 1:
        monkeypatch.setattr(batch_icp, "_BATCH", 7)  # several batches
    refs, curs, guess = _pairs()
    got = align_many(refs, curs, guess, opt)
    assert len(got) == len(refs)
    failed = 0
    for r, c, g, b in zip(refs, curs, guess, got, strict=True):
        a = align(r, c, g, opt)
        assert a.failed == b.failed and a.iterations == b.iterations
        assert a.converged == b.converged and a.matches == b.matches
        failed += bool(a.failed)
        np.testing.assert_allclose(b.delta, a.delta, rtol=0, atol=1e-12)
        if a.failed:
            continue
        assert a.degenerate == b.degenerate and a.matched_fraction == b.matched_fraction
        np.testing.assert_allclose(b.covariance, a.covariance, rtol=1e-8, atol=1e-18)
        assert b.condition == pytest.approx(a.condition, rel=1e-8, abs=1e-15)
        assert b.residual == pytest.approx(a.residual, rel=1e-10)
        assert abs(float(a.weak_direction @ b.weak_direction)) == pytest.approx(1.0)
    assert 2 <= failed <= 4  # the far guess, the short scan, the reference without lines


def test_align_many_of_nothing():
    assert align_many([], [], np.zeros((0, 3))) == []


def _flaser(ranges, pose, t: float) -> str:
    r = " ".join(ranges)
    x, y, th = pose
    return f"FLASER {len(ranges)} {r} {x} {y} {th} {x} {y} {th} {t} host {t}\n"


@pytest.mark.parametrize("odd", ["", "1e0", "+2.5"])
def test_one_pass_parse_equals_the_record_loop(tmp_path, monkeypatch, odd):
    """The same arrays, bit for bit, from the one-pass parse and from the loop (forced by
    a parse that declines), plain decimals and odd number tokens alike; a bad token in any
    record is still named by its line."""
    rng = np.random.default_rng(1)
    lines = []
    for k in range(40):
        ranges = [f"{v:.3f}" for v in rng.uniform(0.1, 30.0, 181)]
        if odd and k == 7:
            ranges[3] = odd
        pose = (f"{rng.normal():.6f}", f"{rng.normal():.17g}", f"{rng.uniform(-3, 3):.6f}")
        lines.append(_flaser(ranges, pose, 100.0 + 0.1 * k))
    path = tmp_path / "a.clf"
    path.write_text("".join(lines))
    calls = []
    one_pass = laser._flaser_in_one_pass
    monkeypatch.setattr(
        laser, "_flaser_in_one_pass", lambda *a: calls.append(one_pass(*a)) or calls[-1]
    )
    fast = read_laser_scans(path)
    assert len(calls) == 1 and calls[0] is not None  # read in one pass
    monkeypatch.setattr(laser, "_flaser_in_one_pass", lambda *a: None)
    rows = read_laser_scans(path)  # the records split, then their numbers in one pass
    monkeypatch.setattr(laser, "_fast_rows", lambda *a: False)
    slow = read_laser_scans(path)  # record by record
    for name in (
        "ranges",
        "laser_pose",
        "odometry_pose",
        "timestamps",
        "start_angle",
        "angular_resolution",
        "max_range",
        "beams",
        "lines",
    ):
        np.testing.assert_array_equal(getattr(fast, name), getattr(slow, name))
        np.testing.assert_array_equal(getattr(rows, name), getattr(slow, name))
    monkeypatch.undo()
    lines[11] = lines[11].replace("FLASER 181 ", "FLASER 181 x", 1)
    path.write_text("".join(lines))
    with pytest.raises(InputError, match=r"a\.clf:12: FLASER range reading 1: expected a number"):
        read_laser_scans(path)
