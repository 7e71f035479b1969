"""recovery.bundle: exact round trip, and every rejection of BUNDLE.md with file and line;
the CLI's exit code 3 on bad bundles; ``slamrel evaluate`` with a bundle as REFERENCE."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from recovery.bundle import read_bundle, write_bundle
from recovery.simulation.bundles import simulate_bundle
from relation_metric.errors import InputError
from slamrel.cli import main


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
    assert m["unassociated"] > 0 and report["nees"]["poses"] == 120
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
