"""EKF-SLAM update speed, against the update before its blocked in-place form, in the same run.

1. One update at n ≈ 2,335 state dimensions (1,166 landmarks): the symmetric in-place form
   ``P −= W Wᵀ`` (``slamrel.backends.ekf_slam._update``) vs the old full product +
   ``0.5·(P + Pᵀ)`` pass (:func:`old_update`, below), on the
   same covariance; results compared. Target: ≥ 2× faster, equal to 1e-12.
2. Whole EKF-SLAM runs (``ekf_slam_bundle``) on the built-in ``complex1`` world with 225
   (default) and 400 features, new vs old update (monkeypatched), max abs difference of the
   map, map covariance and online poses (alternated, best of 3 at 225). The per-element constant of the O(n²) update is
   printed (ns per covariance element).

Run: ``python benchmarks/bench_ekfslam.py``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

import slamrel.backends.ekf_slam as ekfslam  # noqa: E402
import slamrel.simulation.worlds as worlds  # noqa: E402
from recovery.models import range_bearing  # noqa: E402
from relation_metric import se2  # noqa: E402
from slamrel.backends.ekf_slam import ekf_slam_bundle  # noqa: E402
from slamrel.simulation.bundles import world_bundle  # noqa: E402


def old_update(mu, cov, n, slot, meas, r_cov, t, m, gate=np.inf):  # type: ignore[no-untyped-def]
    """The update before the symmetric in-place form: full ``K Hᵀ`` product + ``0.5·(P + Pᵀ)``.

    The same formula as the oracle of ``tests/test_estimation_ekfslam.py``, copied on purpose:
    the benchmark times it and the test checks against it, and neither may change when the
    other's file is edited (benchmarks import nothing from ``tests/``).
    """
    h, hx, hl = range_bearing(mu[:3], mu[slot : slot + 2])
    nu = meas - h
    nu[1] = se2.wrap_angle(nu[1])
    pht = cov[:n, :3] @ hx.T + cov[:n, slot : slot + 2] @ hl.T
    s = hx @ pht[:3] + hl @ pht[slot : slot + 2] + r_cov
    s_inv = np.linalg.inv(s)
    np.linalg.cholesky(s)
    if gate < np.inf and float(nu @ s_inv @ nu) > gate:
        return False
    gain = pht @ s_inv
    mu[:n] += gain @ nu
    mu[2] = se2.wrap_angle(mu[2])
    cov[:n, :n] -= gain @ pht.T
    cov[:n, :n] = 0.5 * (cov[:n, :n] + cov[:n, :n].T)
    return True


def bench_one_update(n: int = 2335, cap: int = 2400, repeat: int = 7) -> dict[str, float]:
    rng = np.random.default_rng(0)
    a = rng.normal(size=(n, n))
    cov0 = np.zeros((cap, cap))
    cov0[:n, :n] = a @ a.T / n + np.eye(n)
    mu0 = np.zeros(cap)
    mu0[3:n] = rng.uniform(-20, 20, n - 3)
    r_cov = np.diag([0.1**2, 0.05**2])
    meas = np.array([5.0, 0.3])
    out: dict[str, float] = {"n": n}
    results = {}
    for name, fn in (("old", old_update), ("new", ekfslam._update)):
        best = np.inf
        for _ in range(repeat):
            mu, cov = mu0.copy(), cov0.copy()
            start = time.perf_counter()
            fn(mu, cov, n, 1001, meas, r_cov, 0.0, 0)
            best = min(best, time.perf_counter() - start)
        out[f"{name}_ms"] = best * 1e3
        results[name] = (mu, cov)
    out["max_abs_diff"] = float(np.abs(results["new"][1] - results["old"][1]).max())
    p = results["new"][1][:n, :n]
    out["exactly_symmetric"] = float(np.array_equal(p, p.T))
    return out


def run_slam(features: int, update) -> tuple[float, object, int]:  # type: ignore[no-untyped-def]
    saved_features, saved_update = worlds.N_FEATURES, ekfslam._update
    worlds.N_FEATURES = features
    ekfslam._update = update
    try:
        w = worlds.make_world("complex1", noise="a", seed=0)
        bundle = world_bundle(w)
        start = time.perf_counter()
        res = ekf_slam_bundle(bundle)[1]
        return time.perf_counter() - start, res, int(w.observations.t.size)
    finally:
        worlds.N_FEATURES, ekfslam._update = saved_features, saved_update


def main() -> None:
    one = bench_one_update()
    ratio = one["old_ms"] / one["new_ms"]
    n = int(one["n"])
    print(
        f"[1] one update at n = {n}: new {one['new_ms']:.2f} ms "
        f"({one['new_ms'] * 1e6 / n**2:.2f} ns per element), old {one['old_ms']:.2f} ms "
        f"({one['old_ms'] * 1e6 / n**2:.2f} ns/element): {ratio:.1f}x; target >= 2x: "
        f"{'met' if ratio >= 2 else 'MISSED'}; max |new - old| {one['max_abs_diff']:.1e} "
        f"({'<= 1e-12' if one['max_abs_diff'] <= 1e-12 else 'DIFFERS'}), P exactly symmetric: "
        f"{bool(one['exactly_symmetric'])}"
    )
    for features, rounds in ((225, 3), (400, 1)):
        t_new = t_old = np.inf
        for _ in range(rounds):  # alternated, best of each: the machine is shared
            t, new, meas = run_slam(features, ekfslam._update)
            t_new = min(t_new, t)
            t, old, _ = run_slam(features, old_update)
            t_old = min(t_old, t)
        diff = max(
            float(np.abs(new.map_xy - old.map_xy).max()),
            float(np.abs(new.map_covariance - old.map_covariance).max()),
            float(np.abs(new.online.poses - old.online.poses).max()),
        )
        print(
            f"[2] EKF-SLAM complex1, {features} features ({new.landmark_ids.size} mapped, "
            f"state {3 + 2 * new.landmark_ids.size}, {meas} measurements): new {t_new:.2f} s, "
            f"old {t_old:.2f} s: {t_old / t_new:.1f}x; max |new - old| {diff:.1e}"
        )


if __name__ == "__main__":
    main()
