"""Issue 38's end to end (:mod:`slamrel.studies.end_to_end`, :mod:`slamrel.simulation.pillars`).

Oracles: the pillar world's drawing (hand-computed centres), hand-made segment crossings, the
laser simulator's own ray casting (an independent line-of-sight rule) and the detector's
stated noise; for the story, the true relations of the simulated drive (the laser relations
must score each estimate within 10 % of them and rank the estimates alike).
"""

from __future__ import annotations

import numpy as np
import pytest

from relation_metric import se2
from slamrel.simulation.laser import LaserSensor, laser_world, ray_cast
from slamrel.simulation.pillars import PILLAR_CLEARANCE, line_of_sight, pillar_log, pillar_world


def test_pillar_centres_are_the_drawn_squares():
    walls, centres = pillar_world()
    assert centres.shape == (20, 2)
    got = {tuple(np.round(c, 6)) for c in centres}
    # a pillar of the loop world (box at 6, 0.3) and one added on the block (10.5, 2.7)
    assert (6.15, 0.45) in got and (10.65, 2.85) in got
    assert walls.shape[0] == laser_world("loop").shape[0] + 4 * 8  # eight 4-sided pillars


def test_line_of_sight_by_hand():
    wall = np.array([[0.0, -1.0, 0.0, 1.0]])
    o = np.array([[-1.0, 0.0], [-1.0, 2.0], [-1.0, 0.5], [-2.0, 0.0]])
    t = np.array([[1.0, 0.0], [1.0, 2.0], [-0.1, 0.5], [-1.0, 0.0]])
    np.testing.assert_array_equal(line_of_sight(o, t, wall), [False, True, True, True])
    # along the wall itself (parallel): never a crossing
    assert line_of_sight(np.array([[0.0, -3.0]]), np.array([[0.0, -2.0]]), wall)[0]


def test_pillar_log_sees_what_the_laser_sees_with_the_stated_noise():
    pl = pillar_log(3)
    b, truth = pl.bundle, pl.laser.truth
    walls, _ = pillar_world()
    k = np.searchsorted(b.odometry.timestamps, b.measurement_times)
    np.testing.assert_array_equal(b.odometry.timestamps[k], b.measurement_times)
    rel = se2.inverse_transform_points(truth[k], pl.landmarks[b.measurement_landmarks])
    r = np.hypot(rel[:, 0], rel[:, 1])
    bearing = np.arctan2(rel[:, 1], rel[:, 0])
    zr = (b.measurements[:, 0] - r) / b.sensor.sigma_range
    zb = se2.wrap_angle(b.measurements[:, 1] - bearing) / b.sensor.sigma_bearing
    assert abs(zr.std() - 1) < 0.1 and abs(zb.std() - 1) < 0.1 and b.measurements.shape[0] > 500
    # independent line of sight: the laser's ray toward the pillar reaches its near face
    for m in range(0, k.size, 17):
        beam = LaserSensor(beams=1, start=float(bearing[m]), resolution=0.0)
        hit = ray_cast(walls, truth[k[m]], beam)[0]
        assert hit >= r[m] - PILLAR_CLEARANCE, m


@pytest.mark.slow
@pytest.mark.parametrize("seed", [3, 4])
def test_laser_relations_score_like_the_truth(seed):
    from slamrel.studies.end_to_end import end_to_end

    r = end_to_end(seed)
    assert r.gross_accepted == 0
    assert abs(r.loop_pairs - r.true_loop_pairs) <= 5
    ratios = {e: round(r.ratio(e), 3) for e in r.scores}
    assert r.within_10_percent, ratios
    assert r.same_ranking
    assert r.ranking("true") == ["recovered", "online", "dead reckoning"]
