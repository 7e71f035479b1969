"""The pose-only study command and the resumable sweep runner."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from slamrel.cli import main
from slamrel.studies.sweep import Task, format_progress, load_results, run_sweep

ROOT = Path(__file__).resolve().parent.parent
SMALL = ["--worlds", "hu-simple1", "--noise", "a", "--methods", "full,m1,m2"]


def _need_distributed() -> None:
    """dask[distributed] is in the test extra: missing is a failure under CI, else a skip."""
    try:
        import distributed  # noqa: F401
    except ImportError:
        message = "dask[distributed] not installed (pip install '.[test]' brings it)"
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(message)
        pytest.skip(message)


@pytest.mark.slow
def test_small_study_writes_tables_and_a_rerun_skips_everything(tmp_path, capsys):
    out = tmp_path / "study"
    assert main(["study", "pose-only", "--runs", "1", "-o", str(out), "-q", *SMALL]) == 0
    rows = list(csv.DictReader((out / "table.csv").open()))
    assert [r["method"] for r in rows] == ["full LS", "pose-only M1", "pose-only M2"]
    for r in rows:
        assert r["world"] == "hu-simple1" and r["runs"] == "1"
        assert r["gate1"] == "280.4"
    # the CSV agrees with the stored case results
    cases = sorted((out / "cases").glob("*.json"))
    assert len(cases) == 3
    full = next(json.loads(p.read_text())["result"] for p in cases if p.name.count("_full-"))
    assert rows[0]["nees1_mean"] == f"{full['nees1']:.1f}"
    assert (out / "fig1_sigma_bounds.png").stat().st_size > 0
    assert (out / "table.tex").read_text().startswith(r"\begin{tabular}")
    before = {p.name: p.read_bytes() for p in out.glob("table.*")}
    capsys.readouterr()
    assert main(["study", "pose-only", "--runs", "1", "-o", str(out), *SMALL]) == 0
    assert "0 run now, 3 already done, 0 failed" in capsys.readouterr().out
    assert {p.name: p.read_bytes() for p in out.glob("table.*")} == before


@pytest.mark.parametrize(
    "bad", [["--worlds", "mars"], ["--methods", "full,ekf"], ["--noise", "d"], ["--runs", "0"]]
)
def test_option_mistakes_are_usage_errors(tmp_path, capsys, bad):
    with pytest.raises(SystemExit) as exc:
        main(["study", "pose-only", "-o", str(tmp_path / "x"), *bad])
    assert exc.value.code == 2
    assert not (tmp_path / "x").exists()


def test_sweep_records_failures_and_goes_on(tmp_path):
    good = [Task(f"ok{k}", "json:loads", {"s": json.dumps({"k": k})}) for k in range(3)]
    bad = Task("bad", "json:loads", {"s": "{"})
    rep = run_sweep([*good, bad], tmp_path, workers=2)
    assert (rep.ran, rep.skipped, rep.failed) == (4, 0, (bad.key,))
    err = json.loads((tmp_path / f"{bad.key}.error.json").read_text())
    assert err["error"].startswith("JSONDecodeError")
    assert [r["result"]["k"] for r in load_results(tmp_path, good)] == [0, 1, 2]
    # a re-run retries only the failed task
    rep = run_sweep([*good, bad], tmp_path)
    assert (rep.ran, rep.skipped) == (1, 3)
    assert "ETA ?" in format_progress(0, 5, 0, 1.0)
    assert (
        format_progress(2, 4, 1, 130.0) == "2/4 done, 1 failed, 2 min 10 s elapsed, ETA 2 min 10 s"
    )


@pytest.mark.slow
def test_killed_study_resumes_to_the_same_tables_byte_for_byte(tmp_path):
    args = ["study", "pose-only", "--runs", "2", *SMALL, "-q"]
    main([*args, "-o", str(tmp_path / "straight")])
    env = dict(os.environ, PYTHONPATH=str(ROOT), MPLBACKEND="Agg")
    killed = tmp_path / "killed"
    proc = subprocess.Popen([sys.executable, "-m", "slamrel", *args, "-o", str(killed)], env=env)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and len(list((killed / "cases").glob("*.json"))) < 2:
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    done = list((killed / "cases").glob("*.json"))
    assert 2 <= len(done) < 6 and not (killed / "table.csv").exists()
    for p in done:  # whole results only
        assert json.loads(p.read_text())["result"]["nees1"] > 0
    assert main([*args, "-o", str(killed)]) == 0
    assert not list((killed / "cases").glob(".*.tmp"))
    for name in ("table.md", "table.csv", "table.tex"):
        assert (killed / name).read_bytes() == (tmp_path / "straight" / name).read_bytes()


def _wait_for(predicate, seconds=120.0):
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.1)
    return False


@pytest.mark.slow
def test_study_on_a_local_dask_cluster_killed_and_resumed(tmp_path):
    _need_distributed()
    args = ["study", "pose-only", "--runs", "2", *SMALL, "-q"]
    main([*args, "-o", str(tmp_path / "straight")])
    env = dict(os.environ, PYTHONPATH=str(ROOT), MPLBACKEND="Agg")
    killed = tmp_path / "killed"
    dask_args = [*args, "--scheduler", "local", "--workers", "2", "-o", str(killed)]
    proc = subprocess.Popen(
        [sys.executable, "-m", "slamrel", *dask_args], env=env, start_new_session=True
    )
    _wait_for(lambda: len(list((killed / "cases").glob("*.json"))) >= 2)
    os.killpg(proc.pid, signal.SIGKILL)  # the client and the cluster it started
    proc.wait()
    assert len(list((killed / "cases").glob("*.json"))) < 6
    done = subprocess.run(
        [sys.executable, "-m", "slamrel", *dask_args], env=env, capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr
    for name in ("table.md", "table.csv", "table.tex"):
        assert (killed / name).read_bytes() == (tmp_path / "straight" / name).read_bytes()


@pytest.mark.slow
def test_study_on_a_separately_started_dask_scheduler_and_worker(tmp_path):
    _need_distributed()
    env = dict(os.environ, PYTHONPATH=str(ROOT), MPLBACKEND="Agg")
    sched_file = tmp_path / "scheduler.json"
    procs = [
        subprocess.Popen(
            [
                sys.executable,
                "-m",
                "distributed.cli.dask_scheduler",
                "--scheduler-file",
                str(sched_file),
                "--port",
                "0",
                "--dashboard-address",
                ":0",
            ],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )  # fmt: skip
    ]
    try:
        assert _wait_for(sched_file.exists, 60)
        procs.append(
            subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "distributed.cli.dask_worker",
                    "--scheduler-file",
                    str(sched_file),
                    "--nthreads",
                    "1",
                    "--dashboard-address",
                    ":0",
                ],
                env=env,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            )  # fmt: skip
        )
        address = json.loads(sched_file.read_text())["address"]
        out = tmp_path / "remote"
        rc = main(["study", "pose-only", "--runs", "1", *SMALL, "-q", "-o", str(out),
                   "--scheduler", address])  # fmt: skip
        assert rc == 0
        local = tmp_path / "local"
        assert main(["study", "pose-only", "--runs", "1", *SMALL, "-q", "-o", str(local)]) == 0
        assert (out / "table.csv").read_bytes() == (local / "table.csv").read_bytes()
    finally:
        for p in reversed(procs):
            p.terminate()
            p.wait(timeout=30)


def test_findings_are_judged_on_paired_intervals_over_runs():
    from slamrel.studies.pose_only import findings, interval_half_width, summary_rows

    jitter = (-1.0, 0.0, 1.0, 0.0)  # per-seed offsets: known sample standard deviations

    def case(noise, method, seed, nees1, rmse, n2, n3):
        d = jitter[seed]
        return {"world": "w", "noise": noise, "method": method, "seed": seed,
                "nees1": nees1 + 10 * d, "gate1": 280.4, "nees2": n2 + d, "dof2": 100,
                "nees3": n3 + d, "dof3": 400, "landmark_nees": 50.0, "landmark_gate": 60.0,
                "rmse_xy": rmse + 0.01 * d, "rmse_theta": 0.01, "seconds": 1.0}  # fmt: skip

    results = []
    for noise in ("a", "c"):
        for seed in range(4):
            # TORO's NEES1 against M2: clearly higher under a; under c it swings by ±60
            # around M2's, so the paired interval contains 0
            toro = 300.0 if noise == "a" else 150.0 + 60 * (-1) ** seed
            results += [
                case(noise, "full", seed, 240.0, 0.1, 200.0, 400.0),
                case(noise, "m1", seed, 130.0, 0.5, 250.0, 420.0),
                case(noise, "m2", seed, 150.0, 0.12 if noise == "a" else 0.3, 300.0, 410.0),
                case(noise, "toro", seed, toro, 0.3, 400.0, 430.0),
            ]
    rows = summary_rows(results)
    full_a = rows[0]
    # the interval by hand: s = sqrt(2/3)·10 over 4 runs, t(0.975, 3) = 3.182446
    assert full_a["nees1_ci"] == pytest.approx(3.182446 * 10 * (2 / 3) ** 0.5 / 2, rel=1e-6)
    assert interval_half_width([5.0]) == 0.0
    got = {title.split(" (")[0]: (v, ev) for title, v, ev in findings(rows)}
    assert got["full LS and pose-only M2 pass the NEES1 gate in most runs"][0] is True
    verdict, ev = got["pose-only M2 is far more accurate than M1"]
    assert verdict is False and ev.startswith("fails in 1/2 groups")
    assert "w/c: M1 0.500 ± 0.013 m, M2 0.300 ± 0.013 m (fails" in ev
    verdict, ev = got["TORO is less consistent than pose-only LS"]
    assert verdict is None and ev.startswith("undecided in 1/2 groups")
    assert "w/a: M2 150 ± 13, TORO 300 ± 13 (holds" in ev
    for label in ("NEES2", "NEES3"):
        assert got[f"{label} orders full LS below pose-only M2"][0] is True
        assert got[f"{label} orders pose-only M2 below TORO"][0] is True


def test_the_study_folder_is_reused_only_when_it_is_a_study_folder(tmp_path, capsys):
    """The resumable output rule: foreign or other slamrel folders are refused before work."""
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine\n")
    assert main(["study", "pose-only", "--runs", "1", "-o", str(foreign), "-q", *SMALL]) == 3
    assert "not a pose-only-study folder" in capsys.readouterr().err
    assert sorted(p.name for p in foreign.iterdir()) == ["notes.txt"]
    other = tmp_path / "example"
    assert main(["example", "-o", str(other), "-q"]) == 0
    before = sorted(p.name for p in other.iterdir())
    assert main(["study", "pose-only", "--runs", "1", "-o", str(other), "-q", *SMALL]) == 3
    assert "says example" in capsys.readouterr().err
    assert sorted(p.name for p in other.iterdir()) == before
    assert main(["study", "pose-only", "--runs", "1", "-o", str(tmp_path), "-q", *SMALL]) == 3
