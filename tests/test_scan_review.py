"""The scan review page's data (no browser): the decimated map, the estimate's relations, the
optional second hypotheses. The page itself is driven in test_scan_review_browser.py."""

from __future__ import annotations

import base64

import numpy as np
import pytest

from relation_metric.se2 import between
from slamrel.review.scans import map_cells, scan_review_html, scan_review_payload
from slamrel.scans.proposals import Proposals
from slamrel.scans.relations import align_scans
from slamrel.simulation.laser import LaserSensor, laser_world, simulate_laser_log


@pytest.fixture(scope="module")
def room():
    walls = laser_world("room")
    k = np.arange(12)
    truth = np.column_stack((2.0 + 0.5 * k, 1.5 + 0.2 * k, 0.1 * k))
    sim = simulate_laser_log(walls, truth, sensor=LaserSensor(sigma=0.0), seed=1)
    return walls, sim


def _segment_distance(p, walls):
    """Distance of points ``(M, 2)`` to the nearest segment, by projection (the oracle)."""
    a, b = walls[None, :, :2], walls[None, :, 2:]
    ab = b - a
    t = np.clip(np.sum((p[:, None] - a) * ab, axis=2) / np.sum(ab * ab, axis=2), 0.0, 1.0)
    return np.linalg.norm(p[:, None] - (a + t[..., None] * ab), axis=2).min(axis=1)


def test_map_cells_lie_on_the_walls(room):
    walls, sim = room
    res, cells = map_cells(sim.scans, sim.truth, resolution=0.05)
    assert res == 0.05 and cells.shape[0] > 500
    assert np.unique(cells, axis=0).shape == cells.shape  # each cell once
    # every occupied cell holds a wall point: its centre within half a diagonal of a wall
    centres = (cells + 0.5) * res
    assert _segment_distance(centres, walls).max() <= res * np.sqrt(2) / 2 + 1e-9


def test_map_cells_coarsen_to_the_limit_and_skip_missing_poses(room):
    _, sim = room
    res, cells = map_cells(sim.scans, sim.truth, resolution=0.05, max_cells=300)
    assert cells.shape[0] <= 300 and res in (0.1, 0.2, 0.4, 0.8, 1.6)
    # one doubling less would not have fitted
    assert map_cells(sim.scans, sim.truth, resolution=res / 2, max_cells=10**9)[1].shape[0] > 300
    poses = sim.truth.copy()
    poses[0] = np.nan
    without = map_cells(sim.scans.take(np.arange(1, 12)), sim.truth[1:], resolution=0.05)
    np.testing.assert_array_equal(map_cells(sim.scans, poses, resolution=0.05)[1], without[1])


def test_payload_estimate_second_hypothesis_and_map(room):
    _, sim = room
    pairs = np.array([[0, 2], [3, 5], [6, 9]])
    t = sim.scans.timestamps
    prop = Proposals(pairs, t[pairs[:, 0]], t[pairs[:, 1]], np.full(3, "given"), np.zeros(3))
    odo = sim.scans.laser_pose
    result = align_scans(sim.scans, prop, between(odo[pairs[:, 0]], odo[pairs[:, 1]]))
    second = np.array([[0.1, 0.2, 0.3, 0.9], [np.nan] * 4, [1.0, 0.0, 0.0, 0.5]])
    data = scan_review_payload(sim.scans, result, odo, second=second, max_map_cells=2000)
    rel = data["relations"]
    np.testing.assert_allclose(
        np.reshape(rel["estimate"], (3, 3)), between(odo[pairs[:, 0]], odo[pairs[:, 1]]), atol=1e-6
    )
    assert rel["second"][:3] == [0.1, 0.2, 0.3] and rel["second"][3:6] == [None] * 3
    assert rel["secondRatio"] == [0.9, None, 0.5]
    # the map: base64 uint16 pairs relative to its origin, the cells of map_cells
    m = data["map"]
    packed = np.frombuffer(base64.b64decode(m["cells"]), dtype="<u2").reshape(-1, 2)
    res, cells = map_cells(sim.scans, odo, min_range=0.05, max_cells=2000)
    assert m["resolution"] == res and m["count"] == cells.shape[0] <= 2000
    np.testing.assert_array_equal(packed.astype(np.int64) + m["origin"], cells)
    assert (
        data["format"] == "slamrel-scan-review/2"
        and "second" not in scan_review_payload(sim.scans, result, odo)["relations"]
    )
    assert "review-data" in scan_review_html(data)
    with pytest.raises(ValueError, match=r"\(3, 3\) or \(3, 4\)"):
        scan_review_payload(sim.scans, result, odo, second=np.zeros((2, 3)))
