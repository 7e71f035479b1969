"""The set-level cycle check (:mod:`slamrel.scans.cycles`): recall, false alarms and time.

1. Synthetic sets (:func:`slamrel.simulation.relation_sets.lap_relations`, three laps, 8 %
   planted gross errors): recall and false-alarm rate against the planted set, and the time
   of :func:`check_cycles` against a named baseline measured in the same run — the χ² of
   every cycle composed one at a time in Python (the loop the vectorised composition
   replaces; cycle enumeration and blame are not in the baseline).
2. The published Freiburg relation files ``fr079`` and ``mit-csail`` (no covariances: a
   uniform 2 cm / 0.5° is given, no floor): how many relations the check can test (the
   files hold no chain, so many close no cycle), which it contradicts, and how those compare
   with an independent SLAM result of the same run (benchmarks 06 and 08, scored with the
   relation metric): the relations that disagree with it by > 0.3 m or > 5°.

    python benchmarks/bench_cycle_check.py [DATA_DIR]
"""

from __future__ import annotations

import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from relation_metric import se2
from slamrel.scans.cycles import CycleOptions, check_cycles, compose_cycles, find_cycles
from slamrel.simulation.relation_sets import lap_relations


def loop_chi2(delta, cov, edges, signs) -> np.ndarray:
    """Baseline: one cycle at a time, pose by pose (the same first-order propagation)."""
    out = np.empty(edges.shape[0])
    for c in range(edges.shape[0]):
        p, s = np.zeros(3), np.zeros((3, 3))
        for e, sg in zip(edges[c], signs[c], strict=True):
            if e < 0:
                break
            d, sd = delta[e], cov[e]
            if sg < 0:
                co, si = np.cos(d[2]), np.sin(d[2])
                j = np.array(
                    [
                        [-co, -si, si * d[0] - co * d[1]],
                        [si, -co, co * d[0] + si * d[1]],
                        [0, 0, -1.0],
                    ]
                )
                d, sd = se2.inverse(d), j @ sd @ j.T
            jp = se2.compose_jacobian(p, d)
            co, si = np.cos(p[2]), np.sin(p[2])
            jt = np.array([[co, -si, 0], [si, co, 0], [0, 0, 1.0]])
            s = jp @ s @ jp.T + jt @ sd @ jt.T
            p = se2.compose(p, d)
        out[c] = p @ np.linalg.solve(s, p)
    return out


def synthetic() -> None:
    for seed in range(5):
        w = lap_relations(seed, laps=3)
        a, b = w.pairs[:, 0], w.pairs[:, 1]
        t0 = time.perf_counter()
        got = check_cycles(a, b, w.delta, w.covariance)
        ours = time.perf_counter() - t0
        _, edges, signs = find_cycles(a, b, np.ones(len(a), bool))
        floor = np.diag([0.01**2, 0.01**2, 0.005**2])
        cov = w.covariance + floor
        t0 = time.perf_counter()
        c, sc = compose_cycles(w.delta, cov, edges, signs)
        vec = np.einsum("ci,ci->c", c, np.linalg.solve(sc, c[..., None])[..., 0])
        t_vec = time.perf_counter() - t0
        t0 = time.perf_counter()
        base = loop_chi2(w.delta, cov, edges, signs)
        t_loop = time.perf_counter() - t0
        assert np.allclose(base, vec, rtol=1e-6, atol=1e-9)
        bad = w.bad
        recall = np.count_nonzero(got.contradicted & bad) / bad.sum()
        fa = np.count_nonzero(got.contradicted & ~bad) / (~bad).sum()
        print(
            f"seed {seed}: {len(a)} relations, {bad.sum()} planted, {got.n_cycles} cycles; "
            f"recall {recall:.3f}, false alarms {fa:.4f}; check_cycles {ours:.2f} s; "
            f"composition of {edges.shape[0]} cycles {t_vec * 1e3:.0f} ms vs the per-cycle "
            f"loop (baseline) {t_loop:.2f} s: {t_loop / t_vec:.0f}x"
        )


def published(root: Path) -> None:
    from relation_metric.evaluate import evaluate
    from slamrel.evaluation import load_trajectory
    from slamrel.formats.relations import read_relations

    for name, run in (("fr079", "06"), ("mit-csail", "08")):
        rel = read_relations(root / "freiburg" / f"{name}.relations")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            est = load_trajectory(
                str(root / "freiburg" / "benchmarks" / run / "test.log"),
                None,
                role="estimate",
                skip_invalid=True,
            ).trajectory
            ev = evaluate(rel, est, allow_empty=True)
        et = np.asarray(ev.errors.translation)
        er = np.degrees(np.asarray(ev.errors.rotation))
        far = (et > 0.3) | (er > 5)
        m = len(rel)
        _, node = np.unique(np.concatenate((rel.first, rel.second)), return_inverse=True)
        cov = np.broadcast_to(np.diag([0.02**2, 0.02**2, np.radians(0.5) ** 2]), (m, 3, 3))
        opt = CycleOptions(min_sd_xy=0.0, min_sd_theta=0.0)
        got = check_cycles(node[:m], node[m:], rel.delta, cov, options=opt)
        checked = got.cycles > 0
        print(
            f"{name}: {m} relations, {checked.sum()} in a cycle; {got.count} contradicted; "
            f"{far.sum()} disagree with run {run} by > 0.3 m or > 5° ({(far & checked).sum()} "
            f"of them in a cycle, {(far & got.contradicted).sum()} contradicted)"
        )
        for k in np.flatnonzero(got.contradicted):
            print(
                f"  contradicted {rel.first[k]:.6f} -> {rel.second[k]:.6f}: run {run} differs "
                f"by {et[k]:.3f} m, {er[k]:.2f}°"
            )


def main() -> None:
    root = Path(
        sys.argv[1] if len(sys.argv) > 1 else os.environ.get("SLAMREL_DATA", "../shared/data")
    )
    synthetic()
    if (root / "freiburg" / "fr079.relations").exists():
        published(root)
    else:
        print(f"{root}/freiburg not found: the published files are skipped")


if __name__ == "__main__":
    main()
