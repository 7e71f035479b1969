"""recovery.lm: the one Levenberg–Marquardt, and batch recovery's normal equations.

Oracles: the linear least-squares solution (numpy lstsq), scipy.optimize.least_squares on
nonlinear problems, hand-wrapped angles, and a finite-difference Jacobian.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from scipy.optimize import least_squares

from recovery.batch_refinement import _factors, _weights, normal_equations
from recovery.ekf import USED, run_filter
from recovery.lm import (
    Linearisation,
    LMOptions,
    levenberg_marquardt,
    retract_poses,
)
from recovery.recover import filter_input
from relation_metric import se2
from relation_metric.errors import DivergenceError
from slamrel.simulation.bundles import simulate_bundle

Residuals = Callable[[np.ndarray], np.ndarray]


class Dense:
    """A small problem with residuals ``f`` and Jacobian ``jac`` (dense normal equations)."""

    def __init__(self, f: Residuals, jac: Callable[[np.ndarray], np.ndarray], poses: bool = False):
        self.f, self.jac, self.poses = f, jac, poses
        self.solves = 0

    def linearise(self, x: np.ndarray) -> Linearisation:
        r, j = self.f(x), self.jac(x)
        h = j.T @ j
        return Linearisation(0.5 * float(r @ r), j.T @ r, np.diag(h).copy(), h)

    def cost(self, x: np.ndarray) -> float:
        r = self.f(x)
        return 0.5 * float(r @ r)

    def solve(self, lin: Linearisation, damping: np.ndarray) -> np.ndarray:
        self.solves += 1
        return np.linalg.solve(lin.system + np.diag(damping), -lin.gradient)

    def retract(self, x: np.ndarray, delta: np.ndarray) -> np.ndarray:
        return retract_poses(x, delta) if self.poses else x + delta


def test_linear_least_squares_one_step_minimum() -> None:
    rng = np.random.default_rng(3)
    a, b = rng.normal(size=(30, 6)), rng.normal(size=30)
    prob = Dense(lambda x: a @ x - b, lambda x: a)
    res = levenberg_marquardt(prob, np.zeros(6), LMOptions(lambda_initial=1e-14))
    x_star = np.linalg.lstsq(a, b, rcond=None)[0]
    c_star = 0.5 * float(np.sum((a @ x_star - b) ** 2))
    # the first accepted step is the Gauss–Newton step: the minimum, to rounding
    assert res.costs[1] == pytest.approx(c_star, rel=1e-12)
    np.testing.assert_allclose(res.x, x_star, atol=1e-10)
    assert res.converged and not res.stopped
    assert res.iterations <= 2  # the next step finds no decrease (or a negligible one)


def _rosenbrock(n: int) -> tuple[Residuals, Callable[[np.ndarray], np.ndarray]]:
    """Extended Rosenbrock: ``r_{2i} = 10 (x_{2i+1} − x_{2i}²)``, ``r_{2i+1} = 1 − x_{2i}``."""

    def f(x: np.ndarray) -> np.ndarray:
        r = np.empty(n)
        r[0::2] = 10.0 * (x[1::2] - x[0::2] ** 2)
        r[1::2] = 1.0 - x[0::2]
        return r

    def jac(x: np.ndarray) -> np.ndarray:
        j = np.zeros((n, n))
        i = np.arange(0, n, 2)
        j[i, i] = -20.0 * x[i]
        j[i, i + 1] = 10.0
        j[i + 1, i] = -1.0
        return j

    return f, jac


@pytest.mark.parametrize("n", [2, 8])
def test_rosenbrock_matches_scipy_least_squares(n: int) -> None:
    f, jac = _rosenbrock(n)
    x0 = np.tile([-1.2, 1.0], n // 2)
    res = levenberg_marquardt(Dense(f, jac), x0, LMOptions(max_iterations=200, ftol=1e-15))
    ref = least_squares(f, x0, jac=jac, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    np.testing.assert_allclose(res.x, ref.x, atol=1e-7)
    np.testing.assert_allclose(res.x, np.ones(n), atol=1e-7)
    assert np.all(np.diff(res.costs) < 0)  # only decreasing steps are accepted
    assert res.converged


def test_angle_wrap_through_the_retraction() -> None:
    target = np.array([1.0, -2.0, -3.1])

    def f(x: np.ndarray) -> np.ndarray:
        r = x[0] - target
        r[2] = se2.wrap_angle(r[2])
        return r

    prob = Dense(f, lambda x: np.eye(3), poses=True)
    start = np.array([[0.0, 0.0, 3.1]])  # 0.083 rad from the target across ±π
    res = levenberg_marquardt(prob, start, LMOptions(lambda_initial=1e-12))
    assert -np.pi <= res.x[0, 2] < np.pi
    np.testing.assert_allclose(res.x[0], target, atol=1e-12)
    # the retraction itself: add, then wrap θ only
    out = retract_poses(
        np.array([[1.0, 2.0, 3.0], [0.0, 0.0, -3.0]]), np.array([1, 1, 1, 0, 0, -1.0])
    )
    np.testing.assert_allclose(out, [[2.0, 3.0, 4.0 - 2 * np.pi], [0.0, 0.0, 2 * np.pi - 4.0]])


def test_stopping_rules() -> None:
    f, jac = _rosenbrock(2)
    x0 = np.array([-1.2, 1.0])
    # at the minimum: no decrease possible → converged after one iteration, max_tries solves
    prob = Dense(f, jac)
    res = levenberg_marquardt(prob, np.ones(2), LMOptions(max_tries=5))
    assert res.converged and res.iterations == 1 and res.costs.size == 1 and prob.solves == 5
    # lambda_max ends the search before max_tries: 1e-4 · 10^k ≤ 1e-1 → 4 solves
    prob = Dense(f, jac)
    levenberg_marquardt(prob, np.ones(2), LMOptions(max_tries=50, lambda_max=1e-1))
    assert prob.solves == 4
    # the caller's stop
    calls: list[tuple[float, float]] = []

    def stop(c: float, c_new: float) -> bool:
        calls.append((c, c_new))
        return True

    res = levenberg_marquardt(Dense(f, jac), x0, stop=stop)
    assert res.stopped and not res.converged and res.iterations == 1 and len(calls) == 1
    assert calls[0] == (res.costs[0], res.costs[1])
    # max_iterations
    res = levenberg_marquardt(Dense(f, jac), x0, LMOptions(max_iterations=2))
    assert res.iterations == 2 and not res.converged and res.costs.size == 3
    # xtol: a huge tolerance stops after the first accepted step
    res = levenberg_marquardt(Dense(f, jac), x0, LMOptions(xtol=1e3))
    assert res.converged and res.iterations == 1


def test_singular_or_non_finite_is_divergence() -> None:
    prob = Dense(lambda x: np.array([x[0] - 1.0]), lambda x: np.array([[1.0, 0.0]]))
    prob.solve = lambda lin, damping: np.full(2, np.nan)  # type: ignore[method-assign]
    with pytest.raises(DivergenceError, match="singular"):
        levenberg_marquardt(prob, np.zeros(2))
    # the residual is infinite beyond x = 0.5, where the first step (to x = 1) lands
    bad = Dense(lambda x: np.array([x[0] - 1.0 if x[0] < 0.5 else np.inf]), lambda x: np.eye(1))
    with pytest.raises(DivergenceError, match="non-finite cost at iteration 1"):
        levenberg_marquardt(bad, np.array([0.0]), LMOptions(lambda_initial=1e-12))


@pytest.mark.parametrize("motion", ["velocity", "odometry"])
def test_batch_normal_equations_equal_finite_difference_jacobian(motion: str) -> None:
    b = simulate_bundle(5, steps=40, measure_every=3, motion=motion)
    inp = filter_input(b, map_mode="marginal")
    used = np.flatnonzero(run_filter(inp).status == USED)
    x = run_filter(inp).poses + np.random.default_rng(1).normal(0, 0.02, (inp.times.size, 3))
    wp, wm = _weights(inp)
    _, _, _, wz, _, _ = _factors(inp, x, used)[0]  # measurement weights held at x

    def r(xf: np.ndarray) -> np.ndarray:
        rp, rm, rz, _, _, _ = _factors(inp, xf.reshape(-1, 3), used)[0]
        return np.concatenate((rp, rm.ravel(), rz.ravel()))

    n = x.size
    eps = 1e-6
    jac = np.stack(
        [(r(x.ravel() + eps * e) - r(x.ravel() - eps * e)) / (2 * eps) for e in np.eye(n)], axis=1
    )
    blocks = [wp, *wm, *wz]
    w = np.zeros((jac.shape[0], jac.shape[0]))
    at = 0
    for blk in blocks:  # the oracle assembles W block by block
        k = blk.shape[0]
        w[at : at + k, at : at + k] = blk
        at += k
    h, g, cost, _ = normal_equations(inp, x, used)
    h_ref = jac.T @ w @ jac
    np.testing.assert_allclose(h.toarray(), h_ref, rtol=1e-5, atol=1e-6 * np.abs(h_ref).max())
    g_ref = jac.T @ w @ r(x.ravel())
    np.testing.assert_allclose(g, g_ref, rtol=1e-5, atol=1e-6 * np.abs(g_ref).max())
    assert cost == pytest.approx(0.5 * r(x.ravel()) @ w @ r(x.ravel()), rel=1e-12)
