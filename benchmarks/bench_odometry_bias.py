"""Benchmark: the cost of carrying the odometry's persisting error in the recovery (issue 36).

Run: ``SLAMREL_DATA=../shared/data python3 benchmarks/bench_odometry_bias.py [--robot 3]``.

Input: an MRCLAM dataset 7 robot imported as ``slamrel import mrclam`` does by default (the
measurements' and the odometry's persisting errors stated), its
:func:`recovery.recover.filter_input`. Measured in the same run, best of ``--repeat``, one
augmented filter pass and its smoother (:mod:`recovery.persisting`):

* baseline: the bundle's measurement biases only (``motion`` not passed: the recovery of the
  same bundle before 2026-12-07);
* ours: with the odometry bias ``o = [s, κ]`` (:mod:`recovery.odometry_bias`: two more states
  and the epochs it adds every ``min(1 s, τ/8)``).

Prints both CPU times, their ratio, and the epochs of each.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from timing import best_wall_cpu  # noqa: E402

from recovery.persisting import run_persisting, smooth_persisting  # noqa: E402
from recovery.recover import filter_input  # noqa: E402
from slamrel.importers.mrclam import mrclam_bundle  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robot", type=int, default=3)
    ap.add_argument("--repeat", type=int, default=2)
    a = ap.parse_args()
    data = Path(os.environ.get("SLAMREL_DATA", "../shared/data"))
    b = mrclam_bundle(data / "mrclam" / "MRCLAM_Dataset7", a.robot)
    inp = filter_input(b)
    pe, mp = b.sensor.persisting, b.motion.persisting
    assert pe is not None and mp is not None
    common = (
        {} if pe.common is None else {"common_sigma": pe.common.sigma, "common_tau": pe.common.tau}
    )

    def one(motion):  # type: ignore[no-untyped-def]
        run = run_persisting(inp, pe.sigma, pe.tau, motion=motion, **common)  # type: ignore[arg-type]
        smooth_persisting(run)
        return run

    base = best_wall_cpu(lambda: one(None), a.repeat)
    ours = best_wall_cpu(lambda: one(mp), a.repeat)
    print(f"MRCLAM dataset 7 robot {a.robot}: {inp.times.shape[0]} grid poses")
    print(
        f"baseline (measurement biases): {base.cpu:.2f} s CPU, {base.result.post_x.shape[0]} epochs"
    )
    print(
        f"ours (+ odometry bias): {ours.cpu:.2f} s CPU, {ours.result.post_x.shape[0]} epochs, "
        f"ratio {ours.cpu / base.cpu:.2f}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
