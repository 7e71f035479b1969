"""What third-party filters write, stated in the bundle and read as stated (issue 38).

Each test compares against an independent oracle: the same bundle written the way the
statement says it is equivalent to (a zero initial covariance vs the documented floor, a
skipped measurement vs the bundle without that row), or a hand computation.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from slamrel.cli import main

ROOT = Path(__file__).resolve().parents[1]
SIM_BUNDLE = ROOT / "data" / "sim-bundle"


def _copy(tmp_path: Path, name: str = "b") -> Path:
    b = tmp_path / name
    shutil.copytree(SIM_BUNDLE, b)
    return b


def _set_manifest(b: Path, **keys: object) -> None:
    doc = json.loads((b / "bundle.json").read_text())
    doc.update(keys)
    (b / "bundle.json").write_text(json.dumps(doc, indent=2) + "\n")


def _edit_measurements(b: Path, edits: dict[int, tuple[int, str]]) -> None:
    """Set field ``col`` of data row ``row`` (0-based, after the header) to ``text``."""
    lines = (b / "measurements.csv").read_text().splitlines()
    for row, (col, text) in edits.items():
        fields = lines[row + 1].split(",")
        fields[col] = text
        lines[row + 1] = ",".join(fields)
    (b / "measurements.csv").write_text("\n".join(lines) + "\n")


def _recovered(tmp_path: Path, b: Path, *extra: str) -> bytes:
    out = tmp_path / f"{b.name}.txt"
    assert main(["recover", str(b), "-o", str(out), "-q", *extra]) == 0
    return out.read_bytes()


def test_zero_initial_covariance_is_the_documented_floor(tmp_path: Path) -> None:
    """An exactly zero (PSD, not PD) initial covariance is accepted and read as ``1e-9 I``:
    the recovered trajectory is byte for byte that of the bundle stating ``1e-9 I``."""
    from recovery.constants import INITIAL_COVARIANCE_FLOOR
    from recovery.recover import start_covariance

    zero = _copy(tmp_path, "zero")
    _set_manifest(zero, initial_covariance=np.zeros((3, 3)).tolist())
    floor = _copy(tmp_path, "floor")
    _set_manifest(floor, initial_covariance=(INITIAL_COVARIANCE_FLOOR * np.eye(3)).tolist())
    assert _recovered(tmp_path, zero) == _recovered(tmp_path, floor)
    # a singular PSD one gets the floor on its diagonal; a PD one is kept as it is
    sing = np.diag([1e-4, 1e-4, 0.0])
    assert np.array_equal(start_covariance(sing), sing + 1e-9 * np.eye(3))
    pd = np.diag([1e-4, 2e-4, 3e-4])
    assert start_covariance(pd) is not None and np.array_equal(start_covariance(pd), pd)


def test_invalid_measurements_refused_with_line_and_option(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    b = _copy(tmp_path)
    _edit_measurements(b, {4: (1, "-0.035"), 8: (2, "nan"), 11: (1, "0")})
    assert main(["recover", str(b), "-o", str(tmp_path / "x.txt"), "-q"]) == 3
    err = capsys.readouterr().err
    assert "measurements.csv:6:" in err and "range -0.035" in err
    assert "3 such measurement(s)" in err and "--skip-invalid-measurements" in err


def test_invalid_measurements_skipped_equal_the_rows_deleted(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--skip-invalid-measurements``: the recovery is that of the bundle without those rows
    (deleted by hand), the count is reported, the warning names the first line."""
    b = _copy(tmp_path, "skip")
    _edit_measurements(b, {4: (1, "-0.035"), 8: (2, "nan"), 11: (1, "0"), 20: (1, "inf")})
    hand = _copy(tmp_path, "hand")
    lines = (hand / "measurements.csv").read_text().splitlines()
    kept = [ln for k, ln in enumerate(lines) if k - 1 not in (4, 8, 11, 20)]
    (hand / "measurements.csv").write_text("\n".join(kept) + "\n")
    report = tmp_path / "r.json"
    got = _recovered(tmp_path, b, "--skip-invalid-measurements", "--report", str(report))
    err = capsys.readouterr().err
    assert got == _recovered(tmp_path, hand)
    assert json.loads(report.read_text())["skipped_invalid"] == 4
    assert "measurements.csv:6: 4 measurement(s) with a range <= 0" in err


def test_run_refuses_simulation_options_on_a_bundle(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    for argv in (["--noise", "c"], ["--rate", "3"], ["--corrupt", "0.5"], ["--noise-scale", "4"],
                 ["--noise", "a"]):  # fmt: skip
        assert main(["run", str(SIM_BUNDLE), "-o", str(tmp_path / "r"), "-q", *argv]) == 2
        assert f"only a simulated world takes {argv[0]}" in capsys.readouterr().err
    assert not (tmp_path / "r").exists()
    argv = ["run", "simple1", "-o", str(tmp_path / "w"), "--skip-invalid-measurements"]
    assert main(argv) == 2


@pytest.mark.slow
def test_run_says_what_seed_changes_on_a_bundle(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["run", str(SIM_BUNDLE), "-o", str(tmp_path / "r")]) == 0
    assert "--seed" not in capsys.readouterr().out
    assert main(["run", str(SIM_BUNDLE), "-o", str(tmp_path / "s"), "--seed", "3"]) == 0
    out = capsys.readouterr().out
    assert "note: --seed 3 draws other global relations" in out
    a = json.loads((tmp_path / "r" / "metrics.json").read_text())
    s = json.loads((tmp_path / "s" / "metrics.json").read_text())
    assert a["recovery"]["nis"] == s["recovery"]["nis"]  # the recovery does not depend on it


# ------------------------------------------------------------ per-step control covariance


def _write_step_covariances(b: Path, covs: np.ndarray) -> None:
    t = np.loadtxt(b / "controls.csv", delimiter=",", skiprows=1)[:, 0]
    rows = [",".join(f"{v:.17g}" for v in (ti, c[0, 0], c[0, 1], c[0, 2], c[1, 1], c[1, 2],
                                            c[2, 2])) for ti, c in zip(t, covs)]  # fmt: skip
    (b / "step_covariance.csv").write_text("t,cxx,cxy,cxt,cyy,cyt,ctt\n" + "\n".join(rows) + "\n")


def test_step_covariance_constant_equals_pose_noise(tmp_path: Path) -> None:
    """A ``step_covariance.csv`` whose every row is ``C`` recovers byte for byte what a body-
    frame ``pose_noise`` ``C`` recovers (the documented equivalence)."""
    c = np.array([[4e-4, 1e-5, 0.0], [1e-5, 1e-4, 2e-6], [0.0, 2e-6, 9e-5]])
    pn = _copy(tmp_path, "pn")
    motion = json.loads((pn / "bundle.json").read_text())["motion_model"]
    for k in ("sigma_v", "sigma_omega"):
        del motion[k]
    _set_manifest(pn, motion_model=motion | {"pose_noise": {"frame": "body", "covariance":
                                                            c.tolist()}})  # fmt: skip
    sc = _copy(tmp_path, "sc")
    _set_manifest(sc, motion_model=motion | {"step_covariance": {"frame": "body"}})
    k = np.loadtxt(sc / "controls.csv", delimiter=",", skiprows=1).shape[0]
    _write_step_covariances(sc, np.repeat(c[None], k, axis=0))
    assert _recovered(tmp_path, sc) == _recovered(tmp_path, pn)


def test_step_covariance_per_row_by_hand() -> None:
    """Each step gets its own row's covariance, ``f C_k`` for a piece covering the fraction
    ``f`` of row k; world frame: ``Rot(θ)ᵀ f C_k Rot(θ)`` at the dead-reckoning heading."""
    from recovery.bundle import Bundle
    from recovery.models import MotionModel, SensorModel
    from recovery.steps import build_steps

    c = np.stack([np.diag([1.0, 2.0, 3.0]), np.diag([4.0, 5.0, 6.0]) + 0.5 * np.eye(3)[[1, 0, 2]],
                  np.diag([7.0, 8.0, 9.0])])  # fmt: skip
    c[1, 2, 2] = 6.0
    th0 = 0.3

    def bundle(frame: str) -> Bundle:
        return Bundle(
            motion=MotionModel("velocity", step_covariance_frame=frame),
            sensor=SensorModel(0.1, 0.01),
            controls=np.array([[0.0, 1.0, 0.0], [1.0, 2.0, 0.0], [2.0, 0.0, 0.0]]),
            step_covariances=c,
            initial_pose=np.array([0.0, 0.0, th0]),
            measurement_times=np.array([1.25]),
            measurements=np.array([[1.0, 0.0]]),
            measurement_landmarks=np.array([0]),
            measurement_associated=np.array([False]),
            map_ids=np.array([0]),
            map_xy=np.array([[5.0, 5.0]]),
            map_marginals=np.zeros((1, 2, 2)),
        )

    body = build_steps(bundle("body")).sigma
    assert np.array_equal(body, np.stack([c[0], 0.25 * c[1], 0.75 * c[1]]))
    rot = np.array([[np.cos(th0), -np.sin(th0), 0], [np.sin(th0), np.cos(th0), 0], [0, 0, 1]])
    world = build_steps(bundle("world")).sigma
    want = np.stack([rot.T @ (f * c[k]) @ rot for k, f in ((0, 1.0), (1, 0.25), (1, 0.75))])
    assert np.allclose(world, want, rtol=1e-14, atol=1e-14)


def test_step_covariance_file_checked(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    b = _copy(tmp_path)
    motion = json.loads((b / "bundle.json").read_text())["motion_model"]
    for k in ("sigma_v", "sigma_omega"):
        del motion[k]
    _set_manifest(b, motion_model=motion | {"step_covariance": {"frame": "body"}})
    out = str(tmp_path / "x.txt")
    assert main(["recover", str(b), "-o", out, "-q"]) == 3
    assert "step_covariance.csv: missing required file" in capsys.readouterr().err
    k = np.loadtxt(b / "controls.csv", delimiter=",", skiprows=1).shape[0]
    _write_step_covariances(b, np.repeat(np.eye(3)[None], k - 1, axis=0))  # one row short
    assert main(["recover", str(b), "-o", out, "-q"]) == 3
    assert f"expected one row per row of controls.csv, at its times ({k} rows)" in (
        capsys.readouterr().err
    )
    bad = np.repeat(np.eye(3)[None], k, axis=0)
    bad[3, 0, 0] = -1.0
    _write_step_covariances(b, bad)
    assert main(["recover", str(b), "-o", out, "-q"]) == 3
    assert "step_covariance.csv:5:" in capsys.readouterr().err


# ------------------------------------------------------------------- the sensor's mounting


def test_conjugation_jacobian_by_finite_differences(rng: np.random.Generator) -> None:
    from recovery.mount import conjugation_jacobian
    from relation_metric import se2

    m = np.array([0.4, -0.2, 0.7])
    for u in rng.normal(0.0, [0.5, 0.2, 0.3], size=(5, 3)):

        def f(v: np.ndarray) -> np.ndarray:
            return se2.compose(se2.inverse(m), se2.compose(v, m))

        num = np.column_stack([(f(u + h) - f(u - h)) / 2e-6 for h in 1e-6 * np.eye(3)])
        assert np.allclose(conjugation_jacobian(u, m), num, atol=1e-8)


def _mounted_bundle(mount: np.ndarray, stated: np.ndarray | None):  # type: ignore[no-untyped-def]
    """sim-bundle's log and truth; the true landmarks as an exact map; noise-free range-
    bearing measurements taken by a sensor at ``truth ∘ mount`` (computed here by hand)."""
    from dataclasses import replace

    from recovery.models import SensorModel
    from slamrel.formats.bundle import read_bundle

    b = read_bundle(SIM_BUNDLE)
    ids, lm = b.landmarks_groundtruth
    g = b.groundtruth
    c, s = np.cos(g.poses[:, 2]), np.sin(g.poses[:, 2])
    sx = g.poses[:, 0] + c * mount[0] - s * mount[1]
    sy = g.poses[:, 1] + s * mount[0] + c * mount[1]
    sth = g.poses[:, 2] + mount[2]
    dx, dy = lm[None, :, 0] - sx[:, None], lm[None, :, 1] - sy[:, None]
    rng_ = np.hypot(dx, dy)
    k, j = np.nonzero(rng_ < 5.0)
    bearing = np.arctan2(dy[k, j], dx[k, j]) - sth[k]
    bearing = (bearing + np.pi) % (2 * np.pi) - np.pi
    sensor = SensorModel(1e-3, 1e-4, mount=None if stated is None else tuple(stated))
    return replace(
        b, sensor=sensor, map_xy=lm, map_ids=ids, map_marginals=np.zeros((ids.size, 2, 2)),
        map_covariance=None, measurement_times=g.timestamps[k],
        measurements=np.column_stack((rng_[k, j], bearing)), measurement_landmarks=ids[j],
        measurement_associated=np.ones(k.size, bool), measurement_lines=None, path=None,
    )  # fmt: skip


def test_mount_used_in_the_measurement_model() -> None:
    """Noise-free measurements of a sensor mounted at (0.3, 0.1, 0.2) in the robot frame:
    stated, the recovered robot poses match the truth (median 4e-5 m: what is left is the
    motion noise between sightings); unstated, they are off by about the mount's offset."""
    from recovery.recover import recover

    m = np.array([0.3, 0.1, 0.2])
    truth = _mounted_bundle(m, m).groundtruth.poses

    def error(stated: np.ndarray | None) -> float:
        rec = recover(_mounted_bundle(m, stated), method="filter", map_mode="ignore")
        return float(np.median(np.hypot(*(rec.trajectory.poses[:, :2] - truth[:, :2]).T)))

    assert error(m) < 1e-3
    assert error(None) > 0.1


# ------------------------------------------------------------------------------ the checks


@pytest.fixture(scope="module")
def client_bundle(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short recorded run of the textbook client with its quirks (distinct marginals, zero
    and singular online covariances, dropouts, a mount)."""
    import math

    from clients.export import recorder_for, write_recorded_bundle
    from clients.textbook_ekfslam import Config, run

    cfg = Config(steps=120, mount=(0.3, 0.1, math.radians(5.0)), motion_noise="control",
                 initial_variance=0.0, dropout=0.01)  # fmt: skip
    rec = recorder_for(cfg)
    r = run(0, cfg, recorder=rec)
    return write_recorded_bundle(r, rec, tmp_path_factory.mktemp("client") / "b")


def test_map_covariance_in_another_order_is_refused(
    tmp_path: Path, client_bundle: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    b = tmp_path / "perm"
    shutil.copytree(client_bundle, b)
    c = np.load(b / "map_covariance.npy")
    m = c.shape[0] // 2
    rows = np.stack([2 * np.arange(m)[::-1], 2 * np.arange(m)[::-1] + 1], 1).ravel()
    np.save(b / "map_covariance.npy", c[np.ix_(rows, rows)])  # landmarks in reverse order
    out = str(tmp_path / "x.txt")
    argv = ["recover", str(b), "-o", out, "-q", "--skip-invalid-measurements"]
    assert main(argv) == 3
    err = capsys.readouterr().err
    assert "map_covariance.npy: its diagonal block 0" in err and "map.csv's order" in err
    assert main(["recover", str(client_bundle), "-o", out, "-q",
                 "--skip-invalid-measurements"]) == 0  # fmt: skip


def test_map_without_covariance_is_reported_exact(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``map.csv`` with no covariance columns and no joint covariance: "exact", and the
    recovery is byte for byte that of ``--map-uncertainty ignore``."""
    b = _copy(tmp_path)
    (b / "map_covariance.npy").unlink()
    rows = [",".join(r.split(",")[:3]) for r in (b / "map.csv").read_text().splitlines()]
    (b / "map.csv").write_text("\n".join(rows) + "\n")
    report = tmp_path / "r.json"
    out = tmp_path / "a.txt"
    assert main(["recover", str(b), "-o", str(out), "--report", str(report)]) == 0
    assert "map uncertainty: exact" in capsys.readouterr().out
    assert json.loads(report.read_text())["map_uncertainty"] == "exact"
    ignore = tmp_path / "b.txt"
    assert main(["recover", str(b), "-o", str(ignore), "-q", "--map-uncertainty", "ignore"]) == 0
    assert out.read_bytes() == ignore.read_bytes()


def test_nees_reads_the_bundles_own_files(
    tmp_path: Path, client_bundle: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``slamrel nees BUNDLE/groundtruth.csv BUNDLE/online.csv``: the zero and singular
    online covariances are left out and counted; the rest is the same NEES as the se2-cov
    file of the remaining rows (written by hand)."""
    from slamrel.formats.bundle import read_online

    gt, on = client_bundle / "groundtruth.csv", client_bundle / "online.csv"
    a = tmp_path / "a.json"
    assert main(["nees", str(gt), str(on), "--json", str(a), "-q"]) == 0
    err = capsys.readouterr().err
    with pytest.warns(UserWarning):
        est = read_online(on)
    assert est.covariances is not None
    ok = np.linalg.eigvalsh(est.covariances)[:, 0] > 0
    assert f"online.csv:2: {int((~ok).sum())} of {ok.size} online pose" in err
    c = est.covariances[ok]
    iu = np.triu_indices(3)
    rows = np.column_stack((est.trajectory.timestamps[ok], est.trajectory.poses[ok],
                            c[:, iu[0], iu[1]]))  # fmt: skip
    hand = tmp_path / "online.se2cov"
    np.savetxt(hand, rows, fmt="%.17g")
    b = tmp_path / "b.json"
    assert main(["nees", str(gt), str(hand), "--json", str(b), "-q"]) == 0
    ja, jb = json.loads(a.read_text()), json.loads(b.read_text())
    assert ja["matched"] == jb["matched"] == int(ok.sum())
    assert ja["nees"] == jb["nees"]


def test_map_compare_leaves_out_landmarks_out_of_reach(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A reference landmark 40 m from every pose of sim-bundle's truth: missed without a
    reach, unobserved with ``--trajectory`` (file + ``--max-range``, or the bundle)."""
    ref = np.array([[100, 0.18, 1.39], [101, -0.68, 14.19], [102, 3.0, 0.5], [103, 40.0, 40.0]])
    (tmp_path / "ref.csv").write_text(
        "landmark,x,y\n" + "".join(f"{int(i)},{x:.17g},{y:.17g}\n" for i, x, y in ref)
    )
    (tmp_path / "est.csv").write_text(
        "landmark,x,y\n" + "".join(f"{int(i)},{x + 0.05:.17g},{y:.17g}\n" for i, x, y in ref[:3])
    )
    base = ["map-compare", str(tmp_path / "est.csv"), str(tmp_path / "ref.csv"), "-q"]
    got = {}
    for name, extra in (("none", []), ("file", ["--trajectory", str(SIM_BUNDLE /
                        "groundtruth.csv"), "--max-range", "5"]),
                        ("bundle", ["--trajectory", str(SIM_BUNDLE)])):  # fmt: skip
        out = tmp_path / f"{name}.json"
        assert main([*base, *extra, "--json", str(out)]) == 0
        got[name] = json.loads(out.read_text())["association"]
    assert got["none"]["missed_ids"] == [103] and got["none"]["unobserved"] == 0
    for name in ("file", "bundle"):
        assert got[name]["missed"] == 0 and got[name]["unobserved_ids"] == [103]
    assert main([*base, "--max-range", "5"]) == 2
    assert main([*base, "--trajectory", str(SIM_BUNDLE / "groundtruth.csv")]) == 2
    capsys.readouterr()


# ------------------------------------------------ frames, initialisation, time, sensor noise


def _empty_landmarks(b: Path, rows: set[int]) -> None:
    lines = (b / "measurements.csv").read_text().splitlines()
    for k in rows:
        f = lines[k + 1].split(",")
        f[3] = ""
        lines[k + 1] = ",".join(f)
    (b / "measurements.csv").write_text("\n".join(lines) + "\n")


def test_unprocessed_frames_and_initialising_measurements_used_as_stated(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``processed`` 0 rows and (``"initialisation": "initialises_only"``) each landmark's
    first measurement are not used: the recovery is byte for byte that of the bundle with
    those landmark cells emptied by hand, and both are counted apart."""
    b = _copy(tmp_path, "stated")
    _set_manifest(b, initialisation="initialises_only")
    lines = (b / "measurements.csv").read_text().splitlines()
    unprocessed = {0, 1, 2}
    lines = [lines[0] + ",processed"] + [
        ln + (",0" if k in unprocessed else ",1") for k, ln in enumerate(lines[1:])
    ]
    (b / "measurements.csv").write_text("\n".join(lines) + "\n")
    # by hand: the first processed measurement of each landmark, in time order (file order)
    seen: set[str] = set()
    first = set()
    for k, ln in enumerate(lines[1:]):
        lm = ln.split(",")[3]
        if k not in unprocessed and lm and lm not in seen:
            seen.add(lm)
            first.add(k)
    hand = _copy(tmp_path, "hand")
    _empty_landmarks(hand, unprocessed | first)
    report = tmp_path / "r.json"
    assert _recovered(tmp_path, b, "--report", str(report)) == _recovered(tmp_path, hand)
    r = json.loads(report.read_text())
    assert r["unprocessed"] == 3 and r["initialising"] == len(first) > 0


def test_time_as_step_index_and_sensor_noise_stated(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``"time": "steps"``: sim-bundle's 0.1 s rows as steps (t × 10, v and ω per step) give
    the same poses; a t that is no step index is refused at its line. ``sensor_model.noise``
    is reported as stated and changes nothing else."""
    from slamrel.formats.bundle import read_bundle

    b = _copy(tmp_path, "steps")
    _set_manifest(b, time="steps")
    ctl = np.loadtxt(b / "controls.csv", delimiter=",", skiprows=1)
    ctl = ctl * [10.0, 0.1, 0.1]
    (b / "controls.csv").write_text(
        "t,v,omega\n" + "".join(f"{round(t)},{v:.17g},{w:.17g}\n" for t, v, w in ctl)
    )
    meas = (b / "measurements.csv").read_text().splitlines()
    out = [meas[0]]
    for ln in meas[1:]:
        f = ln.split(",")
        f[0] = str(round(float(f[0]) * 10))
        out.append(",".join(f))
    (b / "measurements.csv").write_text("\n".join(out) + "\n")
    (b / "groundtruth.csv").unlink()
    motion = json.loads((b / "bundle.json").read_text())["motion_model"]
    per_step = {"sigma_v": motion["sigma_v"] * 0.1, "sigma_omega": motion["sigma_omega"] * 0.1}
    _set_manifest(b, motion_model=motion | per_step)
    steps = read_bundle(b)
    assert steps.time == "steps"
    seconds = read_bundle(SIM_BUNDLE)
    from recovery.recover import recover

    a, s = recover(steps, method="filter").trajectory, recover(seconds, method="filter").trajectory
    assert np.array_equal(a.timestamps, np.round(s.timestamps * 10))
    assert np.allclose(a.poses, s.poses, atol=1e-9)
    f = (b / "measurements.csv").read_text().splitlines()
    t_last = float(f[-1].split(",")[0]) + 0.5  # the last row: still in time order
    f[-1] = f"{t_last}" + f[-1][f[-1].index(",") :]
    (b / "measurements.csv").write_text("\n".join(f) + "\n")
    assert main(["recover", str(b), "-o", str(tmp_path / "x.txt"), "-q"]) == 3
    err = capsys.readouterr().err
    assert f"measurements.csv:{len(f)}: t = {t_last}: expected a step index" in err
    noise = _copy(tmp_path, "noise")
    sensor = json.loads((noise / "bundle.json").read_text())["sensor_model"]
    _set_manifest(noise, sensor_model=sensor | {"noise": "true"})
    report = tmp_path / "r.json"
    assert _recovered(tmp_path, noise, "--report", str(report)) == _recovered(tmp_path, SIM_BUNDLE)
    assert json.loads(report.read_text())["sensor_noise"] == "true"


@pytest.mark.parametrize("kw", [{}, {"process_noise_scale": 2.0}, {"noise_scale": 3.0}])
def test_slam_on_step_covariances_equals_pose_noise(kw: dict[str, float]) -> None:
    """slamrel's EKF-SLAM on a log whose every row states ``C`` maps exactly what it maps
    with ``pose_noise`` ``C``; its noise scales scale the stated ``C_k`` as they scale ``C``."""
    from dataclasses import replace

    from recovery.models import MotionModel
    from slamrel.backends.ekf_slam import ekf_slam_bundle
    from slamrel.formats.bundle import read_bundle

    b = read_bundle(SIM_BUNDLE)
    c = np.diag([4e-4, 1e-4, 9e-5])
    assert b.controls is not None
    pn = replace(b, motion=MotionModel("velocity", pose_noise_frame="body",
                                       pose_noise=tuple(map(tuple, c))))  # fmt: skip
    sc = replace(b, motion=MotionModel("velocity", step_covariance_frame="body"),
                 step_covariances=np.repeat(c[None], b.controls.shape[0], 0))  # fmt: skip
    (o1, _), (o2, _) = ekf_slam_bundle(pn, **kw), ekf_slam_bundle(sc, **kw)  # type: ignore[arg-type]
    assert np.array_equal(o1.map_xy, o2.map_xy)
    assert np.array_equal(o1.map_covariance, o2.map_covariance)
    assert o2.step_covariances is not None and o1.motion.pose_noise is not None
    assert np.allclose(o2.step_covariances, np.asarray(o1.motion.pose_noise), rtol=1e-15, atol=0)


def test_run_skips_and_counts_singular_online_covariances(
    tmp_path: Path, client_bundle: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``run`` on the recorded client (zero and singular online covariances at its start,
    dropouts): a report, the online NEES on the other poses, both counts in the notes."""
    from slamrel.formats.bundle import read_online

    with pytest.warns(UserWarning):
        on = read_online(client_bundle / "online.csv")
    assert on.covariances is not None
    singular = int((np.linalg.eigvalsh(on.covariances)[:, 0] <= 0).sum())
    assert singular > 0
    rep = tmp_path / "rep"
    assert main(["run", str(client_bundle), "-o", str(rep), "-q",
                 "--skip-invalid-measurements"]) == 0  # fmt: skip
    err = capsys.readouterr().err
    assert f"online.csv:2: {singular} online pose covariance(s) zero or singular" in err
    m = json.loads((rep / "metrics.json").read_text())
    notes = " ".join(m["notes"])
    assert f"online NEES: {singular} of {on.covariances.shape[0]} online poses" in notes
    assert "measurement(s) with a range <= 0" in notes
    assert m["nees"]["online"]["mean"] > 0
