"""``sensor_msgs/LaserScan`` from ROS bags (slamrel.formats.bags / formats.laser) and
``slamrel relations align BAG:TOPIC --estimate BAG:/odom``.

The bags are written with rosbags' writers (ROS 1, ROS 2 sqlite3, MCAP) from the ray-casting
laser simulator: a robot drives a loop in the ``room`` world with its laser mounted off its
origin (a two-edge ``tf_static`` chain base_link → laser_mount → laser), its drifting
odometry on ``/odom`` (nav_msgs/Odometry of base_link). The oracles are the simulator's
arrays (the float32 values written), the offset composed by hand in SE(2) from the numbers
written into tf_static, and the simulator's true laser poses for the relations.
"""

from __future__ import annotations

import json
import math
import os
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import require_data

from relation_metric import se3
from relation_metric.errors import InputError
from relation_metric.se2 import between, compose, inverse
from slamrel.cli import main
from slamrel.formats.bags import bag_topics
from slamrel.formats.laser import bag_laser_offset, read_laser_scans
from slamrel.simulation.laser import laser_world, loop_path, simulate_laser_log

if os.environ.get("CI", "").lower() != "true":  # in the test extra: CI must run these
    pytest.importorskip("rosbags", reason="rosbags not installed: pip install .")

from rosbags.rosbag1 import Writer as Writer1  # noqa: E402
from rosbags.rosbag2 import StoragePlugin  # noqa: E402
from rosbags.rosbag2 import Writer as Writer2  # noqa: E402
from rosbags.typesys import Stores, get_types_from_msg, get_typestore  # noqa: E402

SCAN, ODOM, TF = "sensor_msgs/msg/LaserScan", "nav_msgs/msg/Odometry", "tf2_msgs/msg/TFMessage"
T0 = 1_700_000_000
RANGE_MIN = 0.1
#: tf_static: base_link → laser_mount (x, y, z, yaw), laser_mount → laser (x, y, z, yaw, roll)
MOUNT = (0.15, 0.05, 0.3, 0.04)
LASER = (0.05, 0.0, 0.02, 0.06, 0.01)
#: The laser on the robot in SE(2), composed by hand: [0.15, 0.05, 0.04] ∘ [0.05, 0, 0.06]
OFFSET = np.array([0.15 + 0.05 * math.cos(0.04), 0.05 + 0.05 * math.sin(0.04), 0.04 + 0.06])
#: Beams of scan 5 made invalid: NaN, +inf, below range_min, −inf, beyond range_max
BAD_BEAMS = {10: np.nan, 11: np.inf, 12: 0.05, 13: -np.inf, 14: 85.0}
SKIP_ODOM = 2  # the odometry starts at scan 2's stamp: scans 0 and 1 have no pose


def _stamps(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Scan k at T0 + 0.2 k s, as (sec, nanosec)."""
    k = np.arange(n)
    return T0 + k // 5, (k % 5) * 200_000_000


@pytest.fixture(scope="module")
def world():
    """The simulated drive: scans (float32, as written), true laser poses, base odometry."""
    corners = np.array([[1.5, 1.5], [10.5, 1.5], [10.5, 4.5], [1.5, 4.5]])
    base_truth = loop_path(corners, 0.3)
    laser_truth = compose(base_truth, OFFSET)
    log = simulate_laser_log(laser_world("room"), laser_truth, seed=7)
    ranges = log.scans.ranges.astype(np.float32)
    for k, v in BAD_BEAMS.items():
        ranges[5, k] = v
    base_odom = compose(log.scans.laser_pose, inverse(OFFSET))
    return {"log": log, "ranges": ranges, "base_odom": base_odom, "n": len(log.scans)}


def _header(T, sec, nsec, frame, k, ros1):
    fields = {"stamp": T["builtin_interfaces/msg/Time"](sec=int(sec), nanosec=int(nsec))}
    fields["frame_id"] = frame
    if ros1:
        fields["seq"] = k
    return T["std_msgs/msg/Header"](**fields)


def _tf(T, parent, child, xyz, rpy, ros1, sec=T0, nsec=0):
    q = se3.from_euler_zyx(np.asarray(rpy, dtype=np.float64))
    return T["geometry_msgs/msg/TransformStamped"](
        header=_header(T, sec, nsec, parent, 0, ros1),
        child_frame_id=child,
        transform=T["geometry_msgs/msg/Transform"](
            translation=T["geometry_msgs/msg/Vector3"](x=xyz[0], y=xyz[1], z=xyz[2]),
            rotation=T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]),
        ),
    )


def _odometry(T, sec, nsec, pose, k, ros1):
    q = se3.from_euler_zyx(np.array([0.0, 0.0, pose[2]]))
    zero3 = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
    return T[ODOM](
        header=_header(T, sec, nsec, "odom", k, ros1),
        child_frame_id="base_link",
        pose=T["geometry_msgs/msg/PoseWithCovariance"](
            pose=T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](x=pose[0], y=pose[1], z=0.0),
                orientation=T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]),
            ),
            covariance=np.zeros(36),
        ),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](
            twist=T["geometry_msgs/msg/Twist"](linear=zero3, angular=zero3),
            covariance=np.zeros(36),
        ),
    )


def _scan(T, sec, nsec, ranges, k, ros1, sensor=(-math.pi / 2, math.pi / 360, RANGE_MIN, 80.0)):
    """A LaserScan of frame laser; ``sensor`` is (angle_min, increment, range_min, range_max)."""
    return T[SCAN](
        header=_header(T, sec, nsec, "laser", k, ros1),
        angle_min=sensor[0],
        angle_max=sensor[0] + sensor[1] * (ranges.size - 1),
        angle_increment=sensor[1],
        time_increment=0.0,
        scan_time=0.2,
        range_min=sensor[2],
        range_max=sensor[3],
        ranges=np.asarray(ranges, dtype=np.float32),
        intensities=np.zeros(0, dtype=np.float32),
    )


def _writer(path: Path, storage: str):
    if storage == "ros1":
        return Writer1(path)
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    return Writer2(path, version=9, storage_plugin=plugin)


def _write(
    path: Path, storage: str, world: dict, *, tf_static: bool = True, scans=None, laser=LASER
) -> Path:
    """/scan (LaserScan of frame laser), /odom (base_link; also as /tf odom->base_link),
    /tf_static (the two mount edges)."""
    ros1 = storage == "ros1"
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.LATEST)
    if TF not in ts.types:  # the noetic store has no tf2_msgs: its one-line definition
        ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", TF))
    T = ts.types

    def ser(msg, msgtype):
        return ts.serialize_ros1(msg, msgtype) if ros1 else ts.serialize_cdr(msg, msgtype)

    ranges = world["ranges"] if scans is None else scans
    sec, nsec = _stamps(len(ranges))
    with _writer(path, storage) as w:
        if tf_static:
            c = w.add_connection("/tf_static", TF, typestore=ts)
            edges = [
                _tf(T, "base_link", "laser_mount", MOUNT[:3], (0.0, 0.0, MOUNT[3]), ros1),
                _tf(T, "laser_mount", "laser", laser[:3], (laser[4], 0.0, laser[3]), ros1),
            ]
            w.write(c, 1, ser(T[TF](transforms=edges), TF))
        cs = w.add_connection("/scan", SCAN, typestore=ts)
        co = w.add_connection("/odom", ODOM, typestore=ts) if scans is None else None
        ctf = w.add_connection("/tf", TF, typestore=ts) if scans is None else None
        for k, r in enumerate(ranges):
            t = 10**9 * int(sec[k]) + int(nsec[k])
            w.write(cs, t, ser(_scan(T, sec[k], nsec[k], r, k, ros1), SCAN))
            if co is not None and ctf is not None and k >= SKIP_ODOM:
                x, y, th = world["base_odom"][k]
                odom = _odometry(T, sec[k], nsec[k], world["base_odom"][k], k, ros1)
                w.write(co, t + 1, ser(odom, ODOM))
                edge = _tf(T, "odom", "base_link", (x, y, 0.0), (0, 0, th), ros1, sec[k], nsec[k])
                w.write(ctf, t + 2, ser(T[TF](transforms=[edge]), TF))
    return path


STORAGES = [("ros1", "drive.bag"), ("sqlite3", "drive_db3"), ("mcap", "drive_mcap")]


@pytest.fixture(scope="module")
def bags(tmp_path_factory, world):
    root = tmp_path_factory.mktemp("laserbags")
    return {s: _write(root / name, s, world) for s, name in STORAGES}


@pytest.mark.parametrize("storage", [s for s, _ in STORAGES])
def test_laser_scans_read_back_as_written(bags, world, storage):
    s = read_laser_scans(f"{bags[storage]}:/scan")
    n = world["n"]
    sec, nsec = _stamps(n)
    assert len(s) == n and s.record == "LaserScan" and s.frame_id == "laser"
    np.testing.assert_array_equal(s.timestamps, sec + nsec * 1e-9)
    np.testing.assert_array_equal(s.ranges, world["ranges"].astype(np.float64))  # NaN = NaN
    np.testing.assert_array_equal(s.beams, 361)
    np.testing.assert_array_equal(s.start_angle, np.float32(-math.pi / 2))
    np.testing.assert_array_equal(s.angular_resolution, np.float32(math.pi / 360))
    np.testing.assert_array_equal(s.max_range, 80.0)
    np.testing.assert_array_equal(s.min_range, np.float32(RANGE_MIN))
    assert np.isnan(s.laser_pose).all() and np.isnan(s.odometry_pose).all()
    np.testing.assert_array_equal(s.lines, np.arange(1, n + 1))
    # returns by hand from the float32 numbers written; the invalid beams are no returns
    r = world["ranges"][5].astype(np.float64)
    a = np.float32(-math.pi / 2) + np.arange(361) * np.float32(math.pi / 360)
    pts = s.points(5)
    bad = np.isnan(pts[:, 0])
    assert sorted(np.flatnonzero(bad).tolist()) == sorted(BAD_BEAMS)
    np.testing.assert_allclose(pts[~bad, 0], (r * np.cos(a))[~bad], rtol=0, atol=1e-12)
    np.testing.assert_allclose(pts[~bad, 1], (r * np.sin(a))[~bad], rtol=0, atol=1e-12)
    # an option's min_range above the scan's own still applies
    assert np.isnan(s.points(5, min_range=1e3)).all()


def test_laser_offset_from_tf_static(bags):
    for storage, bag in bags.items():
        offset, text = bag_laser_offset(str(bag), "base_link", "laser")
        np.testing.assert_allclose(offset, OFFSET, rtol=0, atol=1e-12, err_msg=storage)
        assert "tf_static base_link->laser" in text and "z 0.32 m" in text
    # one edge, and a frame with itself
    offset, _ = bag_laser_offset(str(bags["mcap"]), "laser_mount", "laser")
    np.testing.assert_allclose(offset, [0.05, 0.0, 0.06], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(bag_laser_offset(str(bags["mcap"]), "laser", "laser")[0], 0.0)
    missing, text = bag_laser_offset(str(bags["mcap"]), "odom", "laser")
    assert missing is None and "base_link->laser_mount, laser_mount->laser" in text


def _errors(ours: np.ndarray, world: dict) -> tuple[np.ndarray, np.ndarray]:
    """Translation [m] and rotation [°] errors of ``t1 t2 x y z roll pitch yaw`` rows."""
    times = world["log"].scans.timestamps
    sec, nsec = _stamps(len(times))
    stamps = sec + nsec * 1e-9
    i = np.abs(ours[:, 0, None] - stamps[None]).argmin(axis=1)
    j = np.abs(ours[:, 1, None] - stamps[None]).argmin(axis=1)
    truth = world["log"].truth
    e = between(between(truth[i], truth[j]), ours[:, [2, 3, 7]])
    return np.hypot(e[:, 0], e[:, 1]), np.degrees(np.abs(e[:, 2]))


@pytest.mark.parametrize("storage", ["ros1", "mcap"])
def test_align_from_a_bag_meets_the_simulated_targets(bags, world, storage, tmp_path, capsys):
    bag = bags[storage]
    out, report = tmp_path / "bag.relations", tmp_path / "q.csv"
    argv = ["relations", "align", f"{bag}:/scan", "--estimate", f"{bag}:/odom", "-o", str(out)]
    assert main([*argv, "--report", str(report), "--review", str(tmp_path / "r.html")]) == 0
    std = capsys.readouterr()
    n = world["n"] - SKIP_ODOM
    assert f"relations from {n} LaserScan scans (laser poses from {bag}:/odom" in std.out
    assert "offset [0.2 0.052 0.1] from tf_static base_link->laser" in std.out
    assert f"{SKIP_ODOM} of {world['n']} scans lie outside the time span" in std.err
    ours = np.loadtxt(out)
    assert len(ours) > 40
    et, er = _errors(ours, world)
    # the targets of the CARMEN simulated tests (tests/test_scans.py)
    assert np.median(et) <= 0.015 and np.median(er) <= 0.2, (np.median(et), np.median(er))
    assert np.percentile(et, 95) <= 0.05 and np.percentile(er, 95) <= 1.0
    # the guesses are the laser's odometry: the base odometry composed with the offset
    rows = np.genfromtxt(report, delimiter=",", skip_header=1, usecols=(0, 1, 5, 6, 7))
    k = np.round((rows[:, :2] - T0) / 0.2).astype(int)
    odom = world["log"].scans.laser_pose
    np.testing.assert_allclose(rows[:, 2:], between(odom[k[:, 0]], odom[k[:, 1]]), atol=1e-9)


def test_a_tf_chain_estimate_names_the_base_frame(bags, tmp_path, capsys):
    """BAG:/tf:odom.base_link: the chain's CHILD is the base frame, as an Odometry's child."""
    bag = bags["sqlite3"]
    outs = []
    for est in ("/odom", "/tf:odom.base_link"):
        outs.append(tmp_path / f"{len(outs)}.relations")
        argv = ["relations", "align", f"{bag}:/scan", "--estimate", f"{bag}:{est}"]
        assert main([*argv, "-o", str(outs[-1]), "--distance", "1"]) == 0
        assert "offset [0.2 0.052 0.1] from tf_static base_link->laser" in capsys.readouterr().out
    np.testing.assert_allclose(np.loadtxt(outs[0]), np.loadtxt(outs[1]), rtol=0, atol=1e-9)


def test_without_tf_static_the_offset_is_zero_and_said(tmp_path, world, capsys):
    bag = _write(tmp_path / "no_tf.bag", "ros1", world, tf_static=False)
    out = tmp_path / "z.relations"
    argv = ["relations", "align", f"{bag}:/scan", "--estimate", f"{bag}:/odom", "-o", str(out)]
    assert main([*argv, "--distance", "2", "-q"]) == 0
    err = capsys.readouterr().err
    assert "no static transform base_link->laser" in err and "its static transforms: none" in err
    assert "laser offset is taken as zero" in err and "--base-frame" in err
    # --base-frame laser: the estimate is taken as the laser's poses, without a warning
    assert main([*argv, "--distance", "2", "-q", "--base-frame", "laser"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "outside the time span" in err[0]  # only that warning


def _one_line_error(capsys, argv: list[str], code: int, text: str) -> None:
    assert main(argv) == code
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and text in err, err


def test_bag_errors_exit_with_one_line(bags, world, tmp_path, capsys):
    bag = bags["sqlite3"]
    out = str(tmp_path / "x.relations")
    align = ["relations", "align"]
    odom = ["--estimate", f"{bag}:/odom", "-o", out]
    _one_line_error(
        capsys,
        [*align, f"{bag}:/odom", *odom],
        3,
        "topic '/odom' holds nav_msgs/Odometry messages; expected sensor_msgs/LaserScan",
    )
    _one_line_error(capsys, [*align, f"{bag}:/nope", *odom], 3, "no topic '/nope' in the bag")
    _one_line_error(capsys, [*align, f"{bag}:/scan", "-o", out], 2, "give --estimate TRAJ")
    _one_line_error(capsys, [*align, f"{bag}:/scan", *odom, "--record", "FLASER"], 2, "--record")
    # a beam count that changes within the topic
    scans = [world["ranges"][k] for k in range(4)]
    scans[2] = scans[2][:360]
    uneven = _write(tmp_path / "uneven_db3", "sqlite3", world, scans=scans)
    _one_line_error(
        capsys,
        [*align, f"{uneven}:/scan", "--estimate", f"{bag}:/odom", "-o", out],
        3,
        "message 3: 360 beams, but the topic's first message has 361",
    )
    # a bag without a topic: the topics listed
    with pytest.raises(InputError, match=r"name the laser as BAG:TOPIC.*/scan \(sensor_msgs"):
        read_laser_scans(bag)
    assert {t.topic for t in bag_topics(bag)} == {"/scan", "/odom", "/tf", "/tf_static"}
    # an estimate that is not a trajectory
    _one_line_error(
        capsys,
        [*align, f"{bag}:/scan", "--estimate", f"{bag}:/scan", "-o", out],
        3,
        "topic '/scan' holds sensor_msgs/LaserScan messages; expected one of",
    )


def test_without_rosbags_one_message_says_how_to_install_it(bags, tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "rosbags.highlevel", None)  # as if not installed
    bag = bags["mcap"]
    argv = ["relations", "align", f"{bag}:/scan", "--estimate", f"{bag}:/odom"]
    _one_line_error(capsys, [*argv, "-o", str(tmp_path / "x")], 3, "pip install rosbags")


def test_a_tilted_laser_is_refused(tmp_path, world):
    """An upside-down laser (roll π on the mount) would mirror the scans: refused."""
    flipped = (*LASER[:4], math.pi)
    bag = _write(tmp_path / "flip.bag", "ros1", world, scans=world["ranges"][:2], laser=flipped)
    with pytest.raises(InputError, match=r"tilt of 180.0° against 'base_link'.*upside-down"):
        bag_laser_offset(str(bag), "base_link", "laser")


def test_a_carmen_log_as_a_bag_gives_the_carmen_relations(tmp_path, capsys):
    """Parity on real scans: mit-csail.clf's FLASER scans and odometry written as a ROS 2
    bag (LaserScan, Odometry, an identity tf_static) give the relations of the CARMEN path at
    the authors' first 40 timestamp pairs, up to the float32 of LaserScan.ranges."""
    log = require_data("freiburg", "mit-csail.clf")
    at = tmp_path / "first.relations"
    at.write_text("".join(require_data("freiburg", "mit-csail.relations").open().readlines()[:40]))
    s = read_laser_scans(log)
    ts = get_typestore(Stores.LATEST)
    T = ts.types
    sec = np.floor(s.timestamps).astype(np.int64)
    nsec = np.round((s.timestamps - sec) * 1e9).astype(np.int64)
    assert (nsec < 10**9).all()
    bag = tmp_path / "mit_mcap"
    with _writer(bag, "mcap") as w:
        c = w.add_connection("/tf_static", TF, typestore=ts)
        same = _tf(T, "base_link", "laser", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), False)
        w.write(c, 1, ts.serialize_cdr(T[TF](transforms=[same]), TF))
        cs = w.add_connection("/scan", SCAN, typestore=ts)
        co = w.add_connection("/odom", ODOM, typestore=ts)
        for k in range(len(s)):
            n = int(s.beams[k])
            sensor = (s.start_angle[k], s.angular_resolution[k], 0.0, s.max_range[k])
            scan = _scan(T, sec[k], nsec[k], s.ranges[k, :n], k, False, sensor)
            t = int(sec[k]) * 10**9 + int(nsec[k])
            w.write(cs, t, ts.serialize_cdr(scan, SCAN))
            odom = _odometry(T, sec[k], nsec[k], s.odometry_pose[k], k, False)
            w.write(co, t + 1, ts.serialize_cdr(odom, ODOM))
    carmen, ours = tmp_path / "carmen.relations", tmp_path / "bag.relations"
    args = ["relations", "align", "--at", str(at), "-q"]
    assert main([*args, str(log), "-o", str(carmen), "--report", str(tmp_path / "c.csv")]) == 0
    bag_args = [f"{bag}:/scan", "--estimate", f"{bag}:/odom", "--report", str(tmp_path / "b.csv")]
    assert main([*args, *bag_args, "-o", str(ours)]) == 0
    assert capsys.readouterr().err == ""  # the offset found, every scan with a pose
    a, b = np.loadtxt(carmen), np.loadtxt(ours)
    np.testing.assert_array_equal(a[:, :2], b[:, :2])
    e = between(a[:, [2, 3, 7]], b[:, [2, 3, 7]])
    assert np.hypot(e[:, 0], e[:, 1]).max() < 1e-5 and np.abs(e[:, 2]).max() < 1e-5
    flags = [np.genfromtxt(tmp_path / f, delimiter=",", dtype=str, skip_header=1)[:, -1]
             for f in ("c.csv", "b.csv")]  # fmt: skip
    np.testing.assert_array_equal(flags[0], flags[1])


def test_a_clockwise_scanner_gives_the_same_returns(tmp_path, world):
    """angle_increment < 0 (beams listed clockwise): the scan reversed, the same points."""
    ts = get_typestore(Stores.LATEST)
    T = ts.types
    r = world["ranges"][:2]
    for name, rows, sensor in (
        ("ccw", r, (-math.pi / 2, math.pi / 360, RANGE_MIN, 80.0)),
        ("cw", np.ascontiguousarray(r[:, ::-1]), (math.pi / 2, -math.pi / 360, RANGE_MIN, 80.0)),
    ):
        with _writer(tmp_path / name, "sqlite3") as w:
            c = w.add_connection("/scan", SCAN, typestore=ts)
            for k, row in enumerate(rows):
                w.write(c, k + 1, ts.serialize_cdr(_scan(T, T0, k, row, k, False, sensor), SCAN))
    ccw, cw = (
        read_laser_scans(f"{next((tmp_path / n).glob('*.db3'))}:/scan") for n in ("ccw", "cw")
    )
    assert cw.angular_resolution[0] < 0
    for k in range(2):
        np.testing.assert_allclose(cw.points(k)[::-1], ccw.points(k), rtol=0, atol=1e-5)


def test_traj_topics_says_what_each_topic_is_read_as(bags, tmp_path, capsys):
    from slamrel.cli import main

    j = tmp_path / "topics.json"
    assert main(["traj", "topics", str(bags["ros1"]), "--json", str(j)]) == 0
    rows = {r["topic"]: r["read_as"] for r in json.loads(j.read_text())["topics"]}
    assert rows == {
        "/scan": "laser scans",
        "/odom": "trajectory",
        "/tf": "trajectory",
        "/tf_static": "trajectory",
    }
    out = capsys.readouterr().out
    assert "laser scans (relations align)" in out


def test_scans_in_a_gap_of_the_estimate_are_counted(bags, world, tmp_path, capsys):
    """Guesses interpolated across a gap of the estimate (2.2 s, here: 10 odometry poses
    removed) are counted in a warning; scans at an estimate pose's own time are not."""
    bag = bags["ros1"]
    tum = tmp_path / "odom.tum"
    assert main(["traj", "convert", f"{bag}:/odom", "-o", str(tum)]) == 0
    rows = np.loadtxt(tum)
    kept = np.delete(rows, np.arange(20, 30), axis=0)  # poses 20..29 after the first one
    gapped = tmp_path / "gapped.tum"
    np.savetxt(gapped, kept, fmt="%.17g")
    capsys.readouterr()
    argv = ["relations", "align", f"{bag}:/scan", "--estimate", str(gapped), "--base-frame"]
    assert main([*argv, "base_link", "-o", str(tmp_path / "g.relations"), "-q"]) == 0
    err = capsys.readouterr().err
    gap = kept[20, 0] - kept[19, 0]
    assert f"10 of {world['n'] - SKIP_ODOM} scans fall in gaps of {gapped}" in err
    assert f"the longest {gap:.3g} s" in err
    full = tmp_path / "full.tum"
    np.savetxt(full, rows, fmt="%.17g")
    argv[4] = str(full)
    assert main([*argv, "base_link", "-o", str(tmp_path / "f.relations"), "-q"]) == 0
    assert "fall in gaps" not in capsys.readouterr().err


def test_interpolation_gaps_by_hand():
    from slamrel.scans.report import interpolation_gaps

    t = np.array([0.0, 1.0, 4.0, 4.5])
    stamps = np.array([-1.0, 0.0, 0.5, 1.0, 2.0, 4.0, 4.2, 5.0])
    np.testing.assert_array_equal(
        interpolation_gaps(t, stamps), [0.0, 0.0, 1.0, 0.0, 3.0, 0.0, 0.5, 0.0]
    )
