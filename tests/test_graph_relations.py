"""``slamrel relations from-graph``: Cartographer's autogenerate_ground_truth on g2o/TORO.

The oracle is a graph with a known optimum: the vertices are the true poses of a simulated
drive (three laps of the laser "loop" world's corridor), the edges the true relations with
sub-millimetre noise, and a planted set of loop closures is perturbed past the thresholds:
exactly those must be dropped as outliers, the rest kept, and short ones dropped by travel
(lap-to-lap travel computed by hand from the path's length).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from relation_metric import se2
from slamrel.backends.graph import PoseGraph
from slamrel.backends.graph_relations import graph_relations
from slamrel.cli import main
from slamrel.formats.g2o import write_g2o_graph
from slamrel.formats.toro import write_toro_graph
from slamrel.simulation.laser import loop_path

CORNERS = np.array([[1.5, 1.5], [28.5, 1.5], [28.5, 18.5], [1.5, 18.5]])
LAP = 2 * (27.0 + 17.0)  # m travelled per lap (turns on the spot add none)


def _graph(seed: int = 0):
    """Three laps; sequential edges, and loop closures every 10th pose of laps 2 and 3 to the
    same pose of lap 1 (travel 88 m and 176 m) and of lap 3 to lap 2 (88 m). 12 of them are
    perturbed past the thresholds (6 by 0.2–0.5 m, 6 by 0.03–0.1 rad)."""
    rng = np.random.default_rng(seed)
    lap = loop_path(CORNERS, 0.5)
    x = np.concatenate([lap, lap, lap])
    n, m = x.shape[0], lap.shape[0]
    k = np.arange(0, m, 10)
    i = np.concatenate((np.arange(n - 1), k, k, k + m))
    j = np.concatenate((np.arange(1, n), k + m, k + 2 * m, k + 2 * m))
    z = se2.compose(se2.between(x[i], x[j]), rng.normal(0, 1, (i.size, 3)) * [3e-4, 3e-4, 1e-4])
    loops = np.flatnonzero(np.abs(i - j) != 1)
    bad = rng.choice(loops, 12, replace=False)
    err = np.zeros((12, 3))
    a = rng.uniform(0, 2 * np.pi, 6)
    r = rng.uniform(0.2, 0.5, 6)
    err[:6, 0], err[:6, 1] = r * np.cos(a), r * np.sin(a)
    err[6:, 2] = rng.choice([-1, 1], 6) * rng.uniform(0.03, 0.1, 6)
    z[bad] = se2.compose(z[bad], err)
    info = np.broadcast_to(np.diag([1e4, 1e4, 1e5]), (i.size, 3, 3))
    g = PoseGraph(poses=x, landmarks=np.empty((0, 2)), pp_i=i, pp_j=j, pp_z=z, pp_info=info)
    return g, bad, m


def test_perturbed_loop_closures_are_dropped_the_others_kept():
    g, bad, m = _graph()
    got = graph_relations(g, min_travel=50.0)
    assert got.sequential == g.n_poses - 1
    outlier = np.isin(got.edge, bad)
    assert (got.reason[outlier] == "outlier").all()
    assert (got.reason[~outlier] == "").all()
    # travel: one lap or two, as the path's length says
    laps = np.abs(got.second - got.first) // m
    np.testing.assert_allclose(got.travel, laps * LAP, rtol=1e-9)
    # Cartographer's defaults: 100 m drops the one-lap closures by travel, before any outlier test
    dflt = graph_relations(g)
    assert ((dflt.reason == "short travel") == (laps == 1)).all()
    assert ((dflt.reason == "outlier") == (outlier & (laps == 2))).all()


def _evaluate_json(tmp_path, rel, est, name):
    out = tmp_path / f"{name}.json"
    assert main(["evaluate", str(rel), str(est), "--json", str(out), "-q"]) == 0
    return json.loads(out.read_text())


def test_command_writes_relations_evaluate_scores(tmp_path, capsys):
    g, bad, m = _graph(1)
    path = tmp_path / "opt.g2o"
    write_g2o_graph(path, g, pose_ids=np.arange(g.n_poses) + 100)
    out = tmp_path / "gt.relations"
    assert main(["relations", "from-graph", str(path), "-o", str(out), "--min-travel", "50"]) == 0
    text = capsys.readouterr().out
    loops = np.flatnonzero(np.abs(g.pp_i - g.pp_j) != 1)
    assert f"{loops.size - 12} relations from {loops.size} loop closures" in text
    assert "dropped 0 with less than 50 m travelled, 12 outliers" in text
    rows = np.loadtxt(out)
    keep = np.setdiff1d(loops, bad)
    # times are the vertex ids; the motions the constraints themselves
    np.testing.assert_array_equal(rows[:, 0], g.pp_i[keep] + 100)
    np.testing.assert_array_equal(rows[:, 1], g.pp_j[keep] + 100)
    np.testing.assert_allclose(rows[:, [2, 3, 7]], g.pp_z[keep], atol=1e-15)
    # the optimum itself, as a g2o trajectory (vertex id = time), scores the constraints' noise
    res = _evaluate_json(tmp_path, out, path, "opt")
    assert res["relations"] == keep.size
    e = se2.between(g.pp_z[keep], se2.between(g.poses[g.pp_i[keep]], g.poses[g.pp_j[keep]]))
    np.testing.assert_allclose(
        res["translation"]["abs"]["mean"], np.hypot(e[:, 0], e[:, 1]).mean(), rtol=1e-9
    )
    # TORO: the same relations
    toro = tmp_path / "opt.graph"
    write_toro_graph(toro, g, pose_ids=np.arange(g.n_poses) + 100)
    out2 = tmp_path / "toro.relations"
    assert main(["relations", "from-graph", str(toro), "-o", str(out2), "--min-travel", "50"]) == 0
    np.testing.assert_array_equal(np.loadtxt(out2), rows)


def test_times_file_maps_vertices_to_stamps(tmp_path):
    g, _, _ = _graph(2)
    path = tmp_path / "opt.g2o"
    write_g2o_graph(path, g)
    stamps = 1000.0 + 0.25 * np.arange(g.n_poses)
    times = tmp_path / "times.txt"
    np.savetxt(times, stamps, fmt="%.6f")
    out = tmp_path / "t.relations"
    args = ["relations", "from-graph", str(path), "-o", str(out), "--times", str(times), "-q"]
    assert main(args) == 0
    by_id = tmp_path / "id.relations"
    assert main(["relations", "from-graph", str(path), "-o", str(by_id), "-q"]) == 0
    a, b = np.loadtxt(out), np.loadtxt(by_id)
    np.testing.assert_allclose(a[:, :2], 1000.0 + 0.25 * b[:, :2])
    np.testing.assert_array_equal(a[:, 2:], b[:, 2:])
    # an estimate with those stamps scores the same as the graph by vertex id
    traj = tmp_path / "est.txt"
    np.savetxt(traj, np.column_stack((stamps, g.poses)), fmt="%.17g")
    r1, r2 = _evaluate_json(tmp_path, out, traj, "t"), _evaluate_json(tmp_path, by_id, path, "i")
    assert r1["relations"] == r2["relations"] > 0
    np.testing.assert_allclose(r1["translation"]["abs"]["mean"], r2["translation"]["abs"]["mean"])


def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.mark.parametrize(
    ("text", "says"),
    [
        (
            "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nVERTEX_SE2 2 2 0 0\n"
            "EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nEDGE_SE2 1 2 1 0 0 1 0 0 1 0 1\n",
            "no loop closures",
        ),
        ("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 7 1 0 0 1 0 0 1 0 1\n", "vertex 7"),
        ("VERTEX_SE2 0.5 0 0 0\n", "integer"),
        ("ODOMETRY 0 1 1 0 0 1 0 0 1 0 1\n", "iSAM text holds no vertex poses"),
        ("VERTEX2 0 0 0 0\nEDGE2 0 3 1 0 0 1 0 1 1 0 0\n", "unknown vertex 3"),
    ],
)
def test_bad_graphs_exit_3(tmp_path, capsys, text, says):
    path = _write(tmp_path, "bad.g2o", text)
    assert main(["relations", "from-graph", str(path), "-o", str(tmp_path / "o")]) == 3
    err = capsys.readouterr().err
    assert says in err and "Traceback" not in err
    assert not (tmp_path / "o").exists()


def test_option_mistakes_exit_2_and_times_count_exits_3(tmp_path, capsys):
    g, _, _ = _graph(3)
    path = tmp_path / "opt.g2o"
    write_g2o_graph(path, g)
    out = str(tmp_path / "o")
    for opt in (["--max-error-xy", "0"], ["--max-error-theta", "-1"], ["--min-travel", "nan"]):
        assert main(["relations", "from-graph", str(path), "-o", out, *opt]) == 2
    times = _write(tmp_path, "times.txt", "1\n2\n3\n")
    assert main(["relations", "from-graph", str(path), "-o", out, "--times", str(times)]) == 3
    assert f"3 timestamps for the graph's {g.n_poses} pose vertices" in capsys.readouterr().err


def test_landmark_edges_are_counted_not_used(tmp_path, capsys):
    g, bad, _ = _graph(4)
    with_lm = PoseGraph(
        poses=g.poses,
        landmarks=np.array([[5.0, 5.0]]),
        pp_i=g.pp_i,
        pp_j=g.pp_j,
        pp_z=g.pp_z,
        pp_info=g.pp_info,
        pl_k=np.array([0, 3]),
        pl_l=np.array([0, 0]),
        pl_z=se2.inverse_transform_points(g.poses[[0, 3]], np.array([[5.0, 5.0]] * 2)),
        pl_info=np.broadcast_to(np.eye(2), (2, 2, 2)),
    )
    a, b = tmp_path / "lm.g2o", tmp_path / "plain.g2o"
    write_g2o_graph(a, with_lm)
    write_g2o_graph(b, g)
    ra, rb = tmp_path / "a.relations", tmp_path / "b.relations"
    assert main(["relations", "from-graph", str(a), "-o", str(ra), "--min-travel", "50"]) == 0
    assert "2 pose-landmark edges not used" in capsys.readouterr().out
    assert main(["relations", "from-graph", str(b), "-o", str(rb), "--min-travel", "50"]) == 0
    np.testing.assert_array_equal(np.loadtxt(ra), np.loadtxt(rb))
