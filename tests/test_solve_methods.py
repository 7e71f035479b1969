"""``solve --method toro`` and ``solve --pose-only m1|m2`` end to end through the CLI."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from relation_metric import se2
from slamrel.backends.pose_only import LandmarkLog, full_graph, pose_only_least_squares
from slamrel.backends.toro_optimiser import graph_cost, toro_optimize
from slamrel.cli import main
from slamrel.formats.g2o import read_g2o_graph, write_g2o_graph
from slamrel.simulation.worlds import make_world
from tests.test_estimation_toro import seeded_graph


def trajectory(path: Path) -> np.ndarray:
    return np.loadtxt(path / "trajectory.txt")[:, 1:]


def test_solve_toro_on_a_pose_graph(tmp_path, rng, capsys):
    write_g2o_graph(tmp_path / "ring.g2o", seeded_graph(rng))
    g, _, _ = read_g2o_graph(tmp_path / "ring.g2o")
    argv = ["solve", str(tmp_path / "ring.g2o"), "-o", str(tmp_path / "out"), "-q"]
    assert main([*argv, "--method", "toro", "--toro-iterations", "40"]) == 0
    got = trajectory(tmp_path / "out")
    want = toro_optimize(g, iterations=40)
    np.testing.assert_allclose(se2.minus(got, np.asarray(want.poses)), 0.0, atol=1e-9)
    assert graph_cost(got, g) < 0.2 * graph_cost(np.asarray(g.poses), g)
    # least squares reaches a lower cost than 40 TORO passes (the optimum: an oracle)
    assert main([*argv[:3], str(tmp_path / "lm"), "-q"]) == 0
    assert graph_cost(trajectory(tmp_path / "lm"), g) <= graph_cost(got, g)


@pytest.mark.slow
def test_solve_pose_only_m2_on_a_landmark_graph_matches_the_study(tmp_path, capsys):
    w = make_world("hu-simple1", noise="a", seed=3)
    log = LandmarkLog.from_world(w)
    g, ids = full_graph(log)
    write_g2o_graph(tmp_path / "w.g2o", g, landmark_ids=1000 + ids)
    out = tmp_path / "po"
    assert main(["solve", str(tmp_path / "w.g2o"), "-o", str(out), "--pose-only", "m2",
                 "--batch", "0"]) == 0  # fmt: skip
    said = capsys.readouterr().out
    ref = pose_only_least_squares(log, method=2, start="align")
    assert f"pose-only M2: {ref.pairs.shape[0]} pair constraints" in said
    # the graph read back from the file gives the study's pose-only solution from the log
    np.testing.assert_allclose(se2.minus(trajectory(out), np.asarray(ref.solution.poses)), 0,
                               atol=1e-6)  # fmt: skip
    # TORO on the same pose-only graph: written, and no better than least squares
    assert main(["solve", str(tmp_path / "w.g2o"), "-o", str(tmp_path / "t"), "-q",
                 "--pose-only", "m2", "--method", "toro"]) == 0  # fmt: skip
    assert graph_cost(trajectory(tmp_path / "t"), ref.graph) >= graph_cost(
        np.asarray(ref.solution.poses), ref.graph
    ) * (1 - 1e-9)


@pytest.mark.parametrize(
    ("extra", "said"),
    [
        (["--method", "toro"], "TORO optimises pose graphs; this graph has"),
        (["--pose-only", "m1"], None),
    ],
)
def test_solve_refusals(tmp_path, capsys, rng, extra, said):
    w = make_world("hu-simple1", noise="a", seed=1)
    g, _ = full_graph(LandmarkLog.from_world(w))
    write_g2o_graph(tmp_path / "w.g2o", g)
    write_g2o_graph(tmp_path / "ring.g2o", seeded_graph(rng))
    if said is not None:
        assert main(["solve", str(tmp_path / "w.g2o"), "-o", str(tmp_path / "o"), *extra]) == 3
        assert said in capsys.readouterr().err
        assert not (tmp_path / "o").exists()
    ring = str(tmp_path / "ring.g2o")
    assert main(["solve", ring, "-o", str(tmp_path / "p"), "--pose-only", "m2"]) == 3
    assert "this graph has none (a pose graph: drop --pose-only)" in capsys.readouterr().err


def test_a_landmark_graph_as_a_log_keeps_every_factor():
    from relation_metric.errors import InputError
    from slamrel.backends.graph import PoseGraph
    from slamrel.backends.pose_only import pose_only_from_landmark_graph

    w = make_world("hu-simple1", noise="a", seed=2)
    log = LandmarkLog.from_world(w)
    g, _ = full_graph(log)
    # a loop closure and a repeated step beside the odometry: kept, counted, unchanged
    extra_i, extra_j = np.array([0, 5]), np.array([40, 6])
    z = se2.between(np.asarray(w.truth.poses)[extra_i], np.asarray(w.truth.poses)[extra_j])
    info = np.broadcast_to(np.diag([100.0, 100.0, 400.0]), (2, 3, 3))
    # the loop closure first, the repeated step last: the first factor k -> k+1 is odometry
    e = g.pp_i.size
    g2 = PoseGraph(g.poses, g.landmarks, np.concatenate((extra_i[:1], g.pp_i, extra_i[1:])),
                   np.concatenate((extra_j[:1], g.pp_j, extra_j[1:])),
                   np.concatenate((z[:1], g.pp_z, z[1:])), np.concatenate((info[:1], g.pp_info,
                   info[1:])), g.pl_k, g.pl_l, g.pl_z, g.pl_info)  # fmt: skip
    back, other = LandmarkLog.from_graph(g2)
    np.testing.assert_array_equal(other, [0, e + 1])
    np.testing.assert_allclose(back.odometry.poses, log.odometry.poses, atol=1e-9)
    np.testing.assert_array_equal(np.sort(back.pose), np.sort(log.pose))
    po = pose_only_from_landmark_graph(g2, method=1)
    assert po.kept == 2
    assert po.graph.pp_i.size == po.constraints.pairs.shape[0] + (g.n_poses - 1) + 2
    np.testing.assert_array_equal(po.graph.pp_z[-2:], z)
    gap = PoseGraph(g.poses, g.landmarks, g.pp_i[g.pp_i != 7], g.pp_j[g.pp_i != 7],
                    g.pp_z[g.pp_i != 7], g.pp_info[g.pp_i != 7], g.pl_k, g.pl_l, g.pl_z,
                    g.pl_info)  # fmt: skip
    with pytest.raises(InputError, match="no pose-pose factor from pose 7 to pose 8"):
        LandmarkLog.from_graph(gap)


def test_solve_reads_toro_graph_files(tmp_path, rng):
    from slamrel.formats.toro import write_toro_graph

    g = seeded_graph(rng)
    write_toro_graph(tmp_path / "ring.graph", g, pose_ids=np.arange(100, 130))
    write_g2o_graph(tmp_path / "ring.g2o", g, pose_ids=np.arange(100, 130))
    for name in ("ring.graph", "ring.g2o"):
        argv = ["solve", str(tmp_path / name), "-o", str(tmp_path / name[-4:]), "-q"]
        assert main([*argv, "--method", "toro", "--toro-iterations", "5"]) == 0
    # the same graph through both readers gives the same TORO result
    np.testing.assert_allclose(trajectory(tmp_path / "raph"), trajectory(tmp_path / ".g2o"),
                               atol=1e-12)  # fmt: skip
    assert "VERTEX_SE2 100 " in (tmp_path / "raph" / "solved.g2o").read_text()
