"""g2o graph files: round trip, hand example, errors."""

from __future__ import annotations

import numpy as np
import pytest

from relation_metric.errors import InputError
from slamrel.backends.least_squares import solve_graph
from slamrel.formats.g2o import read_g2o_graph, write_g2o_graph
from slamrel.formats.isam import read_isam

ISAM = """ODOMETRY 0 1 1.0 0 0 0.01 0 0 0.01 0 0.0001
LANDMARK 1 2 1.0 1.0 0.04 0 0.04
ODOMETRY 1 3 1.0 0 1.5707963 0.01 0.001 0 0.01 0 0.0001
LANDMARK 3 2 1.0 0.0 0.04 0 0.04
"""


def test_round_trip_through_g2o(tmp_path):
    p = tmp_path / "a.txt"
    p.write_text(ISAM)
    g = read_isam(p, noise="covariance").graph
    out = tmp_path / "a.g2o"
    write_g2o_graph(out, g)
    back, pose_ids, lm_ids = read_g2o_graph(out)
    np.testing.assert_array_equal(pose_ids, [0, 1, 2])
    np.testing.assert_array_equal(lm_ids, [3])
    for name in ("poses", "landmarks", "pp_i", "pp_j", "pp_z", "pl_k", "pl_l", "pl_z"):
        np.testing.assert_allclose(getattr(back, name), getattr(g, name), rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(back.pp_info, g.pp_info, rtol=1e-8)
    np.testing.assert_allclose(back.pl_info, g.pl_info, rtol=1e-8)
    assert solve_graph(back).cost[-1] == pytest.approx(solve_graph(g).cost[-1], rel=1e-6)


def test_round_trip_keeps_given_ids(tmp_path):
    p = tmp_path / "a.txt"
    p.write_text(ISAM)
    d = read_isam(p, noise="covariance")
    out = tmp_path / "a.g2o"
    write_g2o_graph(out, d.graph, pose_ids=d.pose_ids, landmark_ids=d.landmark_ids)
    back, pose_ids, lm_ids = read_g2o_graph(out)
    np.testing.assert_array_equal(pose_ids, [0, 1, 3])  # the iSAM file's own ids
    np.testing.assert_array_equal(lm_ids, [2])
    for name in ("pp_i", "pp_j", "pl_k", "pl_l"):
        np.testing.assert_array_equal(getattr(back, name), getattr(d.graph, name))
    with pytest.raises(InputError, match="distinct"):
        write_g2o_graph(out, d.graph, pose_ids=[0, 1, 2], landmark_ids=[2])
    with pytest.raises(InputError, match="need 3 pose ids"):
        write_g2o_graph(out, d.graph, pose_ids=[0, 1], landmark_ids=[2])


def test_hand_written_file(tmp_path):
    p = tmp_path / "b.g2o"
    p.write_text(
        "VERTEX_SE2 10 0 0 0\nVERTEX_SE2 11 1 0 0\nVERTEX_XY 20 1 1\n"
        "EDGE_SE2 10 11 1 0 0 100 0 0 100 0 1000\nEDGE_SE2_XY 11 20 0 1 25 0 25\n"
    )
    g, pids, lids = read_g2o_graph(p)
    np.testing.assert_allclose(g.pp_info[0], np.diag([100, 100, 1000]))
    assert (g.pp_i[0], g.pp_j[0], g.pl_k[0], g.pl_l[0]) == (0, 1, 1, 0)


@pytest.mark.parametrize(
    "text,line,msg",
    [
        ("VERTEX_SE2 0 0 0 0\nEDGE_SE2 0 5 1 0 0 1 0 0 1 0 1\n", 2, "unknown pose vertex 5"),
        ("VERTEX_SE2 0 0 0 0\nVERTEX_SE3:QUAT 1 0 0 0 0 0 0 1\n", 2, "unknown record"),
        ("VERTEX_SE2 0 0 0\nVERTEX_SE2 1 0 0 0\n", 1, "expected 5 fields"),
        (
            "VERTEX_SE2 0 0 0 0\nVERTEX_XY 0 1 1\n",
            2,
            "vertex id 0 is defined twice (first on line 1",
        ),
        ("VERTEX_SE2 0.5 0 0 0\n", 1, "expected an integer id"),
        (
            "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 0 0 0\nEDGE_SE2 0 1 1 0 0 -1 0 0 1 0 1\n",
            3,
            "EDGE_SE2 information matrix: expected a positive semi-definite matrix",
        ),
        (
            "VERTEX_SE2 0 0 0 0\nVERTEX_XY 1 0 0\nEDGE_SE2_XY 0 1 1 0 1 2 1\n",
            3,
            "EDGE_SE2_XY information matrix: expected a positive semi-definite",
        ),
    ],
)
def test_errors(tmp_path, text, line, msg):
    p = tmp_path / "c.g2o"
    p.write_text(text)
    with pytest.raises(InputError) as err:
        read_g2o_graph(p)
    assert f"c.g2o:{line}:" in str(err.value) and msg in str(err.value)


def test_cli_import_and_solve(tmp_path):
    from slamrel.cli import main

    p = tmp_path / "a.txt"
    p.write_text(ISAM)
    g2o = tmp_path / "a.g2o"
    assert main(["import", "isam", str(p), "-o", str(g2o), "-q", "--noise", "covariance"]) == 0
    out = tmp_path / "sol"
    assert main(["solve", str(g2o), "-o", str(out), "-q"]) == 0
    lms = np.genfromtxt(out / "landmarks.csv", delimiter=",", names=True)
    assert float(lms["x"]) == pytest.approx(2.0, abs=1e-6) and float(lms["y"]) == pytest.approx(
        1.0, abs=1e-6
    )
    assert int(lms["landmark"]) == 2  # the iSAM id survives the g2o file
    assert (
        main(["solve", str(p), "-o", str(tmp_path / "sol2"), "-q", "--noise", "covariance"]) == 0
    )  # iSAM text directly
    assert (
        main(
            [
                "solve",
                str(p),
                "-o",
                str(tmp_path / "sol3"),
                "-q",
                "--batch",
                "0",
                "--noise",
                "covariance",
            ]
        )
        == 0
    )
    one = np.genfromtxt(tmp_path / "sol3" / "landmarks.csv", delimiter=",", names=True)
    assert float(one["x"]) == pytest.approx(2.0, abs=1e-6)
    with pytest.raises(SystemExit) as usage:  # an option mistake: exit 2, before any work
        main(["solve", str(p), "-o", str(tmp_path / "sol4"), "--batch", "-1"])
    assert usage.value.code == 2 and not (tmp_path / "sol4").exists()
    assert main(["import", "isam", str(p), "-o", str(p)]) == 3  # never over an input


def test_written_graph_reads_back_bit_for_bit(tmp_path, rng):
    """The g2o writer spells doubles with NUMBER_FORMAT (%.17g): an exact round trip."""
    p = tmp_path / "a.txt"
    p.write_text(ISAM)
    g = read_isam(p, noise="covariance").graph
    poses = g.poses + rng.normal(0, 1e-3, g.poses.shape)  # digits beyond %.9g
    lms = g.landmarks + rng.normal(0, 1e-3, g.landmarks.shape)
    write_g2o_graph(tmp_path / "a.g2o", g, poses=poses, landmarks=lms)
    back, _, _ = read_g2o_graph(tmp_path / "a.g2o")
    np.testing.assert_array_equal(back.poses, poses)
    np.testing.assert_array_equal(back.landmarks, lms)
    for name in ("pp_z", "pp_info", "pl_z", "pl_info"):
        np.testing.assert_array_equal(getattr(back, name), getattr(g, name))


@pytest.mark.parametrize(
    "text,line,msg",
    [
        ("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 0 0\n", 2, "VERTEX_SE2: expected 5 fields (VERTEX_SE2 "),
        ("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 0 x 0\n", 2, "VERTEX_SE2 y: expected a number, got 'x'"),
        ("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 0 0 inf\n", 2, "VERTEX_SE2 theta: expected a finite"),
        ("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1.5 0 0 0\n", 2, "column 'VERTEX_SE2 id': expected an "),
        ("VERTEX_SE2 3 0 0 0\nVERTEX_SE2 3 1 0 0\n", 2, "vertex id 3 is defined twice (first on "),
    ],
)
def test_g2o_pose_records_follow_one_rule_in_every_reader(tmp_path, text, line, msg):
    """The graph reader and the trajectory reader read VERTEX_SE2 through one function."""
    from slamrel.formats.trajectories import read_trajectory

    p = tmp_path / "c.g2o"
    p.write_text(text)
    for read in (read_g2o_graph, read_trajectory):
        with pytest.raises(InputError) as err:
            read(p)
        text = str(err.value)
        assert text.startswith(f"{p}:{line}: ") and msg in text, text


@pytest.mark.parametrize(
    "text,line,msg",
    [
        ("VERTEX_XY 1 0 0\nVERTEX_XY 2 0\n", 2, "VERTEX_XY: expected 4 fields (VERTEX_XY id x y)"),
        ("VERTEX_XY 1 0 0\nVERTEX_XY 2 0 _\n", 2, "VERTEX_XY y: expected a number, got '_'"),
        ("VERTEX_XY 1 0 0\nVERTEX_XY 2.5 0 0\n", 2, "column 'VERTEX_XY id': expected an integer"),
        ("VERTEX_XY 4 0 0\nVERTEX_XY 4 1 1\n", 2, "vertex id 4 is defined twice (first on line 2)"),
    ],
)
def test_g2o_landmark_records_follow_one_rule_in_every_reader(tmp_path, text, line, msg):
    """The graph reader and the landmark-map reader read VERTEX_XY through one function."""
    from slamrel.formats.landmark_maps import read_map

    p = tmp_path / "c.g2o"
    p.write_text("VERTEX_SE2 0 0 0 0\n" + text)
    for read in (read_g2o_graph, read_map):
        with pytest.raises(InputError) as err:
            read(p)
        text = str(err.value)
        assert text.startswith(f"{p}:{line + 1}: ") and msg in text, text


def test_trajectory_and_map_readers_skip_and_count_other_records(tmp_path):
    from slamrel.formats.landmark_maps import read_map
    from slamrel.formats.trajectories import read_trajectory

    p = tmp_path / "c.g2o"
    p.write_text(
        "VERTEX_SE2 1 1 0 0\nVERTEX_SE2 0 0 0 0\nVERTEX_XY 7 2 3\nFIX 0\n"
        "EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nVERTEX_SE3:QUAT 9 0 0 0 0 0 0 1\n"
    )
    loaded = read_trajectory(p)
    np.testing.assert_array_equal(loaded.trajectory.timestamps, [0, 1])  # ids in id order
    np.testing.assert_array_equal(loaded.trajectory.poses[:, 0], [0, 1])
    assert loaded.skipped == {"VERTEX_XY": 1, "FIX": 1, "EDGE_SE2": 1, "VERTEX_SE3:QUAT": 1}
    m = read_map(p)
    np.testing.assert_array_equal(m.ids, [7])
    np.testing.assert_array_equal(m.xy, [[2.0, 3.0]])
    with pytest.raises(InputError, match="unknown record 'FIX'"):
        read_g2o_graph(p)
