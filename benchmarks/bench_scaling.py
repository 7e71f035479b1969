"""Scaling of ``recover``, ``slam`` and ``solve`` over sizes spanning 10×.

Each stage is timed (in process, best of ``--repeat``) at three sizes a factor √10 apart and
the exponent ``b`` of ``t ≈ a·size^b`` is fitted by least squares on the logs.

* ``recover`` (EKF localisation + RTS smoother, :func:`recovery.recover.recover`) on a
  simulated bundle (``bench_recovery.make_bundle``): 10⁴ … 10⁵ control steps, one
  measurement per 10 steps. Expected linear.
* ``slam`` (the reference EKF-SLAM, :func:`slamrel.backends.ekf_slam.ekf_slam_bundle`) on the built-in
  ``complex1`` world with 50 … 500 features. Each update is O(n²) in the state size
  n = 3 + 2L and the measurements grow with L too, so the time is expected to grow like
  L³ here; the constant printed is ns per covariance element per update.
* ``solve`` (``solve_graph_incremental``, the CLI default: 500 poses first, ×2) on the
  Manhattan-world pose graph of ``bench_least_squares`` with the grid side grown as √N (the
  same loop density): 10³ … 10⁴ poses. Sparse direct factorisation of a graph with 2-D loop
  structure costs O(N^1.5) flops (nested dissection bound; the separators are √N poses), so
  superlinear is expected.

Run: ``python benchmarks/bench_scaling.py``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

from bench_least_squares import manhattan  # noqa: E402
from bench_recovery import make_bundle  # noqa: E402
from timing import best_of  # noqa: E402

import slamrel.simulation.worlds as worlds  # noqa: E402
from recovery.recover import recover  # noqa: E402
from slamrel.backends.ekf_slam import ekf_slam_bundle  # noqa: E402
from slamrel.backends.least_squares import solve_graph_incremental  # noqa: E402
from slamrel.simulation.bundles import world_bundle  # noqa: E402


def exponent(sizes: list[float], times: list[float]) -> float:
    return float(np.polyfit(np.log(sizes), np.log(times), 1)[0])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=2)
    args = parser.parse_args()
    rows: list[tuple[str, str, list[float], list[float], str]] = []

    sizes = [10_000, 31_623, 100_000]
    times = []
    for steps in sizes:
        b = make_bundle(steps, steps // 10)
        times.append(best_of(lambda b=b: recover(b, method="smoother"), args.repeat))
    rows.append(("recover (smoother)", "control steps", sizes, times, ""))

    feats = [50, 158, 500]
    times, sizes = [], []
    consts = []
    saved = worlds.N_FEATURES
    try:
        for f in feats:
            worlds.N_FEATURES = f
            w = worlds.make_world("complex1", noise="a", seed=0)
            b = world_bundle(w)
            holder = {}

            def run(b=b, holder=holder):  # type: ignore[no-untyped-def]
                holder["r"] = ekf_slam_bundle(b)[1]

            t = best_of(run, 1)
            r = holder["r"]
            n = 3 + 2 * r.landmark_ids.size
            used = int((r.association >= 0).sum())
            times.append(t)
            sizes.append(float(r.landmark_ids.size))
            consts.append(t / (used * n * n) * 1e9)
    finally:
        worlds.N_FEATURES = saved
    note = "ns per element per update at the largest: " + f"{consts[-1]:.2f}"
    rows.append(("slam (EKF-SLAM)", "landmarks", sizes, times, note))

    poses = [1_000, 3_162, 10_000]
    times = []
    for n in poses:
        g = manhattan(n, size=max(8, round(40 * np.sqrt(n / 10_000))))
        times.append(best_of(lambda g=g: solve_graph_incremental(g, batch=500), 1))
    rows.append(("solve (LS, 500 x2)", "poses", poses, times, ""))

    print(f"{'stage':22s}{'size':>14s}{'times [s] at the three sizes':>34s}{'exponent':>10s}")
    for name, unit, s, t, note in rows:
        sz = f"{s[0]:.0f}..{s[-1]:.0f}"
        tt = "  ".join(f"{x:8.3f}" for x in t)
        print(f"{name:22s}{sz:>14s}  {tt:>32s}{exponent(s, t):10.2f}  ({unit}) {note}")


if __name__ == "__main__":
    main()
