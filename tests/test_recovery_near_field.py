"""Near-field measurements (issue 36): an epoch's measurement whose landmark lies inside the 99 %
region of the prior relative position is processed after the others, against a brute-force
Bayesian posterior on a grid (the oracle) and a hand computation of the order."""

from __future__ import annotations

import numpy as np
import pytest

import recovery.ekf as ekf
from recovery.ekf import NEAR_FIELD_CHI2, FilterInput, run_filter

SIG = (0.3, 0.3, 0.2)  # prior sd of x, y, θ (complex1/b/72 at t = 152 s: 0.29, 0.21, 0.20)
R_SD = (0.1, 0.05)  # range [m], bearing [rad]
TRUE = np.array([-0.6, 0.15, -0.07])  # a 2σ prior error, the estimate at the origin
#: landmark 0 at 0.05 m from the estimate (the near-field one, listed first), the others 2–5 m
LANDMARKS = np.array(
    [[0.05, 0.0], [3.0, 1.0], [-2.0, 3.0], [4.0, -2.0], [-3.5, -2.5], [1.0, -4.0], [2.5, 3.5]]
)


def _range_bearing(pose: np.ndarray, lm: np.ndarray) -> np.ndarray:
    """(..., 3) poses, (M, 2) landmarks -> (..., M, 2) range, bearing (wrapped)."""
    d = lm - pose[..., None, :2]
    b = np.arctan2(d[..., 1], d[..., 0]) - pose[..., None, 2]
    return np.stack((np.hypot(d[..., 0], d[..., 1]), np.angle(np.exp(1j * b))), axis=-1)


def _input(z: np.ndarray, landmarks: np.ndarray = LANDMARKS, map_sd: float = 1e-4) -> FilterInput:
    m = landmarks.shape[0]
    return FilterInput(
        times=np.array([0.0, 1.0]),
        u=np.zeros((1, 3)),
        sigma=np.diag([1e-4, 1e-4, 1e-6])[None],
        x0=np.zeros(3),
        p0=np.diag(np.square(SIG)),
        meas_grid=np.zeros(m, dtype=np.int64),
        meas_z=z,
        meas_landmark=np.arange(m, dtype=np.int64),
        map_xy=landmarks,
        map_marginals=np.repeat(map_sd**2 * np.eye(2)[None], m, axis=0),
        map_covariance=map_sd**2 * np.eye(2 * m),
        r=np.diag(np.square(R_SD)),
    )


def _grid_posterior_mean(z: np.ndarray) -> np.ndarray:
    """Posterior mean of the pose: Gaussian prior × exact range-bearing likelihood on a grid
    over ±5σ, then on a finer grid around the first mean (the posterior is unimodal here)."""

    def mean(lo: np.ndarray, hi: np.ndarray, n: int) -> np.ndarray:
        ax = [np.linspace(a, b, n) for a, b in zip(lo, hi)]
        g = np.stack(np.meshgrid(*ax, indexing="ij"), axis=-1).reshape(-1, 3)
        r = z - _range_bearing(g, LANDMARKS)
        r[..., 1] = np.angle(np.exp(1j * r[..., 1]))
        log = -0.5 * (np.square(g / SIG).sum(-1) + np.square(r / R_SD).sum((-1, -2)))
        w = np.exp(log - log.max())
        return (w[:, None] * g).sum(0) / w.sum()

    s = np.array(SIG)
    c = mean(-5 * s, 5 * s, 61)
    half = np.array([0.25, 0.25, 0.1])
    return mean(c - half, c + half, 51)


def test_order_by_hand() -> None:
    # Mahalanobis distance² of each landmark from the estimate under C = P_pp + Σ_l (isotropic,
    # no cross-covariance yet): ‖l‖² / (0.3² + 1e-8); only landmark 0 (0.05²/0.09 = 0.028) is
    # below χ²₂(0.99) = 9.21 (landmark 1: 10/0.09 = 111)
    d2 = np.square(LANDMARKS).sum(1) / (SIG[0] ** 2 + 1e-8)
    assert (d2 < NEAR_FIELD_CHI2).tolist() == [True] + [False] * 6
    fr = run_filter(_input(_range_bearing(TRUE, LANDMARKS)))
    assert np.asarray(fr.order).tolist() == [1, 2, 3, 4, 5, 6, 0]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_near_field_last_matches_grid_posterior(seed: int) -> None:
    rng = np.random.default_rng(seed)
    z = _range_bearing(TRUE, LANDMARKS) + rng.normal(0.0, R_SD, (LANDMARKS.shape[0], 2))
    oracle = _grid_posterior_mean(z)
    fr = run_filter(_input(z), max_outlier_run=None)
    post = fr.post_poses[0]
    # the 6 far landmarks localise the pose to ~0.05 m; the near one, linearised at the origin
    # first (the order before issue 36), sent it 0.3–1 m away and the NIS beyond 13
    assert np.abs(post[:2] - oracle[:2]).max() < 0.03
    assert abs(post[2] - oracle[2]) < 0.02
    assert np.nanmax(fr.nis) < 13.8  # χ²₂(0.999)


def test_no_near_field_keeps_the_order() -> None:
    # the far landmarks alone (none within the prior's 99 % region): the input's order, and the
    # same posterior as with the near one last (it adds little once the pose is localised)
    far = LANDMARKS[1:]
    fr = run_filter(_input(_range_bearing(TRUE, far), far))
    assert np.asarray(fr.order).tolist() == [0, 1, 2, 3, 4, 5]
    both = run_filter(_input(_range_bearing(TRUE, LANDMARKS)))
    assert np.abs(both.post_poses[0] - fr.post_poses[0]).max() < 0.02


@pytest.mark.parametrize(
    ("d", "c"),
    [
        ((0.05, 0.0), (0.09, 0.0, 0.09)),  # the singularity at 0.17 σ (complex1/b/72)
        ((0.2, 0.1), (0.09, 0.01, 0.05)),
        ((-0.6, -0.2), (0.14, 0.02, 0.1)),  # complex1/c/77 at t = 122 s
        ((1.0, 0.5), (0.04, 0.0, 0.04)),  # far: A is the Jacobian, Ω ≈ 0
    ],
)
def test_statistical_linearisation_against_monte_carlo(d: tuple, c: tuple) -> None:
    # the oracle: 10⁶ draws of d ~ N(d̂, C), range and bearing (wrapped around atan2(d̂)),
    # their regression on d and its residual covariance
    rng = np.random.default_rng(5)
    cov = np.array([[c[0], c[1]], [c[1], c[2]]])
    x = rng.multivariate_normal(d, cov, 1_000_000)
    ref = np.arctan2(d[1], d[0])
    g = np.column_stack(
        (np.hypot(x[:, 0], x[:, 1]), np.angle(np.exp(1j * (np.arctan2(x[:, 1], x[:, 0]) - ref))))
    )
    mg = g.mean(0)
    k = (g - mg).T @ (x - x.mean(0)) / x.shape[0]
    a = k @ np.linalg.inv(np.cov(x.T))
    om = np.cov(g.T) - a @ k.T
    got = ekf._slr(d, c, (0.01, 0.0025))
    assert got is not None
    (a00, a01, a10, a11), rng_m, bearing, (o00, o01, o11) = got
    assert np.abs(np.array([[a00, a01], [a10, a11]]) - a).max() < 0.02 * np.abs(a).max()
    assert abs(rng_m - mg[0]) < 1e-3 and abs(np.angle(np.exp(1j * (bearing - ref - mg[1])))) < 0.01
    got_om = np.array([[o00 - 0.01, o01], [o01, o11 - 0.0025]])
    assert np.abs(got_om - om).max() < 0.02 * max(np.abs(om).max(), 1e-3)
    if np.hypot(*d) > 4 * np.sqrt(c[0]):  # far: the analytic Jacobian
        r = np.hypot(*d)
        jac = np.array([[d[0] / r, d[1] / r], [-d[1] / r**2, d[0] / r**2]])
        assert np.abs(np.array([[a00, a01], [a10, a11]]) - jac).max() < 0.05
