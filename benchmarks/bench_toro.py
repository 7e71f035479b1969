"""slamrel's TORO (:mod:`slamrel.backends.toro_optimiser`) against the real 2-D ``toro``.

The baseline is OpenSLAM's ``toro`` binary (CC BY-NC-SA, never part of slamrel), built by
the user in a side folder and named with ``--toro PATH`` (default ``$SLAMREL_TORO``; see
benchmarks/README.md for the build). Both run in this process's session on the same graph
files with the same number of iterations and their defaults; this script reports

* ``city10000`` (iSAM, ``$SLAMREL_DATA/isam``) from its odometry guess: ``½ χ²`` with the
  file's information after N iterations, as a ratio to least squares' optimum, and the
  position ATE against the ground truth after an SE(2) (rotation + translation) alignment;
* the pose-only study's Method 2 graphs (``--worlds``, noise a and c, seed 0): cost ratio
  to least squares' optimum of the same graph, and slamrel's as a ratio to real TORO's, on
  the graph and as the ratio of the medians over it and ``--copies`` copies whose
  measurements are changed by 1e-12 (TORO's iterates on the complex worlds depend on the
  data's last bits: :func:`m2_graphs`);
* time per iteration: slamrel's ``toro_optimize`` (set-up excluded, best of the runs; the
  set-up, ``iterations=0``, printed beside it) and real TORO's (``TOTAL TIME`` it prints,
  set-up excluded, best of as many runs), and their ratio.

Usage: ``python benchmarks/bench_toro.py [--toro PATH] [--iterations 100 300]``.
Without a TORO binary only slamrel's numbers are printed (no ratios).
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from relation_metric import se2  # noqa: E402
from slamrel.backends.graph import PoseGraph  # noqa: E402
from slamrel.backends.least_squares import solve_graph  # noqa: E402
from slamrel.backends.toro_optimiser import graph_cost, toro_optimize  # noqa: E402
from slamrel.formats.toro import read_toro_graph, write_toro_graph  # noqa: E402

DATA = Path(os.environ.get("SLAMREL_DATA", ROOT.parent / "shared" / "data"))


def aligned_ate(est: np.ndarray, truth: np.ndarray) -> float:
    """RMS position error after the least-squares SE(2) alignment of ``est`` onto ``truth``."""
    a, b = est[:, :2], truth[:, :2]
    ma, mb = a.mean(axis=0), b.mean(axis=0)
    u, _, vt = np.linalg.svd((b - mb).T @ (a - ma))
    r = u @ np.diag([1.0, np.linalg.det(u @ vt)]) @ vt
    d = (a - ma) @ r.T + mb - b
    return float(np.sqrt((d**2).sum(axis=1).mean()))


def real_toro(
    binary: str, graph: PoseGraph, iterations: int, repeat: int
) -> tuple[np.ndarray, float]:
    """Poses after ``iterations`` of the real ``toro`` (its defaults) and its best seconds per
    iteration over ``repeat`` runs (the optimisation time it prints)."""
    best = float("inf")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "g.graph"
        write_toro_graph(path, graph)
        for _ in range(repeat):
            done = subprocess.run(
                [binary, "-i", str(iterations), "-nde", str(path)],
                capture_output=True,
                text=True,
                check=True,
                cwd=tmp,
            )
            out = done.stdout + done.stderr
            found = re.search(r"TOTAL TIME\s*=\s*([0-9.eE+-]+)", out)
            best = min(best, float(found.group(1)))  # type: ignore[union-attr]
        poses = np.asarray(read_toro_graph(Path(tmp) / "g-treeopt-final.graph")[0].poses)
    return poses, best / max(iterations, 1)


def slamrel_toro(graph: PoseGraph, iterations: int, repeat: int) -> tuple[np.ndarray, float, float]:
    """Poses after ``iterations``, the best seconds per iteration (the set-up, measured
    with 0 iterations, subtracted) and the best set-up seconds."""
    best = setup = float("inf")
    sol = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        toro_optimize(graph, iterations=0)
        t1 = time.perf_counter()
        sol = toro_optimize(graph, iterations=iterations)
        t2 = time.perf_counter()
        best = min(best, ((t2 - t1) - (t1 - t0)) / max(iterations, 1))
        setup = min(setup, t1 - t0)
    assert sol is not None
    return np.asarray(sol.poses), best, setup


def city(binary: str | None, iterations: list[int], repeat: int) -> None:
    from slamrel.formats.isam import read_isam

    g = read_isam(DATA / "isam" / "city10000.txt").graph
    gt = np.loadtxt(
        DATA / "isam" / "groundtruth" / "city10000_groundtruth.txt", usecols=range(1, 6)
    )
    chain = gt[gt[:, 1] == gt[:, 0] + 1]
    truth = se2.cumulative_compose(chain[np.argsort(chain[:, 0]), 2:5])
    opt = graph_cost(np.asarray(solve_graph(g).poses), g)
    print(f"city10000: {g.n_poses} poses, {g.pp_i.size} constraints; LS optimum {opt:,.0f}")
    for it in iterations:
        mine, per, setup = slamrel_toro(g, it, repeat)
        c = graph_cost(mine, g)
        line = (
            f"  {it:4d} it: slamrel cost {c:,.0f} ({c / opt:.2f}x opt), ATE "
            f"{aligned_ate(mine, truth):.3f} m, {per * 1e3:.1f} ms/it (set-up {setup:.2f} s)"
        )
        if binary:
            ref, ref_per = real_toro(binary, g, it, repeat)
            rc = graph_cost(ref, g)
            line += (
                f" | real TORO cost {rc:,.0f}, ATE {aligned_ate(ref, truth):.3f} m, "
                f"{ref_per * 1e3:.1f} ms/it | cost ratio {c / rc:.3f}, time ratio {per / ref_per:.1f}x"
            )
        print(line)


def m2_graphs(
    binary: str | None, worlds: list[str], iterations: int, repeat: int, copies: int
) -> None:
    """Cost ratios on the Method 2 graphs: the graph itself and ``copies`` copies whose
    measurements are changed by 1e-12 (relative, seeded). TORO's step caps a dimension at its
    residual, a discontinuous rule, so after a few iterations on the complex worlds the
    iterates of either optimiser depend on the last bits of the data (a 1e-12 change moves
    hu-complex2's cost after 5 iterations by 10-20 %); the medians over the copies are what
    the two optimisers can be compared by there."""
    from slamrel.backends.pose_only import LandmarkLog, pose_only_least_squares
    from slamrel.simulation.worlds import make_world

    print(
        f"pose-only Method 2 graphs, seed 0, {iterations} iterations (cost / LS optimum; "
        f"the graph, then the median [range] over it and {copies} copies changed by 1e-12):"
    )
    for world in worlds:
        for noise in ("a", "c"):
            w = make_world(world, noise=noise, seed=0)
            po = pose_only_least_squares(LandmarkLog.from_world(w), method=2, truth=w.truth)
            g = po.graph
            opt = graph_cost(np.asarray(po.solution.poses), g)
            rng = np.random.default_rng(0)
            mine_r, ref_r, per, ref_per = [], [], [], []  # times: the graph's (k = 0)
            for k in range(copies + 1):
                z = g.pp_z * (1.0 + (1e-12 if k else 0.0) * rng.standard_normal(g.pp_z.shape))
                gk = PoseGraph(g.poses, g.landmarks, g.pp_i, g.pp_j, z, g.pp_info)
                mine, per_k, _ = slamrel_toro(gk, iterations, repeat if k == 0 else 1)
                mine_r.append(graph_cost(mine, g) / opt)
                per.append(per_k)
                if binary:
                    ref, ref_per_k = real_toro(binary, gk, iterations, repeat if k == 0 else 1)
                    ref_r.append(graph_cost(ref, g) / opt)
                    ref_per.append(ref_per_k)
            line = (
                f"  {world} {noise}: {g.n_poses} poses, {g.pp_i.size} constraints; slamrel "
                f"{mine_r[0]:.2f}x, median {np.median(mine_r):.2f} "
                f"[{min(mine_r):.2f}, {max(mine_r):.2f}], {per[0] * 1e3:.2f} ms/it"
            )
            if binary:
                line += (
                    f" | real TORO {ref_r[0]:.2f}x, median {np.median(ref_r):.2f} "
                    f"[{min(ref_r):.2f}, {max(ref_r):.2f}], {ref_per[0] * 1e3:.2f} ms/it | "
                    f"slamrel/real {mine_r[0] / ref_r[0]:.2f}, of the medians "
                    f"{np.median(mine_r) / np.median(ref_r):.2f}"
                )
            print(line, flush=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--toro", default=os.environ.get("SLAMREL_TORO"), help="the real toro binary")
    ap.add_argument("--iterations", type=int, nargs="+", default=[100, 300])
    ap.add_argument(
        "--worlds", nargs="*", default=["hu-simple1", "hu-simple2", "hu-complex1", "hu-complex2"]
    )
    ap.add_argument(
        "--copies", type=int, default=5, help="Method 2 graphs changed by 1e-12 (default 5)"
    )
    ap.add_argument(
        "--repeat", type=int, default=1, help="runs of each timing, both tools; the best is kept"
    )
    args = ap.parse_args()
    city(args.toro, args.iterations, args.repeat)
    m2_graphs(args.toro, args.worlds, args.iterations[0], args.repeat, args.copies)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
