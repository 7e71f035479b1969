"""Trajectory readers and writers: layouts, detection, strict errors, the cut-off last line."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from relation_metric.errors import InputError
from relation_metric.trajectory import Trajectory
from slamrel.formats.text import TruncatedLineWarning
from slamrel.formats.trajectories import (
    InvalidPoseWarning,
    detect_trajectory_format,
    quaternion_from_yaw,
    read_trajectory,
    write_trajectory,
    yaw_from_quaternion,
)


def write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.fixture
def traj(rng):
    t = np.cumsum(rng.uniform(0.05, 0.2, size=50))
    p = np.column_stack((rng.normal(size=(50, 2)) * 10, rng.uniform(-np.pi, np.pi, 50)))
    return Trajectory(t, p)


@pytest.mark.parametrize("fmt", ["plain", "tum", "csv", "g2o", "carmen"])
def test_write_read_round_trip(tmp_path, traj, fmt):
    path = tmp_path / f"traj.{fmt}"
    write_trajectory(path, traj, format=fmt)
    got = read_trajectory(path)
    assert got.format == fmt  # recognised from the content
    tol = 1e-6 if fmt != "carmen" else 1e-6
    if fmt == "g2o":  # g2o has no time: the vertex id becomes the timestamp
        np.testing.assert_array_equal(got.trajectory.timestamps, np.arange(len(traj)))
    else:
        np.testing.assert_allclose(got.trajectory.timestamps, traj.timestamps, atol=tol)
    np.testing.assert_allclose(got.trajectory.poses[:, :2], traj.poses[:, :2], atol=tol)
    dth = np.angle(np.exp(1j * (got.trajectory.poses[:, 2] - traj.poses[:, 2])))
    assert np.abs(dth).max() < 1e-6


@pytest.mark.parametrize("fmt", ["plain", "csv", "g2o", "carmen"])
def test_written_numbers_read_back_bit_for_bit(tmp_path, traj, fmt):
    """Every writer spells doubles with NUMBER_FORMAT (%.17g): no rounding on the way."""
    path = tmp_path / f"traj.{fmt}"
    write_trajectory(path, traj, format=fmt)
    got = read_trajectory(path).trajectory
    np.testing.assert_array_equal(got.poses, traj.poses)
    if fmt != "g2o":
        np.testing.assert_array_equal(got.timestamps, traj.timestamps)


def test_yaw_quaternion_hand_values():
    # rotation of 90° about z: q = (0, 0, sin 45°, cos 45°)
    q = np.array([0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5)])
    assert yaw_from_quaternion(q) == pytest.approx(math.pi / 2)
    ang = np.linspace(-np.pi + 1e-9, np.pi - 1e-9, 101)
    np.testing.assert_allclose(yaw_from_quaternion(quaternion_from_yaw(ang)), ang, atol=1e-12)


def test_carmen_layouts(tmp_path):
    text = (
        "PARAM robot_use_laser on nohost 0\n"
        # FLASER n r1..rn x y θ odom_x odom_y odom_θ ipc_ts host logger_ts (n = 2)
        "FLASER 2 1.0 2.0 1.5 2.5 0.1 9 9 9 100.5 host 0.5\n"
        # ROBOTLASER1 type start fov res maxr acc remmode n r.. m rem.. laser(3) robot(3)
        # tv rv fwd side turn ts host logger_ts (n = 1, m = 2)
        "ROBOTLASER1 0 -1.5 3.1 0.01 80 0.1 0 1 4.0 2 0.3 0.4 3.0 4.0 0.2 7 7 7 "
        "0 0 0 0 0 101.0 host 1.0\n"
        "ODOM 5.0 6.0 0.3 0 0 0 102.0 host 2.0\n"
    )
    p = write(tmp_path, "a.log", text)
    got = read_trajectory(p)
    assert got.format == "carmen"
    np.testing.assert_allclose(got.trajectory.timestamps, [100.5, 101.0, 102.0])
    np.testing.assert_allclose(
        got.trajectory.poses, [[1.5, 2.5, 0.1], [3.0, 4.0, 0.2], [5.0, 6.0, 0.3]]
    )
    assert got.skipped == {"PARAM": 1}
    odo = read_trajectory(p, pose="odometry").trajectory
    np.testing.assert_allclose(odo.poses[:2], [[9, 9, 9 - 2 * np.pi], [7, 7, 7 - 2 * np.pi]])


def test_cut_off_last_line_is_skipped_with_warning(tmp_path):
    text = (
        "FLASER 0 1 2 0.1 1 2 0.1 10.0 h 0\nFLASER 0 1.1 2 0.1 1.1 2 0.1 10.2 h 0\nFLASER 0 1.2 2"
    )
    p = write(tmp_path, "cut.log", text)
    with pytest.warns(
        TruncatedLineWarning, match=r"cut.log:3: no newline at the end: the last line"
    ):
        got = read_trajectory(p)
    assert len(got.trajectory) == 2
    assert got.skipped == {"truncated last line": 1}


def test_plain_cut_off_last_line(tmp_path):
    p = write(tmp_path, "t.txt", "0 0 0 0\n1 1 0 0\n2 2 0")
    with pytest.warns(TruncatedLineWarning):
        got = read_trajectory(p)
    assert len(got.trajectory) == 2


def test_parsing_last_line_without_newline_is_cut_off(tmp_path):
    """``2 2 0 -2.`` may be what is left of ``2 2 0 -2.575``: skipped with a warning."""
    p = write(tmp_path, "t.txt", "0 0 0 0\n1 1 0 0\n2 2 0 -2.")
    with pytest.warns(TruncatedLineWarning, match=r"t.txt:3: no newline at the end"):
        got = read_trajectory(p)
    assert len(got.trajectory) == 2 and got.skipped == {"truncated last line": 1}


def test_comment_last_line_without_newline_is_ignored(tmp_path):
    p = write(tmp_path, "t.txt", "0 0 0 0\n1 1 0 0\n# end")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = read_trajectory(p)
    assert len(got.trajectory) == 2 and got.skipped == {}


BAD_PLAIN = {
    "truncated line before the last": ("0 0 0 0\n1 1 0\n2 2 0 0\n", 2, "expected 4 fields"),
    "letters in a number": ("0 0 0 0\n1 1x 0 0\n", 2, "expected a number, got '1x'"),
    "NaN": ("0 0 0 0\n1 nan 0 0\n", 2, "expected a finite number"),
}


@pytest.mark.parametrize("case", sorted(BAD_PLAIN))
def test_bad_plain_trajectory(tmp_path, case):
    text, line, message = BAD_PLAIN[case]
    p = write(tmp_path, "bad.txt", "# t x y theta\n" + text)
    with pytest.raises(InputError) as err:
        read_trajectory(p)
    assert f"bad.txt:{line + 1}:" in str(err.value)
    assert message in str(err.value)


def test_time_going_backwards_is_sorted_or_refused_beyond_a_tolerance(tmp_path):
    # timed poses are sorted (tests/test_timeorder.py); with a tolerance (a log driving a
    # filter) a larger step back is refused at its line
    p = write(tmp_path, "bad.txt", "# t x y theta\n0 0 0 0\n2 1 0 0\n1 1 0 0\n")
    with pytest.raises(InputError, match="time goes backwards by 1.000000 s") as err:
        read_trajectory(p, max_step_back=0.05)
    assert "bad.txt:4:" in str(err.value) and "(line 3)" in str(err.value)


def test_empty_file(tmp_path):
    p = write(tmp_path, "empty.txt", "")
    with pytest.raises(InputError, match="empty.txt"):
        read_trajectory(p, format="plain")


def test_carmen_errors_name_the_line(tmp_path):
    p = write(
        tmp_path,
        "b.log",
        "FLASER 0 1 2 0.1 1 2 0.1 10.0 h 0\n"
        "FLASER 0 1 2 x 1 2 0.1 10.1 h 0\n"
        "ODOM 1 2 3 0 0 0 11 h 0\n",
    )
    with pytest.raises(InputError, match=r"b.log:2: FLASER θ: expected a number, got 'x'"):
        read_trajectory(p)
    p = write(tmp_path, "c.log", "FLASER 3 1 2 0.1 1 2 0.1 10.0 h 0\nODOM 1 2 3 0 0 0 11 h 0\n")
    with pytest.raises(InputError, match=r"c.log:1: FLASER record: expected 14 fields, got 11"):
        read_trajectory(p)


def test_carmen_non_finite_pose_strict_and_skipped(tmp_path):
    text = (
        "FLASER 0 1 2 0.1 1 2 0.1 10.0 h 0\n"
        "FLASER 0 nan nan nan nan nan nan 99.0 h 0\n"
        "FLASER 0 1 2 0.1 1 2 0.1 10.2 h 0\n"
    )
    p = write(tmp_path, "n.log", text)
    with pytest.raises(InputError, match=r"n.log:2: .*non-finite"):
        read_trajectory(p)
    with pytest.warns(InvalidPoseWarning, match=r"line 2"):
        got = read_trajectory(p, skip_invalid=True)
    assert got.skipped == {"invalid pose": 1}
    np.testing.assert_allclose(got.trajectory.timestamps, [10.0, 10.2])


def test_tum_rejects_non_unit_quaternion(tmp_path):
    p = write(tmp_path, "t.tum", "0 0 0 0 0 0 0 1\n1 0 0 0 0 0 0 2\n")
    with pytest.raises(InputError, match=r"t.tum:2: quaternion norm"):
        read_trajectory(p)


def test_detection_by_content_and_extension(tmp_path):
    assert detect_trajectory_format(write(tmp_path, "x.dat", "# c\n1 2 3 4\n")) == "plain"
    assert detect_trajectory_format(write(tmp_path, "y.dat", "1 2 3 4 0 0 0 1\n")) == "tum"
    assert detect_trajectory_format(write(tmp_path, "z.dat", "VERTEX_SE2 0 1 2 3\n")) == "g2o"
    assert detect_trajectory_format(write(tmp_path, "w.dat", "t,x,y,theta\n0,1,2,3\n")) == "csv"
    assert (
        detect_trajectory_format(write(tmp_path, "v.dat", "ODOM 1 2 3 0 0 0 1 h 0\n")) == "carmen"
    )
    assert detect_trajectory_format(write(tmp_path, "u.clf", "")) == "carmen"
    with pytest.raises(InputError, match="cannot recognise"):
        detect_trajectory_format(write(tmp_path, "s.dat", "1 2 3\n"))


def test_writer_is_atomic_and_keeps_target_on_error(tmp_path, traj):
    out = tmp_path / "out.txt"
    out.write_text("keep me")
    with pytest.raises(InputError):
        write_trajectory(out, traj, format="nonsense")
    assert out.read_text() == "keep me"
    assert sorted(q.name for q in tmp_path.iterdir()) == ["out.txt"]
