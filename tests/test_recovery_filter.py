"""recovery.ekf / smoother / batch against independent oracles: a per-step filterpy EKF
(to 1e-9), a per-step extended RTS written out plainly, a dense augmented-state Schmidt
filter, the dense inverse of the batch normal equations; divergence reporting."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from recovery.baseline import filterpy_localisation
from recovery.batch_refinement import normal_equations, refine
from recovery.ekf import GATED, USED, run_filter
from recovery.models import process_noise, range_bearing
from recovery.recover import filter_input, recover
from recovery.smoother import smooth
from relation_metric import se2
from relation_metric.errors import DivergenceError
from slamrel.formats.bundle import read_bundle, write_bundle
from slamrel.simulation.bundles import simulate_bundle

CASES = [
    {},
    {"alpha": (0.002, 0.001, 0.001, 0.004)},
    {"measurement_offset": 0.4, "unassociated_fraction": 0.1},
    {"motion": "odometry"},
    {"motion": "odometry", "alpha": (0.02, 0.005, 0.01, 0.005), "measurement_offset": 0.7},
]


def _corrupt(b, fraction: float, seed: int):  # type: ignore[no-untyped-def]
    """Replace a fraction of the associations by another landmark."""
    rng = np.random.default_rng(seed)
    lm = b.measurement_landmarks.copy()
    pick = rng.random(lm.shape[0]) < fraction
    lm[pick] = rng.choice(b.map_ids, pick.sum())
    return replace(b, measurement_landmarks=lm)


@pytest.mark.parametrize("kw", CASES)
def test_filter_equals_per_step_filterpy(kw: dict) -> None:  # type: ignore[type-arg]
    # the marginals added to R at every sighting (FilterInput without a joint covariance): the
    # textbook per-step filter's treatment
    b = simulate_bundle(11, steps=250, map_sigma=(0.02, 0.0), **kw)
    inp = replace(filter_input(b, map_mode="marginal"), map_covariance=None)
    fr = run_filter(inp)
    poses, covs, status = filterpy_localisation(inp)
    d = fr.poses - poses
    d[:, 2] = se2.wrap_angle(d[:, 2])
    assert np.abs(d).max() < 1e-9
    assert np.abs(fr.covariances - covs).max() < 1e-9
    np.testing.assert_array_equal(fr.status, status)


def test_gating_equals_filterpy_and_is_counted() -> None:
    b = _corrupt(simulate_bundle(12, steps=300), 0.05, 1)
    inp = replace(filter_input(b, map_mode="marginal"), map_covariance=None)
    fr = run_filter(inp, gate=0.99, max_outlier_run=None)
    poses, covs, status = filterpy_localisation(inp, gate=0.99)
    np.testing.assert_array_equal(fr.status, status)
    assert (status == GATED).sum() >= 5
    d = fr.poses - poses
    d[:, 2] = se2.wrap_angle(d[:, 2])
    assert np.abs(d).max() < 1e-9 and np.abs(fr.covariances - covs).max() < 1e-9
    r = recover(b, method="filter", gate=0.99, max_outlier_run=None, robust=None)
    assert r.counts.gated == (status == GATED).sum()
    assert r.counts.used + r.counts.gated == b.measurement_times.shape[0]


def _per_step_rts(inp):  # type: ignore[no-untyped-def]
    """Plain per-step EKF and extended RTS (Särkkä Alg. 9.3), no shortcuts."""
    n = inp.times.shape[0]
    x, p = inp.x0.astype(float).copy(), inp.p0.astype(float).copy()
    xf, pf, xp, pp, fs = (
        np.zeros((n, 3)),
        np.zeros((n, 3, 3)),
        np.zeros((n, 3)),
        np.zeros((n, 3, 3)),
        np.zeros((n, 3, 3)),
    )
    for k in range(n):
        if k:
            f = se2.compose_jacobian(x, inp.u[k - 1])
            fs[k - 1] = f
            p = f @ p @ f.T + process_noise(x[2], inp.sigma[k - 1])
            x = x + (se2.compose(x, inp.u[k - 1]) - x)  # unwrapped heading
            x[2] = xf[k - 1, 2] + inp.u[k - 1, 2]
        xp[k], pp[k] = x, p
        for j in np.flatnonzero((inp.meas_grid == k) & (inp.meas_landmark >= 0)):
            li = inp.meas_landmark[j]
            z, hx, hl = range_bearing(x, inp.map_xy[li])
            s = hx @ p @ hx.T + inp.r + hl @ inp.map_marginals[li] @ hl.T
            kk = p @ hx.T @ np.linalg.inv(s)
            y = inp.meas_z[j] - z
            y[1] = se2.wrap_angle(y[1])
            x = x + kk @ y
            p = p - kk @ s @ kk.T
        xf[k], pf[k] = x, p
    xs, ps = xf.copy(), pf.copy()
    for k in range(n - 2, -1, -1):
        c = pf[k] @ fs[k].T @ np.linalg.inv(pp[k + 1])
        dx = xs[k + 1] - xp[k + 1]
        dx[2] = se2.wrap_angle(dx[2])
        xs[k] = xf[k] + c @ dx
        ps[k] = pf[k] + c @ (ps[k + 1] - pp[k + 1]) @ c.T
    return xf, pf, xs, ps


@pytest.mark.parametrize("kw", CASES[:4])
def test_smoother_equals_per_step_extended_rts(kw: dict) -> None:  # type: ignore[type-arg]
    b = simulate_bundle(21, steps=200, measure_every=7, **kw)
    inp = filter_input(b, map_mode="marginal")
    fr = run_filter(inp)
    sm = smooth(fr)
    xf, pf, xs, ps = _per_step_rts(inp)
    d = sm.poses - xs
    d[:, 2] = se2.wrap_angle(d[:, 2])
    assert np.abs(d).max() < 1e-9
    np.testing.assert_allclose(sm.covariances, ps, atol=1e-11, rtol=1e-7)


def test_batch_is_stationary_and_covariance_is_dense_inverse() -> None:
    for kw in ({"motion": "odometry"}, {}):
        b = simulate_bundle(31, steps=70, **kw)
        inp = filter_input(b, map_mode="marginal")
        fr = run_filter(inp)
        used = fr.status == USED
        br = refine(inp, smooth(fr).poses, used=used)
        h, g, cost, _ = normal_equations(inp, br.poses, np.flatnonzero(used))
        step = np.linalg.solve(h.toarray(), g)
        assert np.abs(step).max() < 1e-7  # Gauss–Newton step at the solution ~ 0
        hinv = np.linalg.inv(h.toarray())
        blocks = np.stack([hinv[3 * k : 3 * k + 3, 3 * k : 3 * k + 3] for k in range(70)])
        np.testing.assert_allclose(br.covariances, blocks, rtol=1e-6, atol=1e-12)
        assert br.cost_final <= br.cost_initial
        # another start converges to the same optimum
        start = smooth(fr).poses + np.random.default_rng(0).normal(0, 0.01, (70, 3))
        br2 = refine(inp, start, used=used)
        d = br2.poses - br.poses
        d[:, 2] = se2.wrap_angle(d[:, 2])
        assert np.abs(d).max() < 1e-6


def test_schmidt_equals_dense_augmented_consider_filter() -> None:
    b = simulate_bundle(41, steps=150, landmarks=6, map_sigma=(0.05, 0.1), map_covariance=True)
    inp = filter_input(b, map_mode="joint")
    fr = run_filter(inp)
    m = b.map_xy.shape[0]
    dim = 3 + 2 * m
    x = inp.x0.astype(float).copy()
    p = np.zeros((dim, dim))
    p[:3, :3] = inp.p0
    p[3:, 3:] = inp.map_covariance
    out_x, out_p = [], []
    for k in range(inp.times.shape[0]):
        if k:
            f = np.eye(dim)
            f[:3, :3] = se2.compose_jacobian(x, inp.u[k - 1])
            q = np.zeros((dim, dim))
            q[:3, :3] = process_noise(x[2], inp.sigma[k - 1])
            p = f @ p @ f.T + q
            x = se2.compose(x, inp.u[k - 1])
        for j in np.flatnonzero(inp.meas_grid == k):
            li = inp.meas_landmark[j]
            z, hx, hl = range_bearing(x, inp.map_xy[li])
            h = np.zeros((2, dim))
            h[:, :3], h[:, 3 + 2 * li : 5 + 2 * li] = hx, hl
            s = h @ p @ h.T + inp.r
            kk = p @ h.T @ np.linalg.inv(s)
            kk[3:] = 0.0  # Schmidt: the map is a consider parameter
            y = inp.meas_z[j] - z
            y[1] = se2.wrap_angle(y[1])
            x = x + kk[:3] @ y
            a = np.eye(dim) - kk @ h
            p = a @ p @ a.T + kk @ inp.r @ kk.T  # Joseph form
        out_x.append(x.copy())
        out_p.append(p[:3, :3].copy())
    d = fr.poses - np.array(out_x)
    d[:, 2] = se2.wrap_angle(d[:, 2])
    assert np.abs(d).max() < 1e-9
    np.testing.assert_allclose(fr.covariances, np.array(out_p), atol=1e-12, rtol=1e-8)


def test_divergence_names_time_and_measurement(tmp_path: Path) -> None:
    b = simulate_bundle(51, steps=300)
    write_bundle(tmp_path / "b", replace(b, map_xy=b.map_xy + [3.0, -2.0]))
    bad = read_bundle(tmp_path / "b")
    with pytest.raises(DivergenceError) as info:
        recover(bad, method="filter", max_outlier_run=20, on_divergence="raise")
    msg = str(info.value)
    assert "t=" in msg and "measurements.csv:" in msg and "consecutive" in msg
    # without the run limit it completes, and says how far off it is
    r = recover(bad, method="filter", max_outlier_run=None, gate=0.99)
    assert r.counts.gated_fraction > 0.5
    from slamrel.cli import main

    assert (
        main(
            [
                "recover",
                str(tmp_path / "b"),
                "-o",
                str(tmp_path / "t.txt"),
                "-q",
                "--max-outlier-run",
                "20",
                "--fail-on-divergence",
            ]
        )
        == 3
    )


def test_non_positive_definite_covariance_is_divergence() -> None:
    b = simulate_bundle(52, steps=50)
    inp = filter_input(b, map_mode="marginal")
    bad = replace(inp, p0=np.diag([1e-9, 1e-9, -1.0]))
    with pytest.raises(DivergenceError, match=r"t=.*not"):
        run_filter(bad)
