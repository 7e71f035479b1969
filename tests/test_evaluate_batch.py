"""``slamrel batch``: many runs through the resumable sweep, one table over runs."""

from __future__ import annotations

import csv
import json
import os
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from slamrel.cli import main
from slamrel.evaluation import evaluate_files

ROOT = Path(__file__).resolve().parent.parent


def _make_runs(root: Path, n_runs: int, poses: int, seed: int = 0) -> Path:
    """Seeded planar runs (t x y θ) and their manifest: 2 datasets × 2 algorithms."""
    rng = np.random.default_rng(seed)
    root.mkdir(parents=True, exist_ok=True)
    lines = ["name,reference,estimate,dataset,algorithm"]
    t = np.arange(poses) * 0.1
    for k in range(n_runs):
        th = np.cumsum(rng.normal(0, 0.05, poses))
        xy = np.cumsum(np.column_stack((np.cos(th), np.sin(th))) * 0.5, axis=0)
        ref = np.column_stack((t, xy, th))
        est = ref + np.column_stack(
            (np.zeros(poses), rng.normal(0, 0.02 * (1 + k % 3), (poses, 3)))
        )
        np.savetxt(root / f"ref{k}.txt", ref, fmt="%.9f")
        np.savetxt(root / f"est{k}.txt", est, fmt="%.9f")
        lines.append(f"r{k:03d},ref{k}.txt,est{k}.txt,d{k % 2},a{(k // 2) % 2}")
    (root / "runs.csv").write_text("\n".join(lines) + "\n")
    return root / "runs.csv"


def _table(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_batch_table_equals_evaluate_per_run_and_hand_statistics(tmp_path, capsys):
    manifest = _make_runs(tmp_path / "runs", 100, 40)
    out = tmp_path / "batch"
    assert main(["batch", str(manifest), "-o", str(out), "--workers", "0", "--step", "2"]) == 0
    assert "100 runs (100 run now, 0 already done, 0 failed)" in capsys.readouterr().out
    rows = _table(out / "table.csv")
    runs = [r for r in rows if r["kind"] == "run"]
    assert [r["name"] for r in runs] == [f"r{k:03d}" for k in range(100)]
    for k in (0, 37, 99):  # each run as slamrel evaluate scores it
        ev = evaluate_files(
            tmp_path / "runs" / f"ref{k}.txt", tmp_path / "runs" / f"est{k}.txt", step=2
        )
        assert float(runs[k]["trans_mean"]) == ev.translation.abs.mean
        assert int(runs[k]["relations"]) == len(ev.relations) == 38
    # the group statistics by hand (statistics module: sample std, n - 1)
    for d, a in (("d0", "a0"), ("d1", "a1")):
        vals = [float(r["trans_rmse"]) for r in runs if (r["dataset"], r["algorithm"]) == (d, a)]
        stats = {
            r["kind"]: r
            for r in rows
            if r["kind"] != "run" and (r["dataset"], r["algorithm"]) == (d, a)
        }
        assert stats["mean"]["name"] == str(len(vals)) == "25"
        assert float(stats["mean"]["trans_rmse"]) == pytest.approx(
            statistics.fmean(vals), rel=1e-12
        )
        assert float(stats["std"]["trans_rmse"]) == pytest.approx(statistics.stdev(vals), rel=1e-9)
        assert float(stats["max"]["trans_rmse"]) == max(vals)
    # the per-relation CSV is evaluate's --per-relation, byte for byte (compare's input)
    mine = tmp_path / "mine.csv"
    assert (
        main(
            [
                "evaluate",
                str(tmp_path / "runs" / "ref37.txt"),
                str(tmp_path / "runs" / "est37.txt"),
                "--step",
                "2",
                "--per-relation",
                str(mine),
                "-q",
            ]
        )
        == 0
    )
    assert (out / "per_relation" / "r037.csv").read_bytes() == mine.read_bytes()
    # run again: everything skipped, the same table
    before = (out / "table.csv").read_bytes()
    assert main(["batch", str(manifest), "-o", str(out), "--workers", "0", "--step", "2"]) == 0
    assert "(0 run now, 100 already done" in capsys.readouterr().out
    assert (out / "table.csv").read_bytes() == before
    # an edited estimate is scored again (its digest is part of the key)
    est = tmp_path / "runs" / "est5.txt"
    data = np.loadtxt(est)
    data[:, 1] += 1e-3
    np.savetxt(est, data, fmt="%.9f")
    assert main(["batch", str(manifest), "-o", str(out), "--workers", "0", "--step", "2"]) == 0
    assert "(1 run now, 99 already done" in capsys.readouterr().out


def test_a_folder_of_runs_and_manifest_mistakes(tmp_path, capsys):
    for k in range(3):
        d = tmp_path / "runs" / f"run{k}"
        d.mkdir(parents=True)
        t = np.arange(20) * 0.1
        traj = np.column_stack((t, t, np.zeros(20), np.zeros(20)))
        np.savetxt(d / "reference.txt", traj, fmt="%.9f")
        traj[:, 2] += 0.01 * k * t
        if k == 1:  # a pose written twice: dropped and warned about, counted in the table
            traj = np.vstack((traj[:5], traj[4:]))
        np.savetxt(d / "estimate.txt", traj, fmt="%.9f")
    assert (
        main(["batch", str(tmp_path / "runs"), "-o", str(tmp_path / "b"), "--workers", "0", "-q"])
        == 0
    )
    rows = [r for r in _table(tmp_path / "b" / "table.csv") if r["kind"] == "run"]
    assert [r["name"] for r in rows] == ["run0", "run1", "run2"]
    assert float(rows[0]["trans_mean"]) == 0.0 and float(rows[2]["trans_mean"]) > 0.0
    assert [r["warnings"] for r in rows] == ["0", "1", "0"]
    # --ate: the RMSEs evaluate --ate gives; the table feeds compare
    assert (
        main(
            [
                "batch",
                str(tmp_path / "runs"),
                "-o",
                str(tmp_path / "ba"),
                "--workers",
                "0",
                "--ate",
                "-q",
            ]
        )
        == 0
    )
    rows = [r for r in _table(tmp_path / "ba" / "table.csv") if r["kind"] == "run"]
    js = tmp_path / "e.json"
    run2 = tmp_path / "runs" / "run2"
    assert (
        main(
            [
                "evaluate",
                str(run2 / "reference.txt"),
                str(run2 / "estimate.txt"),
                "--ate",
                "--json",
                str(js),
                "-q",
            ]
        )
        == 0
    )
    ate = json.loads(js.read_text())["ate"]
    assert float(rows[2]["ate_rigid_rmse"]) == ate["se2"]["translation"]["rmse"]
    assert float(rows[2]["ate_none_rmse"]) == ate["none"]["translation"]["rmse"]
    per = tmp_path / "ba" / "per_relation"
    assert (
        main(
            [
                "compare",
                f"d:a={per / 'run1.csv'}",
                f"d:b={per / 'run2.csv'}",
                "-o",
                str(tmp_path / "cmp"),
                "-q",
            ]
        )
        == 0
    )
    assert (tmp_path / "cmp" / "table.csv").is_file()
    bad = tmp_path / "bad.csv"
    bad.write_text("name,reference,estimate\nr1,a.txt,b.txt\nr1,c.txt,d.txt\n")
    assert main(["batch", str(bad), "-o", str(tmp_path / "c")]) == 3
    err = capsys.readouterr().err
    assert "bad.csv:3" in err and "repeats line 2" in err


@pytest.mark.slow
def test_batch_on_a_local_dask_cluster_killed_and_resumed(tmp_path):
    try:
        import distributed  # noqa: F401
    except ImportError:
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail("dask[distributed] not installed (the test extra brings it)")
        pytest.skip("dask[distributed] not installed (pip install '.[test]' brings it)")
    manifest = _make_runs(tmp_path / "runs", 100, 1500)
    args = ["batch", str(manifest), "--step", "3", "-q"]
    assert main([*args, "--workers", "0", "-o", str(tmp_path / "straight")]) == 0
    env = dict(os.environ, PYTHONPATH=str(ROOT), MPLBACKEND="Agg")
    killed = tmp_path / "killed"
    dask_args = [*args, "--scheduler", "local", "--workers", "2", "-o", str(killed)]
    proc = subprocess.Popen(
        [sys.executable, "-m", "slamrel", *dask_args], env=env, start_new_session=True
    )
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and len(list((killed / "cases").glob("*.json"))) < 3:
        time.sleep(0.02)
    os.killpg(proc.pid, signal.SIGKILL)  # the client and the cluster it started
    proc.wait()
    done = len(list((killed / "cases").glob("*.json")))
    print(f"killed after {done} of 100 runs")
    assert 3 <= done < 100 and not (killed / "table.csv").exists()
    again = subprocess.run(
        [sys.executable, "-m", "slamrel", *dask_args],
        env=env,
        capture_output=True,
        text=True,
    )
    assert again.returncode == 0, again.stderr
    for name in ("table.csv", "table.md"):
        assert (killed / name).read_bytes() == (tmp_path / "straight" / name).read_bytes()
    for k in (0, 50, 99):
        rel = f"per_relation/r{k:03d}.csv"
        assert (killed / rel).read_bytes() == (tmp_path / "straight" / rel).read_bytes()


def test_batch_kitti_drift_and_time_window_equal_evaluate(tmp_path):
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import kitti_sim

    for k in range(2):
        d = tmp_path / "runs" / f"seq{k}"
        d.mkdir(parents=True)
        gt, est = kitti_sim.drive(seed=k, frames=400)
        kitti_sim.write_kitti(d / "reference.txt", gt)
        kitti_sim.write_kitti(d / "estimate.txt", est)
    opts = ["--t-start", "30", "--t-end", "350"]  # KITTI without times.txt: t = frame index
    assert main(["batch", str(tmp_path / "runs"), "-o", str(tmp_path / "b"), "--workers", "0",
                 "--kitti-drift", *opts, "-q"]) == 0  # fmt: skip
    rows = [r for r in _table(tmp_path / "b" / "table.csv") if r["kind"] == "run"]
    for k, row in enumerate(rows):
        d = tmp_path / "runs" / f"seq{k}"
        js = tmp_path / f"{k}.json"
        assert main(["evaluate", str(d / "reference.txt"), str(d / "estimate.txt"),
                     "--kitti-drift", *opts, "--json", str(js), "-q"]) == 0  # fmt: skip
        res = json.loads(js.read_text())
        assert float(row["drift_t_percent"]) == res["kitti_drift"]["translation_percent"]
        assert float(row["drift_r_deg_per_m"]) == res["kitti_drift"]["rotation_deg_per_m"]
        assert int(row["relations"]) == res["relations"] < 399  # the window cut the run
    assert main(["batch", str(tmp_path / "runs"), "-o", str(tmp_path / "c"), "--t-start", "9",
                 "--t-end", "1"]) == 2  # fmt: skip
