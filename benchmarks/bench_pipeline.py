"""``slamrel run`` on every built-in world × noise type: it finishes, and how long it takes.

Target: the default run (``slamrel run``: simple1, noise a) < 30 s on this machine.
Baseline printed beside it: the EKF-SLAM alone on the same world, measured in the same run.
Run: ``python benchmarks/bench_pipeline.py``.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from slamrel.backends.ekf_slam import ekf_slam_bundle  # noqa: E402
from slamrel.pipeline import run_pipeline, write_report  # noqa: E402
from slamrel.simulation.bundles import world_bundle  # noqa: E402
from slamrel.simulation.worlds import NOISE_TYPES, WORLDS, make_world  # noqa: E402


def main() -> None:
    print(
        f"{'world':10s}{'noise':>6s}{'run [s]':>10s}{'EKF-SLAM [s]':>14s}{'ratio':>8s}"
        f"{'recovered global [m]':>22s}{'dead reckoning [m]':>20s}"
    )
    for world in WORLDS:
        for noise in sorted(NOISE_TYPES):
            t = time.perf_counter()
            ekf_slam_bundle(world_bundle(make_world(world, noise=noise)))
            t_slam = time.perf_counter() - t
            t = time.perf_counter()
            with tempfile.TemporaryDirectory() as tmp:
                result = run_pipeline(world, noise=noise)
                write_report(result, Path(tmp) / "report")
            t_run = time.perf_counter() - t
            rec = result.recovered["global"].translation.abs.mean
            dr = result.dead_reckoning["global"].translation.abs.mean
            print(
                f"{world:10s}{noise:>6s}{t_run:10.2f}{t_slam:14.2f}{t_run / t_slam:8.1f}"
                f"{rec:22.4f}{dr:20.4f}"
            )
    print("target: the default run (simple1, a) < 30 s")


if __name__ == "__main__":
    main()
