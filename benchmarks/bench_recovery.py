"""Benchmark: EKF localisation + RTS smoother vs a per-step filterpy EKF loop.

Run: ``python3 benchmarks/bench_recovery.py [--steps 100000] [--measurements 10000]``.

Input: a simulated bundle about the size of one MRCLAM robot (100,000 velocity-control steps,
10,000 range-bearing measurements, at times between control rows so the grid also splits
rows). Measured in the same run:

* baseline: :func:`recovery.baseline.filterpy_localisation` (filterpy ``ExtendedKalmanFilter``
  predicted every step, updated with every measurement through ``update`` with a wrapping
  residual);
* ours: :func:`recovery.ekf.run_filter` + :func:`recovery.smoother.smooth`;
* also peak memory (tracemalloc) of ours;
* batch recovery (:func:`recovery.batch_refinement.refine` from the smoothed trajectory, its covariance
  pass included; ``slamrel recover --method batch`` runs filter + smoother + this): its time
  over filter + smoother's, and — with ``--scaling`` — both at three sizes a factor √10 apart
  (``steps/10 … steps``) with the exponent ``b`` of ``t ≈ a·steps^b`` fitted on the logs.

Targets: ours ≤ 1/20 of the baseline's time; batch ≤ 3× filter + smoother, and linear.
Prints the ratios and checks that both filters agree.
"""

from __future__ import annotations

import argparse
import sys
import time
import tracemalloc
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from timing import best_wall_cpu  # noqa: E402

from recovery.baseline import filterpy_localisation  # noqa: E402
from recovery.batch_refinement import refine  # noqa: E402
from recovery.ekf import USED, run_filter  # noqa: E402
from recovery.recover import filter_input  # noqa: E402
from recovery.smoother import smooth  # noqa: E402
from relation_metric import se2  # noqa: E402
from slamrel.simulation.bundles import simulate_bundle  # noqa: E402


def make_bundle(steps: int, measurements: int, seed: int = 7):  # type: ignore[no-untyped-def]
    b = simulate_bundle(
        seed,
        steps=steps,
        landmarks=steps // 50,
        measure_every=10,
        max_range=5.0,
        measurement_offset=0.5,
    )
    rng = np.random.default_rng(seed)
    n = b.measurement_times.shape[0]
    keep = np.sort(rng.choice(n, size=min(measurements, n), replace=False))
    return replace(
        b,
        measurement_times=b.measurement_times[keep],
        measurements=b.measurements[keep],
        measurement_landmarks=b.measurement_landmarks[keep],
        measurement_associated=b.measurement_associated[keep],
        measurement_lines=None,
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=100_000)
    ap.add_argument("--measurements", type=int, default=10_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--scaling", action="store_true", help="batch vs smoother at 3 sizes")
    args = ap.parse_args()

    bundle = make_bundle(args.steps, args.measurements)
    # the exact map: the filterpy baseline is the plain EKF (no Schmidt update of a map
    # covariance), so the two filters are the same estimator and their results are compared
    inp = filter_input(bundle, map_mode="ignore")
    n, j = inp.times.shape[0], inp.meas_grid.shape[0]
    print(f"grid poses {n}, control rows {args.steps}, measurements {j}")

    ours = best_wall_cpu(lambda: (lambda f: (f, smooth(f)))(run_filter(inp)), args.repeat)
    t_ours, (fr, sm) = ours.wall, ours.result
    t_filter = best_wall_cpu(lambda: run_filter(inp), args.repeat).wall
    t0 = time.perf_counter()
    base_poses, base_covs, _ = filterpy_localisation(inp)
    t_base = time.perf_counter() - t0

    d = se2.minus(fr.poses, base_poses)
    print(
        f"max |pose - filterpy| {np.abs(d).max():.2e}, max |P - filterpy| "
        f"{np.abs(fr.covariances - base_covs).max():.2e}"
    )
    print(f"filterpy per-step loop   {t_base:8.3f} s  ({1e6 * t_base / n:.1f} µs / grid step)")
    print(f"ours: filter             {t_filter:8.3f} s")
    print(f"ours: filter + smoother  {t_ours:8.3f} s")
    ratio = t_ours / t_base
    print(
        f"ratio (filter + smoother) / filterpy = {ratio:.4f} = 1/{1 / ratio:.1f} "
        f"(target <= 1/20: {'met' if ratio <= 1 / 20 else 'NOT met'})"
    )

    tracemalloc.start()
    f = run_filter(inp)
    smooth(f)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    print(f"peak memory (tracemalloc) filter + smoother: {peak / 2**20:.1f} MiB")

    batch = best_wall_cpu(lambda: refine(inp, sm.poses, used=fr.status == USED), args.repeat)
    t_batch, br = batch.wall, batch.result
    ratio_b = t_batch / t_ours
    ratio_cpu = batch.cpu / ours.cpu
    print(
        f"batch refinement (LM, banded Cholesky): {t_batch:.3f} s, {br.iterations} iterations; "
        f"batch / (filter + smoother) = {ratio_b:.2f} (target <= 3: "
        f"{'met' if ratio_b <= 3 else 'NOT met'}); CPU {batch.cpu:.3f} s vs "
        f"{ours.cpu:.3f} s = {ratio_cpu:.2f}, cost {br.cost_final:.10f}"
    )
    gt = bundle.groundtruth
    idx = np.searchsorted(inp.times, gt.timestamps)
    for name, p in (("filter", fr.poses), ("smoother", sm.poses), ("batch", br.poses)):
        e = p[idx, :2] - gt.poses[:, :2]
        print(f"  position RMSE {name:9s} {np.sqrt(np.mean(np.sum(e * e, axis=1))):.4f} m")
    if args.scaling:
        scaling(args.steps, args.repeat)
    return 0


def time_batch(bundle, repeat: int):  # type: ignore[no-untyped-def]
    """Best times (:class:`timing.Timed`) of filter + smoother and of the batch refinement
    from its result."""
    # the exact map, as in main(): with the map's covariance (2,000 landmarks at 10^5 steps)
    # the joint problem's dense map terms would need 41 GB (recovery.batch_refinement.check_joint_size)
    inp = filter_input(bundle, map_mode="ignore")
    fs = best_wall_cpu(lambda: (lambda f: (f, smooth(f)))(run_filter(inp)), repeat)
    fr, sm = fs.result
    return fs, best_wall_cpu(lambda: refine(inp, sm.poses, used=fr.status == USED), repeat)


def scaling(steps: int, repeat: int) -> None:
    """Filter + smoother and batch at ``steps/10, steps/√10, steps``; fitted exponents."""
    sizes = [int(round(steps / 10 ** (k / 2))) for k in (2, 1, 0)]
    rows = []
    for size in sizes:
        fs, b = time_batch(make_bundle(size, size // 10), repeat)
        t_fs, t_b, br = fs.wall, b.wall, b.result
        rows.append((size, t_fs, t_b, br.iterations))
        print(
            f"  steps {size:7d}: filter + smoother {t_fs:7.3f} s, batch {t_b:7.3f} s "
            f"({br.iterations} it, {1e3 * t_b / br.iterations:.1f} ms/it), ratio {t_b / t_fs:.2f}; "
            f"CPU {fs.cpu:.3f} / {b.cpu:.3f} s, ratio {b.cpu / fs.cpu:.2f}"
        )
    x = np.log([r[0] for r in rows])
    fit = {
        name: float(np.polyfit(x, np.log(col), 1)[0])
        for name, col in (
            ("filter + smoother", [r[1] for r in rows]),
            ("batch", [r[2] for r in rows]),
            ("batch per iteration", [r[2] / r[3] for r in rows]),
        )
    }
    print("  exponents over 10x steps: " + ", ".join(f"{k} {v:.2f}" for k, v in fit.items()))


if __name__ == "__main__":
    sys.exit(main())
