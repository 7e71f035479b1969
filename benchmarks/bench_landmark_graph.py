"""Landmark-graph speed against named baselines measured in the same run.

1. Mesh + relations (edge lengths, corner angles) + statistics for 10^5 and 10^6 landmarks,
   as a ratio to
   ``scipy.spatial.Delaunay`` alone on the same points (the floor) — target ≤ 1.3×.
   Baseline and measured runs alternate (best of 5 at 10^5, of 2 at 10^6). The optional
   displacement errors are timed separately at 10^5 (no target).
2. Automatic association (seeded RANSAC on local descriptors + sparse optimal assignment) of
   10^4 landmarks after a rigid transform with 10% removed — target < 2 s.

Run: ``python benchmarks/bench_landmark_graph.py`` (``--small`` skips 10^6).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial import Delaunay

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from timing import best_of  # noqa: E402

from landmark_graph.landmark_association import associate_auto  # noqa: E402
from landmark_graph.maps import LandmarkMap  # noqa: E402
from landmark_graph.mesh import delaunay_mesh  # noqa: E402
from landmark_graph.mesh_relations import mesh_errors  # noqa: E402
from relation_metric import se2  # noqa: E402
from relation_metric.evaluate import error_summaries  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--small", action="store_true")
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    for n in (10**5,) if args.small else (10**5, 10**6):
        ref = rng.uniform(0, 1000, (n, 2))
        est = ref + rng.normal(0, 0.01, ref.shape)
        repeat = 5 if n <= 10**5 else 2

        def full(ref=ref, est=est, displacement=False) -> object:  # type: ignore[no-untyped-def]
            mesh = delaunay_mesh(ref)
            err = mesh_errors(est, ref, mesh, displacement=displacement)
            error_summaries(err.edge_length)
            error_summaries(err.corner_angle.ravel())
            if displacement:
                error_summaries(err.edge_displacement_triangle)
                error_summaries(err.edge_displacement_aligned)
            return mesh

        # baseline and measured runs alternate, so that load from other processes hits both
        floor = ours = with_disp = float("inf")
        for _ in range(repeat):
            floor = min(floor, best_of(lambda ref=ref: Delaunay(ref), 1))
            ours = min(ours, best_of(full, 1))
            if n <= 10**5:
                with_disp = min(with_disp, best_of(lambda: full(displacement=True), 1))
        mesh = full()
        floor_cpu = best_of(lambda ref=ref: Delaunay(ref), repeat, clock=time.process_time)
        ours_cpu = best_of(full, repeat, clock=time.process_time)
        print(
            f"n = {n:>8d}: mesh + relations + statistics {ours:7.2f} s, Delaunay alone {floor:7.2f} s: "
            f"ratio {ours / floor:.2f}x   target <= 1.3x ({mesh.edges.shape[0]} edges, {mesh.triangles.shape[0]} triangles)"
        )
        print(
            f"             CPU time (process_time): {ours_cpu:7.2f} s vs {floor_cpu:7.2f} s: "
            f"ratio {ours_cpu / floor_cpu:.2f}x"
        )
        if n <= 10**5:
            print(
                f"             with the optional displacement errors (triangle frame, aligned) "
                f"{with_disp:7.2f} s: ratio {with_disp / floor:.2f}x   (no target)"
            )
    n = 10**4
    ref = rng.uniform(0, 1000, (n, 2))
    keep = np.sort(rng.permutation(n)[: int(0.9 * n)])
    est = se2.transform_points(
        np.array([5.0, 3.0, 0.7]), ref[keep] + rng.normal(0, 0.05, (keep.size, 2))
    )
    t = time.perf_counter()
    a = associate_auto(LandmarkMap(keep, est), LandmarkMap(np.arange(n), ref), cutoff=1.0)
    dt = time.perf_counter() - t
    correct = float(np.mean(keep[a.estimate_rows] == a.reference_rows))
    print(
        f"automatic association of 10^4 landmarks (10% removed): {dt:.2f} s, {a.estimate_rows.size} matched, "
        f"{100 * correct:.1f}% correct   target < 2 s"
    )


if __name__ == "__main__":
    main()
