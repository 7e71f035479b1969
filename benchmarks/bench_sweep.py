"""Sweep throughput: 2 workers against 1 on the same study cases (target ≥ 1.7×).

Baseline: the same task list run by ``slamrel.studies.sweep.run_sweep`` with one worker process, in
the same run. Measured: two worker processes, and a 2-worker Dask ``LocalCluster`` when
``dask[distributed]`` is installed. Each configuration runs into a fresh folder (nothing is
skipped); the pool's start-up (spawning the workers, importing numpy/scipy) is included,
as a user sees it. The tasks are pose-only study cases of ``hu-simple1`` (full LS and pose-only
Method 2 under noise a and c), each a few tenths of a second.

Usage: ``python benchmarks/bench_sweep.py [--runs N]`` (default 20 runs per world/noise:
80 tasks; with 24 the pool start-up weighs ~1 s of 3). The 2-core machine must be
otherwise idle for the ratio to mean anything.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from slamrel.studies.pose_only import study_tasks  # noqa: E402
from slamrel.studies.sweep import run_sweep  # noqa: E402


def timed(tasks, **kwargs) -> float:  # type: ignore[no-untyped-def]
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        report = run_sweep(tasks, Path(tmp) / "cases", **kwargs)
        elapsed = time.perf_counter() - start
    assert report.ran == len(tasks) and not report.failed, report
    return elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=20)
    args = parser.parse_args()
    tasks = study_tasks(["hu-simple1"], ["a", "c"], args.runs, ["full", "m2"])
    n = len(tasks)
    one = timed(tasks, workers=1)
    two = timed(tasks, workers=2)
    print(f"sweep of {n} study cases (hu-simple1, noise a/c, full LS + pose-only M2)")
    print(f"  1 worker process : {one:7.2f} s  ({n / one:5.2f} tasks/s)  [baseline]")
    print(f"  2 worker processes: {two:7.2f} s  ({n / two:5.2f} tasks/s)  ratio {one / two:.2f}x")
    try:
        import distributed  # noqa: F401
    except ImportError:
        print("  Dask LocalCluster: skipped (pip install 'dask[distributed]')")
        return
    d1 = timed(tasks, workers=1, scheduler="local")
    d2 = timed(tasks, workers=2, scheduler="local")
    print(f"  Dask, 1 worker   : {d1:7.2f} s  ({n / d1:5.2f} tasks/s)  [baseline]")
    print(f"  Dask, 2 workers  : {d2:7.2f} s  ({n / d2:5.2f} tasks/s)  ratio {d1 / d2:.2f}x")
    print("target: 2 workers >= 1.7x the throughput of 1")


if __name__ == "__main__":
    main()
