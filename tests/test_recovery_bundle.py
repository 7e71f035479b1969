"""recovery.bundle: exact round trip, and every rejection of docs/bundle.md with file and line;
the CLI's exit code 3 on bad bundles; ``slamrel evaluate`` with a bundle as REFERENCE."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from relation_metric.errors import InputError
from slamrel.cli import main
from slamrel.formats.bundle import read_bundle, write_bundle
from slamrel.simulation.bundles import simulate_bundle


@pytest.fixture
def bundle_dir(tmp_path: Path) -> Path:
    b = simulate_bundle(
        3, steps=120, map_sigma=(0.02, 0.05), map_covariance=True, unassociated_fraction=0.1
    )
    write_bundle(tmp_path / "b", b)
    return tmp_path / "b"


def test_round_trip_is_exact(tmp_path: Path) -> None:
    for kw in ({}, {"motion": "odometry", "alpha": (0.1, 0.01, 0.02, 0.01)}):
        b = simulate_bundle(1, steps=80, unassociated_fraction=0.2, **kw)
        write_bundle(tmp_path / "x", b)
        r = read_bundle(tmp_path / "x")
        assert r.motion == b.motion and r.sensor == b.sensor
        for name in (
            "measurement_times",
            "measurements",
            "map_xy",
            "map_marginals",
            "map_ids",
            "initial_pose",
            "initial_covariance",
        ):
            np.testing.assert_array_equal(getattr(r, name), getattr(b, name), err_msg=name)
        np.testing.assert_array_equal(r.measurement_associated, b.measurement_associated)
        a = b.measurement_associated
        np.testing.assert_array_equal(r.measurement_landmarks[a], b.measurement_landmarks[a])
        np.testing.assert_array_equal(r.groundtruth.poses, b.groundtruth.poses)
        if b.controls is not None:
            np.testing.assert_array_equal(r.controls, b.controls)
        else:
            np.testing.assert_array_equal(r.odometry.poses, b.odometry.poses)
        # writing the read bundle again gives the same bytes
        write_bundle(tmp_path / "y", r)
        for f in (tmp_path / "x").iterdir():
            assert f.read_bytes() == (tmp_path / "y" / f.name).read_bytes(), f.name


def _edit(path: Path, line: int, text: str) -> None:
    lines = path.read_text().splitlines()
    lines[line - 1] = text
    path.write_text("\n".join(lines) + "\n")


def _expect(bundle_dir: Path, file: str, line: int | None, words: str) -> None:
    with pytest.raises(InputError) as info:
        read_bundle(bundle_dir)
    msg = str(info.value)
    where = str(bundle_dir / file) + (f":{line}" if line else "")
    assert msg.startswith(where + ":"), msg
    assert words in msg, msg
    assert main(["recover", str(bundle_dir), "-o", str(bundle_dir.parent / "o.txt"), "-q"]) == 3


def test_missing_file(bundle_dir: Path) -> None:
    (bundle_dir / "map.csv").unlink()
    _expect(bundle_dir, "map.csv", None, "missing required file")


def test_missing_column(bundle_dir: Path) -> None:
    _edit(bundle_dir / "measurements.csv", 1, "t,range,landmark,bearing_x")
    _expect(bundle_dir, "measurements.csv", 1, "missing column(s) bearing")


def test_non_finite_number(bundle_dir: Path) -> None:
    lines = (bundle_dir / "controls.csv").read_text().splitlines()
    _edit(bundle_dir / "controls.csv", 5, lines[4].split(",")[0] + ",nan,0.1")
    _expect(bundle_dir, "controls.csv", 5, "column 'v': expected a finite number")


def test_wrong_field_count(bundle_dir: Path) -> None:
    _edit(bundle_dir / "map.csv", 3, "101,1.0")
    _expect(bundle_dir, "map.csv", 3, "expected 6 comma-separated fields")


def test_time_goes_backwards(bundle_dir: Path) -> None:
    lines = (bundle_dir / "controls.csv").read_text().splitlines()
    _edit(bundle_dir / "controls.csv", 7, "0.0," + ",".join(lines[6].split(",")[1:]))
    _expect(bundle_dir, "controls.csv", 7, "time goes backwards")


def test_unknown_model_type(bundle_dir: Path) -> None:
    meta = json.loads((bundle_dir / "bundle.json").read_text())
    meta["motion_model"]["type"] = "ackermann"
    (bundle_dir / "bundle.json").write_text(json.dumps(meta, indent=2))
    text = (bundle_dir / "bundle.json").read_text().splitlines()
    line = next(i for i, t in enumerate(text, 1) if '"type"' in t)
    _expect(bundle_dir, "bundle.json", line, "unknown type 'ackermann'")


def test_unknown_landmark_and_skip(bundle_dir: Path) -> None:
    lines = (bundle_dir / "measurements.csv").read_text().splitlines()
    row = next(i for i, t in enumerate(lines[1:], 2) if not t.endswith(","))
    _edit(bundle_dir / "measurements.csv", row, lines[row - 1].rsplit(",", 1)[0] + ",99999")
    _expect(bundle_dir, "measurements.csv", row, "landmark 99999 is not in map.csv")
    n = len(lines) - 1
    b = read_bundle(bundle_dir, skip_unknown_landmarks=True)
    assert b.skipped_unknown == 1 and b.measurement_times.shape[0] == n - 1
    out = bundle_dir.parent / "r.json"
    code = main(
        [
            "recover",
            str(bundle_dir),
            "-o",
            str(bundle_dir.parent / "t.txt"),
            "--skip-unknown-landmarks",
            "--report",
            str(out),
            "-q",
        ]
    )
    assert code == 0
    assert json.loads(out.read_text())["measurements"]["skipped_unknown"] == 1


def test_non_psd_covariances(bundle_dir: Path) -> None:
    _edit(bundle_dir / "map.csv", 2, "100,1.0,2.0,0.01,0.5,0.01")
    _expect(bundle_dir, "map.csv", 2, "expected a positive semi-definite matrix")


def test_non_psd_joint_map_covariance(bundle_dir: Path) -> None:
    cov = np.load(bundle_dir / "map_covariance.npy")
    cov[0, 0] = -1.0
    np.save(bundle_dir / "map_covariance.npy", cov)
    _expect(bundle_dir, "map_covariance.npy", None, "positive semi-definite")
    cov[0, 0], cov[0, 1] = 1.0, cov[0, 1] + 0.5
    np.save(bundle_dir / "map_covariance.npy", cov)
    _expect(bundle_dir, "map_covariance.npy", None, "symmetric")


def test_non_psd_initial_covariance(bundle_dir: Path) -> None:
    meta = json.loads((bundle_dir / "bundle.json").read_text())
    meta["initial_covariance"] = [[1, 2, 0], [2, 1, 0], [0, 0, 1]]
    (bundle_dir / "bundle.json").write_text(json.dumps(meta))
    _expect(bundle_dir, "bundle.json", 1, "initial_covariance: expected a positive semi-definite")


def test_cli_recover_outputs(bundle_dir: Path, tmp_path: Path) -> None:
    traj, cov, rep = tmp_path / "t.tum", tmp_path / "c.npy", tmp_path / "r.json"
    code = main(
        [
            "recover",
            str(bundle_dir),
            "--method",
            "filter",
            "-o",
            str(traj),
            "--covariances",
            str(cov),
            "--report",
            str(rep),
            "--gate",
            "0.999",
            "-q",
        ]
    )
    assert code == 0
    rows = np.loadtxt(traj)
    assert rows.shape == (120, 8)
    c = np.load(cov)
    assert c.shape == (120, 3, 3)
    np.testing.assert_allclose(c, c.transpose(0, 2, 1))
    report = json.loads(rep.read_text())
    m = report["measurements"]
    assert m["used"] + m["gated"] + m["unassociated"] + m["outside"] == m["measurements"]
    assert m["unassociated"] > 0
    # the simulator starts the run at the true start pose: the NEES frame is the truth frame
    # (nothing to align), so the NEES is the unaligned one, and the landmark fit is reported
    # beside it
    frame = report["nees_frame"]
    assert not frame["aligned"] and "start pose" in frame["frame"]
    assert report["nees"] == report["nees_truth_frame"] and report["nees"]["dof"] == 3
    assert frame["map_anchoring"]["landmarks"] > 2 and report["nees"]["mean"] > 0
    # refuses to write over an input
    assert main(["recover", str(bundle_dir), "-o", str(bundle_dir / "map.csv"), "-q"]) == 3


def test_evaluate_accepts_bundle_as_reference(bundle_dir: Path, tmp_path: Path) -> None:
    b = read_bundle(bundle_dir)
    est = tmp_path / "est.txt"
    # the ground truth itself scores zero; a shifted copy scores its shift's relation error
    gt = b.groundtruth
    np.savetxt(est, np.column_stack((gt.timestamps, gt.poses)))
    out = tmp_path / "m.json"
    assert (
        main(
            [
                "evaluate",
                str(bundle_dir),
                str(est),
                "--strategy",
                "consecutive",
                "--json",
                str(out),
                "-q",
            ]
        )
        == 0
    )
    res = json.loads(out.read_text())
    assert res["relations"] == len(gt) - 1
    assert res["translation"]["abs"]["max"] < 1e-8


# ------------------------------ the checks live in the type (every producer is checked)


@pytest.fixture(scope="module")
def good():  # type: ignore[no-untyped-def]
    """A valid in-memory bundle (odometry model, joint map covariance, ground truth)."""
    return simulate_bundle(
        5, steps=60, motion="odometry", map_sigma=(0.02, 0.05), map_covariance=True
    )


def _bad_fields(b):  # type: ignore[no-untyped-def]
    """One invalid value per field, and a word the error must contain (the field / the rule)."""
    j, m = b.measurement_times.size, b.map_ids.size
    neg = b.measurements.copy()
    neg[3, 0] = -1.0
    back = b.measurement_times.copy()
    back[5] = back[4] - 1.0
    dup = b.map_ids.copy()
    dup[1] = dup[0]
    unknown = b.measurement_landmarks.copy()
    unknown[2] = 10**6
    asym = b.map_covariance.copy()
    asym[0, 1] += 1.0
    marg = b.map_marginals.copy()
    marg[0] = -np.eye(2)
    nan_xy = b.map_xy.copy()
    nan_xy[0, 0] = np.nan
    return {
        "measurements": (b.measurements[:, :1], "measurements: expected shape"),
        "measurement_landmarks": (b.measurement_landmarks[:-1], "measurement_landmarks"),
        "measurement_associated": (np.ones(j + 1, bool), "measurement_associated"),
        "map_xy": (np.zeros((m, 3)), "map_xy: expected shape"),
        "map_marginals": (np.zeros((m + 1, 2, 2)), "map_marginals"),
        "map_covariance": (np.eye(2 * m + 1), "map_covariance: expected shape"),
        "initial_pose": (np.zeros(2), "initial_pose"),
        "initial_covariance": (-np.eye(3), "initial_covariance"),
        "odometry": (None, "odometry model needs odometry"),
        "controls": (None, None),  # unused by the odometry model: no error
        "landmarks_groundtruth": ((b.map_ids, np.zeros((m, 3))), "landmarks_groundtruth xy"),
        "map_ids": (dup, "duplicate landmark id"),
        "measurement_times": (back, "goes back"),
        "map_xy_nan": (nan_xy, "map_xy: expected finite"),
        "ranges": (neg, "expected a positive range"),
        "unknown": (unknown, "is not in map.csv"),
        "asymmetric": (asym, "map covariance: expected a symmetric matrix"),
        "marginal": (marg, "positive semi-definite"),
    }


FIELD_OF = {
    "map_xy_nan": "map_xy",
    "ranges": "measurements",
    "unknown": "measurement_landmarks",
    "asymmetric": "map_covariance",
    "marginal": "map_marginals",
}


@pytest.mark.parametrize(
    "case",
    [
        "measurements", "measurement_landmarks", "measurement_associated", "map_xy",
        "map_marginals", "map_covariance", "initial_pose", "initial_covariance", "odometry",
        "controls", "landmarks_groundtruth", "map_ids", "measurement_times", "map_xy_nan",
        "ranges", "unknown", "asymmetric", "marginal",
    ],
)  # fmt: skip
def test_each_invalid_field_is_one_clear_error(good, case: str) -> None:  # type: ignore[no-untyped-def]
    """Built in memory (``dataclasses.replace``, as the producers do): the type checks itself."""
    from dataclasses import replace

    value, expected = _bad_fields(good)[case]
    field = FIELD_OF.get(case, case)
    if expected is None:
        assert replace(good, **{field: value}).controls is None
        return
    with pytest.raises(InputError) as err:
        replace(good, **{field: value})
    text = str(err.value)
    assert expected in text, text
    assert "np.float64" not in text and err.value.path is None  # in memory: no file to name


def test_velocity_model_needs_two_control_rows(good) -> None:  # type: ignore[no-untyped-def]
    from dataclasses import replace

    from recovery.models import MotionModel

    vel = MotionModel("velocity", sigma=(0.1, 0.1))
    with pytest.raises(InputError, match="needs controls"):
        replace(good, motion=vel)
    with pytest.raises(InputError, match="at least two control rows"):
        replace(good, motion=vel, controls=np.array([[0.0, 1.0, 0.0]]))
    with pytest.raises(InputError, match=r"controls: expected shape \(K, 3\)"):
        replace(good, motion=vel, controls=np.zeros((4, 2)))


def test_in_memory_producers_are_checked(tmp_path: Path) -> None:
    """A producer's bad array no longer slips through: its own ``Bundle(...)`` raises."""
    from slamrel.formats.isam import isam_log_bundle, read_isam

    # property: a producer's ordinary output passes ...
    b = simulate_bundle(2, steps=40, unassociated_fraction=0.3)
    assert b.measurements.shape == (b.measurement_times.size, 2)
    # ... noise far beyond the ranges draws negative ones: refused where the bundle is built
    with pytest.raises(InputError, match="expected a positive range"):
        simulate_bundle(2, steps=40, sigma_range=1e3)
    # the iSAM importer: a landmark seen at the robot's own position has range 0
    p = tmp_path / "zero.txt"
    p.write_text(
        "ODOMETRY 0 1 1.0 0 0 0.01 0 0 0.01 0 0.0001\n"
        "LANDMARK 0 3 2.0 0.0 0.04 0 0.04\nLANDMARK 1 2 0.0 0.0 0.04 0 0.04\n"
    )
    with pytest.raises(InputError, match=r"range 0\.0: expected a positive range"):
        isam_log_bundle(read_isam(p))


def test_read_errors_still_name_file_and_line(bundle_dir: Path) -> None:
    """The checks moved into the type; read from disk they still name the file and the line."""
    p = bundle_dir / "measurements.csv"
    rows = p.read_text().splitlines()
    t, _, bearing, lm = rows[4].split(",")
    rows[4] = ",".join((t, "-2.5", bearing, lm))
    p.write_text("\n".join(rows) + "\n")
    with pytest.raises(InputError) as err:
        read_bundle(bundle_dir)
    assert str(err.value).startswith(f"{p}:5: range -2.5: expected a positive range")
