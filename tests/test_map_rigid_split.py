"""recovery.anchoring.rigid_split: a map's error split into a rigid motion and the rest."""

from __future__ import annotations

import numpy as np
import pytest

from recovery.anchoring import rigid_split
from relation_metric.errors import InputError


def _rot(theta: float) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s], [s, c]])


def _landmarks(rng: np.random.Generator, n: int = 12) -> np.ndarray:
    return rng.uniform(-15.0, 15.0, (n, 2))


def _cov(rng: np.random.Generator, n: int) -> np.ndarray:
    a = rng.normal(0.0, 0.05, (2 * n, 2 * n))
    return a @ a.T + 0.01 * np.eye(2 * n)


@pytest.mark.parametrize("weighted", [False, True])
def test_known_rigid_motion_is_recovered_exactly(weighted: bool) -> None:
    """A true map moved by (dx, dy, θ): that motion, zero residual, rigid part = the move."""
    rng = np.random.default_rng(1)
    t = _landmarks(rng)
    dx, dy, th = 0.4, -0.7, np.radians(3.0)
    m = t @ _rot(th).T + [dx, dy]
    s = rigid_split(m, t, _cov(rng, len(t)) if weighted else None)
    assert (s.dx, s.dy, s.dtheta) == pytest.approx((dx, dy, th), abs=1e-12)
    np.testing.assert_allclose(s.residual, 0.0, atol=1e-12)
    np.testing.assert_allclose(s.rigid, m - t, atol=1e-12)
    if weighted:
        assert s.nees_residual == pytest.approx(0.0, abs=1e-18)
        assert s.nees_rigid is not None and s.nees_rigid > 0.0
    else:
        assert s.nees_rigid is None and s.nees_residual is None


def test_parts_add_up_and_nees_adds_to_the_total() -> None:
    """rigid + residual = m − t; NEES_rigid + NEES_residual = eᵀ P⁻¹ e (a hand computation)."""
    rng = np.random.default_rng(2)
    t = _landmarks(rng, 7)
    p = _cov(rng, 7)
    m = t + rng.multivariate_normal(np.zeros(14), p).reshape(7, 2)
    s = rigid_split(m, t, p)
    np.testing.assert_allclose(s.rigid + s.residual, m - t, atol=1e-12)
    e = (m - t).reshape(-1)
    assert s.nees_rigid + s.nees_residual == pytest.approx(float(e @ np.linalg.solve(p, e)))
    assert (s.dof_rigid, s.dof_residual) == (3, 11)


def test_weighted_fit_is_the_gls_projection_for_small_errors() -> None:
    """With a linear gauge (small motion), NEES_rigid is the generalised least-squares
    projection ``eᵀ W G (Gᵀ W G)⁻¹ Gᵀ W e`` of the error on the gauge directions G."""
    rng = np.random.default_rng(3)
    n = 9
    t = _landmarks(rng, n)
    p = _cov(rng, n) * 1e-6
    m = t + rng.multivariate_normal(np.zeros(2 * n), p).reshape(n, 2)
    s = rigid_split(m, t, p)
    g = np.zeros((n, 2, 3))
    g[:, 0, 0] = g[:, 1, 1] = 1.0
    g[:, 0, 2], g[:, 1, 2] = -t[:, 1], t[:, 0]
    g = g.reshape(2 * n, 3)
    w = np.linalg.inv(p)
    e = (m - t).reshape(-1)
    b = g.T @ w @ e
    assert s.nees_rigid == pytest.approx(float(b @ np.linalg.solve(g.T @ w @ g, b)), rel=1e-4)


def test_residual_invariant_under_a_common_rigid_motion() -> None:
    """Moving both maps by one rigid motion rotates the residual with it and keeps both NEES
    (the covariance rotated alike)."""
    rng = np.random.default_rng(4)
    n = 10
    t = _landmarks(rng, n)
    p = _cov(rng, n)
    m = t + rng.multivariate_normal(np.zeros(2 * n), p).reshape(n, 2)
    a = rigid_split(m, t, p)
    r = _rot(0.8)
    big = np.kron(np.eye(n), r)
    b = rigid_split(m @ r.T + [5.0, -3.0], t @ r.T + [5.0, -3.0], big @ p @ big.T)
    np.testing.assert_allclose(b.residual, a.residual @ r.T, atol=1e-9)
    assert b.nees_residual == pytest.approx(a.nees_residual, rel=1e-8)
    assert b.nees_rigid == pytest.approx(a.nees_rigid, rel=1e-8)
    assert b.dtheta == pytest.approx(a.dtheta, abs=1e-10)


def test_maps_drawn_from_their_covariance_have_nees_near_dof() -> None:
    """Over 400 maps drawn from their stated covariance, the mean NEES is its degrees of
    freedom (χ²₃ and χ²_{2n−3}): within 4 standard errors of the mean."""
    rng = np.random.default_rng(5)
    n, runs = 8, 400
    t = _landmarks(rng, n)
    p = _cov(rng, n)
    draws = rng.multivariate_normal(np.zeros(2 * n), p, size=runs).reshape(runs, n, 2)
    rig = np.array([rigid_split(t + d, t, p).nees_rigid for d in draws])
    res = np.array([rigid_split(t + d, t, p).nees_residual for d in draws])
    for x, dof in ((rig, 3), (res, 2 * n - 3)):
        assert abs(x.mean() - dof) < 4.0 * np.sqrt(2.0 * dof / runs)


def test_remove_takes_the_rigid_part_away() -> None:
    """T̂⁻¹ applied to the estimate leaves truth + rotated residual; distances kept."""
    rng = np.random.default_rng(6)
    t = _landmarks(rng, 6)
    m = (t + rng.normal(0, 0.05, t.shape)) @ _rot(0.05).T + [0.3, 0.1]
    p = _cov(rng, 6)
    s = rigid_split(m, t, p)
    xy, q = s.remove(m, p)
    np.testing.assert_allclose(xy - t, s.residual @ _rot(-s.dtheta).T, atol=1e-12)
    dist = lambda a: np.linalg.norm(a[:, None] - a[None], axis=2)  # noqa: E731
    np.testing.assert_allclose(dist(xy), dist(m), atol=1e-12)
    assert q is not None
    np.testing.assert_allclose(np.linalg.eigvalsh(q), np.linalg.eigvalsh(p), rtol=1e-10)


@pytest.mark.parametrize(
    "m, t, cov",
    [
        (np.zeros((1, 2)), np.zeros((1, 2)), None),
        (np.zeros((3, 2)), np.zeros((4, 2)), None),
        (np.zeros((3, 2)), np.zeros((3, 2)), np.eye(5)),
        (np.ones((3, 2)), np.arange(6.0).reshape(3, 2), -np.eye(6)),
    ],
)
def test_invalid_input_is_an_input_error(m, t, cov) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(InputError):
        rigid_split(m, t, cov)
