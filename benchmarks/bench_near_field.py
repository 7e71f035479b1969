"""Benchmark: the cost of ordering each epoch's near-field measurements last (issue 36).

Run: ``python3 benchmarks/bench_near_field.py [--world complex1 --noise b --seed 72]``.

Input: the reference EKF-SLAM run (``--jacobians oc``) of a built-in world, its bundle's
:func:`recovery.recover.filter_input` (joint map covariance: the Schmidt filter). Measured in
the same run, best of ``--repeat``:

* baseline: :func:`recovery.ekf.run_filter` with ``recovery.ekf._linear_first`` replaced by a
  no-op (the measurements in the input's order, the filter before issue 36);
* ours: :func:`recovery.ekf.run_filter` as it is.

Prints both CPU times, their ratio, and how many measurements were moved.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from timing import best_wall_cpu  # noqa: E402

import recovery.ekf as ekf  # noqa: E402
from recovery.recover import filter_input  # noqa: E402
from slamrel.pipeline import simulate_run_input  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--world", default="complex1")
    ap.add_argument("--noise", default="b")
    ap.add_argument("--seed", type=int, default=72)
    ap.add_argument("--repeat", type=int, default=5)
    a = ap.parse_args()
    run = simulate_run_input(a.world, noise=a.noise, seed=a.seed, jacobians="oc")
    inp = filter_input(run.bundle)
    ours = best_wall_cpu(lambda: ekf.run_filter(inp), a.repeat)
    keep = ekf._linear_first
    ekf._linear_first = lambda *args: None  # type: ignore[assignment]
    try:
        base = best_wall_cpu(lambda: ekf.run_filter(inp), a.repeat)
    finally:
        ekf._linear_first = keep  # type: ignore[assignment]
    moved = int((np.asarray(ours.result.order) != np.asarray(base.result.order)).sum())  # type: ignore[attr-defined]
    print(
        f"{a.world}/{a.noise}/seed {a.seed}: {inp.meas_grid.shape[0]} measurements, {moved} moved"
    )
    print(f"baseline (input order): {base.cpu:.4f} s CPU")
    print(f"ours (near field last): {ours.cpu:.4f} s CPU  ratio {ours.cpu / base.cpu:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
