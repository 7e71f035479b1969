"""Relation sets: the Freiburg format, generation strategies, exact reproduction."""

from __future__ import annotations

import numpy as np
import pytest

from relation_metric import se2
from relation_metric.errors import InputError
from relation_metric.relations import STRATEGIES, RelationSet, generate_relations
from relation_metric.trajectory import Trajectory
from slamrel.formats.relations import read_relations, write_relations


@pytest.fixture
def loop_traj(rng):
    """Two laps of a 10 m circle, 1 s apart poses, with a little noise."""
    s = np.linspace(0, 4 * np.pi, 400)
    xy = np.column_stack((10 * np.cos(s), 10 * np.sin(s))) + rng.normal(0, 0.01, (400, 2))
    th = s + np.pi / 2
    return Trajectory(np.arange(400.0), np.column_stack((xy, th)))


@pytest.mark.parametrize("strategy", [s for s in STRATEGIES if s != "all-pairs"])
def test_generated_deltas_reproduce_the_reference_exactly(loop_traj, strategy):
    rel = generate_relations(
        loop_traj, strategy, key="index", count=300, radius=1.0, min_separation_time=100.0
    )
    assert len(rel) > 0
    i = rel.first.astype(int)
    j = rel.second.astype(int)
    rebuilt = se2.compose(loop_traj.poses[i], rel.delta)
    np.testing.assert_allclose(rebuilt[:, :2], loop_traj.poses[j, :2], atol=1e-9)
    np.testing.assert_allclose(se2.wrap_angle(rebuilt[:, 2] - loop_traj.poses[j, 2]), 0, atol=1e-12)


def test_strategy_selections(loop_traj):
    c = generate_relations(loop_traj, "consecutive", step=5, key="index")
    assert np.all(c.second - c.first == 5) and len(c) == 395
    d = generate_relations(loop_traj, "distance", distance=2.0, key="index")
    s = loop_traj.path_length()
    gi, gj = d.first.astype(int), d.second.astype(int)
    assert np.all(s[gj] - s[gi] >= 2.0) and np.all(s[gj - 1] - s[gi] < 2.0)
    loops = generate_relations(
        loop_traj, "loops", radius=0.5, min_separation_time=150.0, key="index"
    )
    li, lj = loops.first.astype(int), loops.second.astype(int)
    assert len(loops) > 0
    assert np.all(np.hypot(*(loop_traj.xy[lj] - loop_traj.xy[li]).T) <= 0.5)
    assert np.all(lj - li >= 150)
    g = generate_relations(loop_traj, "global", count=200, min_distance=15.0, seed=3, key="index")
    assert len(g) == 200
    assert np.all(
        np.hypot(*(loop_traj.xy[g.second.astype(int)] - loop_traj.xy[g.first.astype(int)]).T)
        >= 15.0
    )
    pairs = set(zip(g.first.tolist(), g.second.tolist()))
    assert len(pairs) == 200  # no duplicates
    r1 = generate_relations(loop_traj, "random", count=50, seed=7)
    r2 = generate_relations(loop_traj, "random", count=50, seed=7)
    np.testing.assert_array_equal(r1.first, r2.first)  # seeded: same draw
    assert len(generate_relations(Trajectory.from_poses(np.zeros((20, 3))), "all-pairs")) == 190


def test_relations_file_round_trip(tmp_path, rng):
    rel = RelationSet(
        rng.uniform(0, 100, 30), rng.uniform(0, 100, 30), se2.wrap_last(rng.normal(size=(30, 3)))
    )
    path = tmp_path / "r.relations"
    write_relations(path, rel)
    back = read_relations(path)
    np.testing.assert_allclose(back.first, rel.first, atol=1e-6)
    np.testing.assert_allclose(back.delta, rel.delta, atol=1e-9)
    np.testing.assert_array_equal(back.out_of_plane, 0.0)


def test_relations_format_details(tmp_path):
    # comments, double spaces, t2 < t1, out-of-plane parts kept
    text = "# header\n2.0  1.0 0.5 0.1 0.3  0.01 0.02 0.2\n\n1.0 2.0 0.5 0.1 0 0 0 -0.2\n"
    p = tmp_path / "a.relations"
    p.write_text(text)
    r = read_relations(p)
    np.testing.assert_allclose(r.first, [2.0, 1.0])
    np.testing.assert_allclose(r.delta, [[0.5, 0.1, 0.2], [0.5, 0.1, -0.2]])
    np.testing.assert_allclose(r.out_of_plane, [[0.3, 0.01, 0.02], [0, 0, 0]])


@pytest.mark.parametrize(
    "text,line,msg",
    [
        ("1 2 0 0 0 0 0 0\n1 2 0 0 0 0 0\n3 4 0 0 0 0 0 0\n", 2, "expected 8 fields"),
        ("1 2 0 0 0 0 0 0\n1 2 0 0 0 zero 0 0\n", 2, "expected a number, got 'zero'"),
        ("1 2 0 nan 0 0 0 0\n", 1, "finite"),
    ],
)
def test_bad_relations_files(tmp_path, text, line, msg):
    p = tmp_path / "bad.relations"
    p.write_text(text)
    with pytest.raises(InputError) as err:
        read_relations(p)
    assert f"bad.relations:{line}:" in str(err.value) and msg in str(err.value)


def test_empty_relations_file(tmp_path):
    p = tmp_path / "e.relations"
    p.write_text("# nothing\n")
    with pytest.raises(InputError, match="no data"):
        read_relations(p)
