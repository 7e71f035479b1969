"""recovery.batch_refinement: the chain retraction and the minimum it converges to.

Oracles: a per-pose loop of :func:`relation_metric.se2.compose` over the increments moved by
their linear model (built from :func:`relation_metric.se2.between`'s own Jacobians), the
additive retraction to first order, and the batch run the way it ran before the chain
retraction (additive step, ``λ`` from 1e-6, floor 1e-12) driven to a tight tolerance; the
retried factorisation against a direct banded solve with the floor damping.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import solveh_banded

from recovery.batch_refinement import (
    _band,
    _BatchProblem,
    _cholesky_solve,
    _factors,
    _weights,
    batch_covariances,
    refine,
    regularised_sigma,
    retract_chain,
)
from recovery.ekf import USED, run_filter
from recovery.lm import LMOptions, levenberg_marquardt, retract_poses
from recovery.recover import filter_input
from recovery.smoother import smooth, smoothed_covariances
from relation_metric import se2
from relation_metric.errors import DivergenceError
from slamrel.simulation.bundles import simulate_bundle


def _looped_chain(x: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """``x'_0 = x_0 + δ_0``, ``x'_{k+1} = x'_k ∘ (d_k + J_a δ_k + J_b δ_{k+1})``, one pose at
    a time."""
    step = delta.reshape(x.shape)
    d, j_a, j_b = se2.between(x[:-1], x[1:], jacobians=True)
    out = np.empty_like(x)
    out[0] = x[0] + step[0]
    out[0, 2] = se2.wrap_angle(out[0, 2])
    for k in range(x.shape[0] - 1):
        moved = d[k] + j_a[k] @ step[k] + j_b[k] @ step[k + 1]
        out[k + 1] = se2.compose(out[k], moved)
    return out


def _walk(
    rng: np.random.Generator, n: int, step: float, turn: float, bend: float = 0.0
) -> np.ndarray:
    """A random trajectory of ``n`` poses with headings anywhere in [−π, π) (``bend``: the
    mean turn per step)."""
    u = np.column_stack(
        (
            rng.uniform(0.0, step, n - 1),
            rng.normal(0.0, step / 10, n - 1),
            rng.normal(bend, turn, n - 1),
        )
    )
    start = [rng.uniform(-50, 50), rng.uniform(-50, 50), rng.uniform(-np.pi, np.pi)]
    return se2.cumulative_compose(u, start)


def _pose_diff(a: np.ndarray, b: np.ndarray) -> float:
    d = a - b
    d[:, 2] = se2.wrap_angle(d[:, 2])
    return float(np.abs(d).max())


@settings(max_examples=100, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(2, 40),
    step=st.floats(0.0, 2.0),
    turn=st.floats(0.0, 1.5),
    size=st.floats(1e-8, 0.5),
)
def test_chain_retraction_equals_looped_compose(
    seed: int, n: int, step: float, turn: float, size: float
) -> None:
    rng = np.random.default_rng(seed)
    x = _walk(rng, n, step, turn)
    delta = rng.normal(0.0, size, 3 * n)
    got = retract_chain(x, delta)
    want = _looped_chain(x, delta)
    assert _pose_diff(got, want) < 1e-9
    assert np.all((got[:, 2] >= -np.pi) & (got[:, 2] < np.pi))
    # the motion increments land exactly on their linear model
    d, j_a, j_b = se2.between(x[:-1], x[1:], jacobians=True)
    s = delta.reshape(-1, 3)
    lin = d + np.einsum("nij,nj->ni", j_a, s[:-1]) + np.einsum("nij,nj->ni", j_b, s[1:])
    moved = se2.between(got[:-1], got[1:])
    assert _pose_diff(moved, lin) < 1e-9


def test_chain_retraction_on_a_long_chain_and_across_the_angle_cut() -> None:
    rng = np.random.default_rng(3)
    x = _walk(rng, 10_000, 0.05, 0.02, 0.005)  # 250 m of loops, headings wrap 8 times
    assert np.ptp(np.unwrap(x[:, 2])) > 2 * np.pi
    delta = rng.normal(0.0, 1e-3, x.size)
    got, want = retract_chain(x, delta), _looped_chain(x, delta)
    assert _pose_diff(got, want) < 1e-9  # no rounding drift along 10^4 compositions
    # headings exactly at the cut: x + δ crosses ±π and is wrapped like retract_poses
    x[:, 2] = np.where(np.arange(x.shape[0]) % 2, np.pi - 1e-9, -np.pi)
    delta[2::3] = np.where(np.arange(x.shape[0]) % 2, 2e-9, -1e-9)
    np.testing.assert_array_equal(retract_chain(x, delta)[:, 2], retract_poses(x, delta)[:, 2])


def test_chain_retraction_is_exact_at_zero_and_first_order_additive() -> None:
    rng = np.random.default_rng(4)
    x = _walk(rng, 500, 0.5, 0.2)
    np.testing.assert_array_equal(retract_chain(x, np.zeros(x.size)), x)  # bit for bit
    delta = rng.normal(0.0, 1.0, x.size)
    gaps = [
        _pose_diff(retract_chain(x, t * delta), retract_poses(x, t * delta)) for t in (1e-3, 1e-4)
    ]
    assert gaps[1] < gaps[0] / 50  # second order: 100× smaller for a 10× smaller step


@pytest.mark.parametrize("motion", ["velocity", "odometry"])
def test_chain_retraction_reaches_the_minimum_of_the_additive_one(motion: str) -> None:
    b = simulate_bundle(11, steps=3000, measure_every=5, motion=motion)
    inp = filter_input(b, map_mode="ignore")  # poses only: the map exact, no map correction
    fr = run_filter(inp)
    used = fr.status == USED
    start = smooth(fr).poses
    new = refine(inp, start, used=used)
    # the pre-chain batch: additive steps, λ from 1e-6 with floor 1e-12, to a tight tolerance
    old_problem = _BatchProblem(inp, np.flatnonzero(used), None, chain=False)
    old_options = LMOptions(
        lambda_initial=1e-6, lambda_max=1e12, max_tries=100, max_iterations=200, ftol=0.0
    )
    old = levenberg_marquardt(old_problem, np.array(start), old_options)
    assert new.cost_final == pytest.approx(float(old.costs[-1]), rel=1e-11)
    assert _pose_diff(new.poses, old.x) < 1e-6
    assert new.iterations < old.iterations
    # and it is a stationary point: the Gauss–Newton step there is negligible
    problem = _BatchProblem(inp, np.flatnonzero(used), None)
    lin = problem.linearise(new.poses)
    assert np.abs(problem.solve(lin, np.zeros_like(lin.diagonal))).max() < 1e-6


def test_failed_factorisation_is_retried_with_the_damping_floor(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    import recovery.batch_refinement as batch

    b = simulate_bundle(12, steps=60, measure_every=4)
    inp = filter_input(b, map_mode="marginal")
    fr = run_filter(inp)
    problem = _BatchProblem(inp, np.flatnonzero(fr.status == USED), None)
    lin = problem.linearise(smooth(fr).poses)
    real, seen = batch._cholesky_solve, []

    def fails_first(ab, rhs):  # type: ignore[no-untyped-def]
        seen.append(ab[0].copy())
        if len(seen) == 1:
            raise np.linalg.LinAlgError("not positive definite")
        return real(ab, rhs)

    monkeypatch.setattr(batch, "_cholesky_solve", fails_first)
    damping = np.full_like(lin.diagonal, 1e-30)
    step = problem.solve(lin, damping)
    np.testing.assert_array_equal(seen[0], lin.system[0] + damping)
    np.testing.assert_array_equal(seen[1], lin.system[0] + 1e-12 * lin.diagonal)
    ab = lin.system.copy()
    ab[0] += 1e-12 * lin.diagonal
    np.testing.assert_allclose(step, solveh_banded(ab, -lin.gradient, lower=True), rtol=1e-12)
    monkeypatch.setattr(batch, "_cholesky_solve", lambda ab, rhs: real(-np.abs(ab), rhs))
    with pytest.raises(DivergenceError, match="not positive definite"):
        problem.solve(lin, damping)


def _small_problem(seed: int, steps: int = 200):  # type: ignore[no-untyped-def]
    b = simulate_bundle(seed, steps=steps, measure_every=4)
    inp = filter_input(b, map_mode="marginal")
    fr = run_filter(inp)
    return inp, np.flatnonzero(fr.status == USED), smooth(fr).poses


def test_motion_residuals_are_between_bit_for_bit() -> None:
    inp, used, x = _small_problem(21)
    (_, rm, _, _, _, _), (c, s), _ = _factors(inp, x, used)
    want = se2.between(x[:-1], x[1:]) - inp.u
    want[:, 2] = se2.wrap_angle(want[:, 2])
    np.testing.assert_array_equal(rm, want)
    np.testing.assert_array_equal(c, np.cos(x[:-1, 2]))
    np.testing.assert_array_equal(s, np.sin(x[:-1, 2]))


def test_lower_band_is_the_dense_matrix_and_its_solve() -> None:
    inp, used, x = _small_problem(22)
    wp, wm = _weights(inp)
    ab, g, _ = _band(inp, x, used, wp, wm)
    assert ab.flags.f_contiguous and ab.shape == (6, g.size)
    size = g.size
    dense = np.zeros((size, size))  # the band read back entry by entry: ab[i − j, j] = H[i, j]
    for d in range(6):
        idx = np.arange(size - d)
        dense[idx + d, idx] = ab[d, : size - d]
        dense[idx, idx + d] = ab[d, : size - d]
    rows = np.add.outer(np.arange(6), np.arange(size))  # ab[d, j] is H[j + d, j]
    assert np.all(ab[rows >= size] == 0.0)  # past the last row: LAPACK's unused corner
    rhs = np.random.default_rng(5).normal(size=size)
    got = _cholesky_solve(ab.copy(order="F"), rhs.copy())
    # backward stable: the residual is rounding of the (stiff, 1e11-sized) products
    assert np.all(np.abs(dense @ got - rhs) <= 1e-12 * (np.abs(dense) @ np.abs(got)))
    # SciPy's wrapper of the same LAPACK routine (with its checks and copies): bit for bit
    np.testing.assert_array_equal(got, solveh_banded(ab, rhs, lower=True))
    with pytest.raises(np.linalg.LinAlgError):
        _cholesky_solve(-ab.copy(order="F"), rhs.copy())


@pytest.mark.parametrize("seed", [23, 24])
def test_covariance_only_smoother_is_the_full_one_bit_for_bit(seed: int) -> None:
    inp, used, x = _small_problem(seed, steps=400)
    fr = run_filter(inp)  # the filter's own run
    np.testing.assert_array_equal(smoothed_covariances(fr), smooth(fr).covariances)
    # and the batch's covariance pass: linearised at given poses, regularised noise
    mask = fr.status == USED
    got = batch_covariances(inp, x, mask, regularised=regularised_sigma(inp.sigma))
    reg = replace(inp, sigma=regularised_sigma(inp.sigma), map_covariance=None)
    full = run_filter(reg, linearize_at=x, use=mask, max_outlier_run=None)
    np.testing.assert_array_equal(got, smooth(full).covariances)


def test_weights_from_a_given_regularisation_are_the_plain_ones() -> None:
    inp, _, _ = _small_problem(25)
    wp, wm = _weights(inp, regularised=regularised_sigma(inp.sigma))
    inv = np.linalg.inv(regularised_sigma(inp.sigma))
    np.testing.assert_array_equal(wm, 0.5 * (inv + inv.transpose(0, 2, 1)))  # bit for bit
    np.testing.assert_array_equal(wm, wm.transpose(0, 2, 1))
    np.testing.assert_array_equal(wp, _weights(inp)[0])
