"""Scan pairs aligned per second: slamrel's point-to-line ICP vs a plain point-to-point ICP.

Data: the 1,172 timestamp pairs of ``mit-csail.relations`` on ``mit-csail.clf`` (361-beam
scans), guesses from the log's odometry; both matchers get the same prepared returns and the
same guesses. Baseline: point-to-point ICP (Besl & McKay 1992) on a cKDTree of the reference
returns, SVD (Arun et al. 1987) per iteration, the same 0.5 m gate, 60 iterations at most and
1e-6 convergence. Scan preparation (line fitting, trees) is timed separately and counted per
scan. Target: ≥ 200 pairs/s.

    python benchmarks/bench_scan_matching.py [DATA_DIR]
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from relation_metric.se2 import between
from slamrel.formats.laser import read_laser_scans
from slamrel.scans.matching import align, prepare_scan
from slamrel.scans.proposals import pairs_at_times


def point_to_point(ref: np.ndarray, tree: cKDTree, cur: np.ndarray, guess: np.ndarray):
    """Plain ICP: nearest neighbours within 0.5 m, closed-form rigid fit, 60 iterations."""
    x = guess.copy()
    for _ in range(60):
        c, s = np.cos(x[2]), np.sin(x[2])
        q = cur @ np.array([[c, s], [-s, c]]) + x[:2]
        d, k = tree.query(q, distance_upper_bound=0.5)
        ok = np.isfinite(d)
        if ok.sum() < 3:
            break
        a, b = ref[k[ok]], cur[ok]
        ma, mb = a.mean(0), b.mean(0)
        h = (b - mb).T @ (a - ma)
        u, _, vt = np.linalg.svd(h)
        r = vt.T @ u.T
        if np.linalg.det(r) < 0:
            vt[1] *= -1
            r = vt.T @ u.T
        th = np.arctan2(r[1, 0], r[0, 0])
        t = ma - r @ mb
        step = np.array([t[0], t[1], th]) - x
        x = np.array([t[0], t[1], th])
        if np.hypot(step[0], step[1]) < 1e-6 and abs(step[2]) < 1e-6:
            break
    return x


def main() -> None:
    root = Path(
        sys.argv[1] if len(sys.argv) > 1 else os.environ.get("SLAMREL_DATA", "../shared/data")
    )
    scans = read_laser_scans(root / "freiburg" / "mit-csail.clf")
    rel = np.loadtxt(root / "freiburg" / "mit-csail.relations")
    prop = pairs_at_times(scans.timestamps, rel[:, 0], rel[:, 1], tolerance=0.01)
    guess = between(scans.laser_pose[prop.pairs[:, 0]], scans.laser_pose[prop.pairs[:, 1]])
    used = np.unique(prop.pairs)
    t0 = time.perf_counter()
    prepared = {int(k): prepare_scan(scans.points(int(k))) for k in used}
    t_prep = time.perf_counter() - t0
    trees = {k: cKDTree(p.points) for k, p in prepared.items()}
    t_tree = time.perf_counter() - t0 - t_prep
    pairs = prop.pairs.tolist()
    n = len(pairs)
    t0 = time.perf_counter()
    for (i, j), g in zip(pairs, guess):
        align(prepared[i], prepared[j], g)
    t_ours = time.perf_counter() - t0
    t0 = time.perf_counter()
    for (i, j), g in zip(pairs, guess):
        point_to_point(prepared[i].points, trees[i], prepared[j].points, g)
    t_base = time.perf_counter() - t0
    per_pair_prep = t_prep / len(used) * 2
    ours = n / (t_ours + t_prep)
    print(f"{n} pairs, {len(used)} scans of 361 beams")
    print(
        f"scan preparation (lines + tree): {t_prep * 1e3 / len(used):.2f} ms/scan "
        f"(point-to-point's trees alone {t_tree * 1e3 / len(used):.2f} ms/scan)"
    )
    print(
        f"point-to-line ICP (ours):       {n / t_ours:8.1f} pairs/s alignment only, "
        f"{ours:8.1f} pairs/s with preparation"
    )
    print(
        f"point-to-point ICP (baseline):  {n / (t_base):8.1f} pairs/s alignment only, "
        f"{n / (t_base + t_tree):8.1f} pairs/s with trees"
    )
    print(
        f"ratio ours/baseline (with preparation): {(n / (t_ours + t_prep)) / (n / (t_base + t_tree)):.2f}"
    )
    print(
        f"target >= 200 pairs/s: {'met' if ours >= 200 else 'missed'} ({ours:.0f}); "
        f"worst case, preparing both scans per pair: {1 / (t_ours / n + per_pair_prep):.0f} pairs/s"
    )


if __name__ == "__main__":
    main()
