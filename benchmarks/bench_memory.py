"""Peak memory of ``slamrel evaluate`` with the quadratic strategies at 10⁶ poses (issue 39).

``--strategy loops`` once grew to 23.7 GB on 10⁶ poses and ``all-pairs`` passed 6 GB on 10⁴;
both now hold a pair budget (``relation_metric.relations.MAX_RELATIONS``): a selection over it
is refused up front, saying why and what to change, and ``loops`` streams its candidates.

Each case runs ``python -m slamrel evaluate`` as a child of a fresh wrapper process and reads
the child's peak resident set size with ``resource.getrusage(RUSAGE_CHILDREN).ru_maxrss``.
Baseline, measured in the same run: ``--strategy consecutive`` (10⁶ relations) on the same
file. Target: every case under 2 GB (scored, or refused with exit 3 and a message).

Trajectories (TUM, written to a temp dir, estimate = reference + seeded noise):

* ``laps``: 10⁶ poses 0.1 m apart on a 50 m circle (318 laps): billions of pose pairs within
  1 m and 30 s apart — over the budget, refused;
* ``lanes``: 10⁶ poses 0.1 m apart on a lawnmower of 1,000 m lanes 0.98 m apart: a few
  million loop pairs — under the budget, scored.

Run: ``python benchmarks/bench_memory.py`` (about 2 minutes; ``--poses N`` for other sizes).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
LIMIT_MB = 2048.0

WRAPPER = (
    "import resource, subprocess, sys\n"
    "p = subprocess.run(sys.argv[1:], capture_output=True, text=True)\n"
    "err = p.stderr.strip().splitlines()\n"
    "print(p.returncode, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)\n"
    "print(err[-1] if err else '')\n"
)


def write_tum(path: Path, t: np.ndarray, x: np.ndarray, y: np.ndarray, th: np.ndarray) -> None:
    z = np.zeros_like(t)
    rows = np.column_stack((t, x, y, z, z, z, np.sin(th / 2), np.cos(th / 2)))
    np.savetxt(path, rows, fmt="%.6f")


def trajectories(folder: Path, n: int) -> dict[str, tuple[Path, Path]]:
    rng = np.random.default_rng(0)
    t = np.arange(n) * 0.1
    s = t * 1.0  # 1 m/s: 0.1 m between poses
    a = s / 50.0
    laps = (50 * np.cos(a), 50 * np.sin(a), a + np.pi / 2)
    lane = np.floor(s / 1000.0)
    along = s - 1000.0 * lane
    forward = lane % 2 == 0
    lanes = (np.where(forward, along, 1000.0 - along), 0.98 * lane, np.where(forward, 0.0, np.pi))
    out = {}
    for name, (x, y, th) in (("laps", laps), ("lanes", lanes)):
        ref, est = folder / f"{name}_ref.tum", folder / f"{name}_est.tum"
        write_tum(ref, t, x, y, th)
        noise = rng.normal(0.0, 0.01, (3, n))
        write_tum(est, t, x + noise[0], y + noise[1], th + noise[2])
        out[name] = (ref, est)
    return out


def peak(args: list[str]) -> tuple[int, float, float, str]:
    """Exit code, peak RSS [MB] and wall time [s] of ``slamrel ARGS``, its last stderr line."""
    start = time.perf_counter()
    cmd = [sys.executable, "-c", WRAPPER, sys.executable, "-m", "slamrel", *args]
    done = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, check=True)
    wall = time.perf_counter() - start
    first, message = (done.stdout.splitlines() + [""])[:2]
    code, kb = first.split()
    return int(code), int(kb) / 1024.0, wall, message


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=1_000_000)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        files = trajectories(Path(tmp), args.poses)
        laps, lanes = files["laps"], files["lanes"]
        cases = [
            ("baseline: consecutive, laps", ["--strategy", "consecutive", *laps]),
            ("loops, laps (over budget)", ["--strategy", "loops", *laps]),
            ("loops, lanes", ["--strategy", "loops", *lanes]),
            ("all-pairs, laps (over budget)", ["--strategy", "all-pairs", *laps]),
            (
                "random --count 5000000, lanes",
                ["--strategy", "random", "--count", "5000000", *lanes],
            ),
        ]
        print(f"{args.poses:,} poses; target: peak < {LIMIT_MB:.0f} MB, or refused up front")
        print(f"{'case':34s} {'exit':>4s} {'peak MB':>8s} {'× base':>7s} {'s':>6s}  target")
        base = None
        for name, cli in cases:
            code, mb, wall, message = peak(["evaluate", "-q", *cli])
            base = mb if base is None else base
            ok = "met" if mb < LIMIT_MB and code in (0, 3) else "MISSED"
            print(f"{name:34s} {code:4d} {mb:8.0f} {mb / base:7.2f} {wall:6.1f}  {ok}")
            if code:
                print(f"    {message[:300]}")


if __name__ == "__main__":
    main()
