"""``slamrel traj``: bag topics, trajectory information and conversion.

Oracles: a hand-computed info of a 3-pose file, the values written into a bag with rosbags,
and round trips through the readers (TUM bit for bit; KITTI to rounding of the matrix).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_bags import TYPES, N, _truth, _write

from relation_metric import se3
from slamrel.cli import main
from slamrel.formats.trajectories import read_trajectory


def test_info_by_hand(tmp_path, capsys):
    f = tmp_path / "a.txt"
    # t x y theta: steps of 5 m (3-4-5) then none; times 0, 1, 3
    f.write_text("0 0 0 0\n1 3 4 0.5\n3 3 4 1.0\n")
    j = tmp_path / "info.json"
    assert main(["traj", "info", str(f), "--json", str(j)]) == 0
    (e,) = json.loads(j.read_text())["trajectories"]
    assert (e["poses"], e["dimension"], e["format"]) == (3, "2-D", "plain")
    assert e["duration_s"] == 3.0 and e["length_m"] == 5.0
    assert e["rate_hz"] == pytest.approx(2 / 3)
    assert e["median_step_s"] == 1.5 and e["max_gap_s"] == 2.0
    assert e["extent_m"] == [3.0, 4.0]
    out = capsys.readouterr().out
    assert "3 poses" in out and "length       5 m" in out


def test_topics_and_bag_info(tmp_path, rng, capsys):
    truth = _truth(rng)
    bag = _write(tmp_path / "r.bag", "ros1", truth)
    j = tmp_path / "topics.json"
    assert main(["traj", "topics", str(bag), "--json", str(j)]) == 0
    rows = {r["topic"]: r for r in json.loads(j.read_text())["topics"]}
    assert {k: (r["type"], r["messages"]) for k, r in rows.items()} == {
        f"/{k}": (v, 1 if k == "text" else N) for k, v in TYPES.items()
    }
    assert not rows["/text"]["trajectory"] and rows["/odom"]["trajectory"]
    j2 = tmp_path / "info.json"
    assert main(["traj", "info", f"{bag}:/odom", "--json", str(j2)]) == 0
    (e,) = json.loads(j2.read_text())["trajectories"]
    stamps = truth["sec"] + truth["nsec"] * 1e-9
    assert e["poses"] == N and e["start_s"] == stamps[0] and e["end_s"] == stamps[-1]
    steps = np.linalg.norm(np.diff(truth["xyz"], axis=0), axis=1)
    assert e["length_m"] == pytest.approx(steps.sum(), rel=1e-12)
    assert (e["frame_id"], e["child_frame_id"], e["covariance"]) == ("map", "base_link", True)
    assert (
        "nav_msgs/msg/Odometry; frame map -> base_link, with covariance" in capsys.readouterr().out
    )
    # not a bag; a missing topic: input errors, exit 3
    assert main(["traj", "topics", str(tmp_path / "info.json")]) == 3
    assert main(["traj", "info", f"{bag}:/missing"]) == 3


def test_convert_round_trips(tmp_path, rng, capsys):
    truth = _truth(rng)
    bag = _write(tmp_path / "c.bag", "ros1", truth)
    src = read_trajectory(f"{bag}:/pose").trajectory
    tum = tmp_path / "out.tum"
    assert main(["traj", "convert", f"{bag}:/pose", "-o", str(tum), "-q"]) == 0
    back = read_trajectory(tum).trajectory
    np.testing.assert_array_equal(back.timestamps, src.timestamps)
    np.testing.assert_array_equal(back.poses, src.poses)  # 17 digits: bit for bit
    kitti, times = tmp_path / "out.kitti", tmp_path / "times.txt"
    args = ["traj", "convert", str(tum), "-o", str(kitti), "--output-times", str(times), "-q"]
    assert main(args) == 0
    k = read_trajectory(kitti, format="kitti", times=times).trajectory
    np.testing.assert_array_equal(k.timestamps, src.timestamps)
    np.testing.assert_allclose(se3.to_matrix(k.poses), se3.to_matrix(src.poses), atol=1e-12)
    # planar: 3-D to csv needs --planar; then CSV reads back as the projection
    csv = tmp_path / "out.csv"
    assert main(["traj", "convert", str(tum), "-o", str(csv), "-q"]) == 2
    capsys.readouterr()
    assert main(["traj", "convert", str(tum), "-o", str(csv), "--planar", "-q"]) == 0
    assert "discarding its out-of-plane motion" in capsys.readouterr().err  # said, not silent
    c = read_trajectory(csv).trajectory
    yaw = se3.euler_zyx(src.poses[:, 3:])[:, 2]
    np.testing.assert_allclose(c.poses[:, 2], yaw, atol=1e-12)
    np.testing.assert_array_equal(c.poses[:, :2], src.poses[:, :2])
    # no format from the name, times for a non-KITTI output: option errors (exit 2)
    assert main(["traj", "convert", str(tum), "-o", str(tmp_path / "x.txt")]) == 2
    assert main(["traj", "convert", str(tum), "-o", str(tum) + "2", "--to", "tum",
                 "--output-times", str(times)]) == 2  # fmt: skip
    # the output is never the input bag
    assert main(["traj", "convert", f"{bag}:/pose", "-o", str(bag), "--to", "tum"]) != 0
    assert bag.stat().st_size > 0 and read_trajectory(f"{bag}:/pose").trajectory.poses.shape == (
        N,
        7,
    )


def test_info_reads_what_evaluate_reads_and_says_the_repeats(tmp_path, capsys):
    """A file with two different poses at one time (fr2_desk's ground truth has one) is
    described, not refused: its repeats counted by line, what evaluate and ape/rpe do said."""
    f = tmp_path / "rep.tum"
    f.write_text("0 0 0 0 0 0 0 1\n1 1 0 0 0 0 0 1\n1 1 1 0 0 0 0 1\n2 2 0 0 0 0 0 1\n")
    j = tmp_path / "info.json"
    assert main(["traj", "info", str(f), "--json", str(j)]) == 0
    captured = capsys.readouterr()
    (e,) = json.loads(j.read_text())["trajectories"]
    assert e["poses"] == 4 and e["repeated_times"] == {"count": 1, "differing": 1, "first_line": 3}
    assert e["length_m"] == pytest.approx(2 + 2**0.5)  # 1 + 1 + √2: every row kept
    assert "1 with a different pose (first at line 3)" in captured.out
    assert "--duplicate_stamps keep" in captured.out and captured.err == ""


def test_info_of_kitti_without_times_invents_none(tmp_path, capsys):
    f = tmp_path / "p.kitti"
    f.write_text("".join(f"1 0 0 {k} 0 1 0 0 0 0 1 0\n" for k in range(5)))
    j = tmp_path / "info.json"
    assert main(["traj", "info", str(f), "--json", str(j)]) == 0
    out = capsys.readouterr().out
    (e,) = json.loads(j.read_text())["trajectories"]
    assert e["times"] is False and e["start_s"] is None and e["rate_hz"] is None
    assert e["poses"] == 5 and e["length_m"] == 4.0
    assert "no times, 5 poses" in out and "Hz" not in out
    times = tmp_path / "times.txt"
    times.write_text("0\n0.1\n0.2\n0.3\n0.4\n")
    assert main(["traj", "info", str(f), "--times", str(times), "--json", str(j)]) == 0
    (e,) = json.loads(j.read_text())["trajectories"]
    assert e["rate_hz"] == pytest.approx(10.0) and "times" not in e


def test_info_of_a_tf_chain_warns_once(tmp_path, capsys):
    from test_bags import _tf_bag

    _tf_bag(tmp_path / "tf")
    assert main(["traj", "info", f"{tmp_path / 'tf'}:/tf:map.camera"]) == 0
    err = capsys.readouterr().err
    assert err.count("lie outside the time span") == 1, err
