"""Consistency and accuracy of the recovery on healthy-by-construction bundles (issue 23).

Run: ``PYTHONPATH=. python tests/healthy_consistency.py [--worlds simple1,complex1]
[--seeds 0-9] [--forms joint,marginal] [--scale 1] [--map-mode default] [--neff 100]``.

Input: :func:`slamrel.simulation.healthy.healthy_bundle` — a simulated world's log and ground
truth, the true associations, and a map = true landmarks + an error drawn from exactly the
map covariance the bundle states (``joint``: a correlated ``map_covariance``; ``marginal``:
independent landmarks, ``map_marginals`` only). ``--scale 3`` draws the error 3 × larger
than stated (the control: must look inconsistent).

Prints one row per world × seed × form × method × robust (``None`` is the plain EKF,
``redescending`` the default): the mean pose NEES (3 dof) of the run, its 95 % band for one
run (``nees_band(3, n_eff)``, n_eff of ``tests/test_recovery_healthy.py``), the mean
translational error of 500 global relations (``generate_relations(groundtruth, "global",
count=500, seed=0)``) and the time; then per world × form × method × robust the mean over
seeds against the band of that average (``nees_band(3, seeds · n_eff)``), the largest /
smallest of the three methods' means, and how often smoother ≤ filter and batch ≤ 1.05 ×
smoother held.

``--neff N`` instead measures the effective sample size of a run's mean NEES: over ``N``
seeds (from 1000, disjoint from the tests' seeds) with a recovery known to be consistent on
these bundles — the filter with the joint covariance, the ``marginal`` form's marginals put
into a block-diagonal ``map_covariance`` — ``n_eff = 6 / var(mean NEES)`` (a mean of
``n`` independent χ²₃ has variance ``6 / n``), and the mean of the means.

Target (issue 23, acceptance 1): every average inside its band; the three methods within
10 %; smoother ≤ filter and batch ≤ 1.05 × smoother in every run.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy.linalg import block_diag

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from test_recovery_healthy import N_EFF  # noqa: E402

import slamrel  # noqa: E402
from recovery.recover import recover  # noqa: E402
from relation_metric.consistency import nees_band  # noqa: E402
from slamrel.runs.nees import recovery_nees  # noqa: E402
from slamrel.simulation.healthy import FORMS, healthy_bundle  # noqa: E402

METHODS = ("filter", "smoother", "batch")
ROBUST = (None, "redescending")


def _mean_nees(b, r) -> float:  # type: ignore[no-untyped-def]
    """The recovery's mean pose NEES against the truth, as slamrel run computes it."""
    got = recovery_nees(b, r)
    assert got is not None
    return float(got[0].summary.mean)


def _seeds(text: str) -> list[int]:
    if "-" in text:
        a, b = text.split("-")
        return list(range(int(a), int(b) + 1))
    return [int(s) for s in text.split(",")]


def _error(bundle, recovery) -> float:  # type: ignore[no-untyped-def]
    rel = slamrel.generate_relations(bundle.groundtruth, "global", count=500, seed=0)
    return float(slamrel.evaluate(rel, recovery.trajectory).translation.abs.mean)


def table(worlds, seeds, forms, scale: float, map_mode: str | None) -> None:  # type: ignore[no-untyped-def]
    rows = []
    print(
        f"map error drawn {scale:g} x the stated covariance; map mode "
        f"{map_mode or 'default (joint; the marginals when no map_covariance)'}"
    )
    print(
        f"{'world':9} {'seed':>4} {'form':8} {'method':8} {'robust':12} {'mode':8} "
        f"{'NEES':>7} {'band95(1 run)':>14} {'error[m]':>8} {'time':>5}"
    )
    for w in worlds:
        for s in seeds:
            for f in forms:
                b = healthy_bundle(w, s, f, error_scale=scale)
                lo, hi = nees_band(3, N_EFF[f], 0.95)
                for rb in ROBUST:
                    for m in METHODS:
                        t = time.perf_counter()
                        kw = {} if map_mode is None else {"map_mode": map_mode}
                        r = recover(b, method=m, robust=rb, **kw)
                        dt = time.perf_counter() - t
                        e = _error(b, r)
                        nees = _mean_nees(b, r)
                        rows.append((w, s, f, m, str(rb), nees, e))
                        print(
                            f"{w:9} {s:4d} {f:8} {m:8} {rb!s:12} {r.map_mode:8} {nees:7.2f} "
                            f"[{lo:5.2f},{hi:5.2f}] {e:8.3f} {dt:5.2f}",
                            flush=True,
                        )
    print()
    print(
        f"{'world':9} {'form':8} {'robust':12} {'method':8} {'mean NEES':>9} "
        f"{'band95(mean)':>14} {'in':>3} {'max/min':>7} {'sm<=f':>6} {'b<=1.05sm':>9} "
        f"{'error[m]':>8}"
    )
    arr = np.array(rows, dtype=object)
    for w in worlds:
        for f in forms:
            lo, hi = nees_band(3, len(seeds) * N_EFF[f], 0.95)
            for rb in map(str, ROBUST):
                sel = (arr[:, 0] == w) & (arr[:, 2] == f) & (arr[:, 4] == rb)
                nees = {m: arr[sel & (arr[:, 3] == m), 5].astype(float) for m in METHODS}
                err = {m: arr[sel & (arr[:, 3] == m), 6].astype(float) for m in METHODS}
                means = [float(nees[m].mean()) for m in METHODS]
                ratio = max(means) / min(means)  # of the means over seeds, as the test
                sm_f = int((err["smoother"] <= err["filter"]).sum())
                b_sm = int((err["batch"] <= 1.05 * err["smoother"]).sum())
                for m in METHODS:
                    mean = float(nees[m].mean())
                    ok = "yes" if lo <= mean <= hi else "NO"
                    extra = (
                        f"{ratio:7.2f} {sm_f:3d}/{len(seeds):<2d} {b_sm:6d}/{len(seeds):<2d}"
                        if m == "filter"
                        else " " * 7 + " " * 7 + " " * 10
                    )
                    print(
                        f"{w:9} {f:8} {rb:12} {m:8} {mean:9.2f} [{lo:5.2f},{hi:5.2f}] "
                        f"{ok:>3} {extra} {err[m].mean():8.3f}"
                    )


def neff(worlds, forms, runs: int) -> None:  # type: ignore[no-untyped-def]
    print(f"n_eff of a run's mean NEES: filter, joint Schmidt update, {runs} seeds from 1000")
    print(f"{'world':9} {'form':8} {'mean':>6} {'sd':>6} {'n_eff':>6} {'min':>6} {'max':>6}")
    for w in worlds:
        for f in forms:
            v = []
            for s in range(1000, 1000 + runs):
                b = healthy_bundle(w, s, f)
                if b.map_covariance is None:  # the marginal form as the block-diagonal joint
                    b = b.with_map(b.map_xy, b.map_marginals, block_diag(*b.map_marginals))
                v.append(_mean_nees(b, recover(b, method="filter", robust=None)))
            a = np.array(v)
            print(
                f"{w:9} {f:8} {a.mean():6.2f} {a.std(ddof=1):6.2f} {6 / a.var(ddof=1):6.1f} "
                f"{a.min():6.2f} {a.max():6.2f}",
                flush=True,
            )


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--worlds", default="simple1,simple2,complex1,complex2")
    p.add_argument("--seeds", default="0-9", help="a-b or a,b,c")
    p.add_argument("--forms", default=",".join(FORMS))
    p.add_argument("--scale", type=float, default=1.0, help="map error / stated (control: 3)")
    p.add_argument(
        "--map-mode", default="default", choices=("default", "joint", "marginal", "ignore")
    )
    p.add_argument("--neff", type=int, default=0, help="measure n_eff over this many seeds")
    a = p.parse_args()
    worlds, forms = a.worlds.split(","), a.forms.split(",")
    if a.neff:
        neff(worlds, forms, a.neff)
        return
    mode = None if a.map_mode == "default" else a.map_mode
    table(worlds, _seeds(a.seeds), forms, a.scale, mode)


if __name__ == "__main__":
    main()
