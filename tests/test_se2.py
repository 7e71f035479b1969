"""SE(2) algebra: identities, round trips at large angles, vectorised == looped."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from relation_metric import se2

finite = st.floats(min_value=-1e3, max_value=1e3, allow_nan=False, allow_infinity=False)
angle = st.floats(min_value=-math.pi, max_value=math.pi, allow_nan=False, exclude_max=True)
pose = st.tuples(finite, finite, angle).map(np.array)
poses = arrays(np.float64, (7, 3), elements=st.floats(-50, 50)).map(se2.wrap_last)


def mat(p: np.ndarray) -> np.ndarray:
    c, s = math.cos(p[2]), math.sin(p[2])
    return np.array([[c, -s, p[0]], [s, c, p[1]], [0.0, 0.0, 1.0]])


def test_wrap_angle_range_and_identity():
    a = np.array([-3 * np.pi, -np.pi, -1e-18, 0.0, np.pi - 1e-12, np.pi, 3 * np.pi, 1e6])
    w = se2.wrap_angle(a)
    assert np.all(w >= -np.pi) and np.all(w < np.pi)
    assert w[1] == -np.pi and w[5] == -np.pi  # π maps to −π: the interval is [−π, π)
    np.testing.assert_allclose(np.sin(w), np.sin(a), atol=1e-9)
    np.testing.assert_allclose(np.cos(w), np.cos(a), atol=1e-9)


@given(pose, pose)
def test_compose_matches_matrix_product(a, b):
    expected = se2.from_matrix(mat(a) @ mat(b))
    got = se2.compose(a, b)
    np.testing.assert_allclose(got[:2], expected[:2], atol=1e-8)
    assert abs(se2.wrap_angle(got[2] - expected[2])) < 1e-9


@given(pose, pose)
def test_between_and_ominus(a, b):
    d = se2.between(a, b)
    back = se2.compose(a, d)
    np.testing.assert_allclose(back[:2], b[:2], atol=1e-8)
    assert abs(se2.wrap_angle(back[2] - b[2])) < 1e-9
    np.testing.assert_allclose(se2.ominus(b, a), d, atol=1e-9)
    np.testing.assert_allclose(se2.between(a, b), se2.compose(se2.inverse(a), b), atol=1e-8)


@given(pose)
def test_inverse(a):
    e = se2.compose(a, se2.inverse(a))
    np.testing.assert_allclose(e, np.zeros(3), atol=1e-8)


@given(st.tuples(finite, finite, angle).map(np.array))
def test_exp_log_round_trip_full_angle_range(xi):
    np.testing.assert_allclose(se2.log(se2.exp(xi)), xi, rtol=1e-9, atol=1e-8)


@given(pose)
def test_log_exp_round_trip(p):
    q = se2.exp(se2.log(p))
    np.testing.assert_allclose(q[:2], p[:2], rtol=1e-9, atol=1e-8)
    assert abs(se2.wrap_angle(q[2] - p[2])) < 1e-12


def test_exp_near_pi_and_small_angles():
    for phi in (np.pi - 1e-9, -np.pi, 1e-5, -1e-5, 1e-12, 0.0):
        xi = np.array([1.5, -0.7, phi])
        np.testing.assert_allclose(se2.log(se2.exp(xi)), se2.wrap_last(xi), atol=1e-9)
    # exp of a pure rotation is a rotation about the origin; small-angle series is continuous
    a, b = se2.exp([1.0, 0.0, 0.99e-4]), se2.exp([1.0, 0.0, 1.01e-4])
    np.testing.assert_allclose(a[:2], b[:2], atol=1e-5)


@given(poses, poses)
@settings(max_examples=50)
def test_vectorised_equals_looped(a, b):
    for fn in (se2.compose, se2.between, se2.ominus):
        vec = fn(a, b)
        loop = np.array([fn(x, y) for x, y in zip(a, b)])
        np.testing.assert_array_equal(vec, loop)
    for fn1 in (se2.inverse, se2.exp, se2.log):
        np.testing.assert_array_equal(fn1(a), np.array([fn1(x) for x in a]))


def test_broadcasting_one_against_many(rng):
    a = rng.normal(size=3)
    b = se2.wrap_last(rng.normal(size=(5, 4, 3)))
    out = se2.compose(a, b)
    assert out.shape == (5, 4, 3)
    np.testing.assert_allclose(out[2, 3], se2.compose(a, b[2, 3]))


def test_points_round_trip(rng):
    p = se2.wrap_last(rng.normal(size=(10, 3)) * 5)
    q = rng.normal(size=(10, 2)) * 10
    np.testing.assert_allclose(
        se2.inverse_transform_points(p, se2.transform_points(p, q)), q, atol=1e-12
    )
    # transform_points is the matrix action on homogeneous points
    h = np.einsum("nij,nj->ni", se2.to_matrix(p), np.column_stack((q, np.ones(10))))
    np.testing.assert_allclose(se2.transform_points(p, q), h[:, :2], atol=1e-12)


def test_cumulative_compose_equals_loop(rng):
    u = rng.normal(size=(200, 3)) * [0.5, 0.1, 0.3]
    x0 = np.array([1.0, -2.0, 3.0])
    fast = se2.cumulative_compose(u, start=x0)
    slow = [se2.wrap_last(x0)]
    for step in u:
        slow.append(se2.compose(slow[-1], step))
    np.testing.assert_allclose(fast, np.array(slow), atol=1e-9)


# --- derivatives (one home: se2) ----------------------------------------------------------


def _fd(f, x: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Central finite-difference Jacobian of ``f`` at ``x`` (an independent oracle)."""
    cols = []
    for k in range(x.size):
        e = np.zeros_like(x)
        e[k] = h
        cols.append((f(x + e) - f(x - e)) / (2 * h))
    return np.stack(cols, axis=-1)


def _between_unwrapped(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    d = se2.between(a, b)
    d[..., 2] = b[..., 2] - a[..., 2]  # the derivative is of the unwrapped difference
    return d


def test_between_jacobians_match_finite_differences(rng: np.random.Generator) -> None:
    a = rng.normal(size=(20, 3)) * [3.0, 3.0, 2.0]
    b = rng.normal(size=(20, 3)) * [3.0, 3.0, 2.0]
    d, j_a, j_b = se2.between(a, b, jacobians=True)
    np.testing.assert_array_equal(d, se2.between(a, b))
    assert j_a.shape == j_b.shape == (20, 3, 3)
    for k in range(20):
        fa = _fd(lambda x, k=k: _between_unwrapped(x, b[k]), a[k])
        fb = _fd(lambda x, k=k: _between_unwrapped(a[k], x), b[k])
        np.testing.assert_allclose(j_a[k], fa, atol=1e-7)
        np.testing.assert_allclose(j_b[k], fb, atol=1e-7)


def test_between_jacobians_broadcast_one_pose_against_many(rng: np.random.Generator) -> None:
    a, b = rng.normal(size=3), rng.normal(size=(5, 3))
    _, j_a, j_b = se2.between(a, b, jacobians=True)
    _, j_a1, j_b1 = se2.between(np.broadcast_to(a, (5, 3)), b, jacobians=True)
    np.testing.assert_array_equal(j_a, j_a1)
    np.testing.assert_array_equal(j_b, j_b1)


def test_compose_jacobian_and_shear_match_finite_differences(rng: np.random.Generator) -> None:
    a = rng.normal(size=(20, 3)) * [3.0, 3.0, 2.0]
    b = rng.normal(size=(20, 3)) * [3.0, 3.0, 0.5]
    f = se2.compose_jacobian(a, b)
    for k in range(20):

        def comp(x: np.ndarray, k: int = k) -> np.ndarray:
            out = se2.compose(x, b[k])
            out[2] = x[2] + b[k, 2]  # unwrapped
            return out

        np.testing.assert_allclose(f[k], _fd(comp, a[k]), atol=1e-7)
    step = se2.compose(a, b)[:, :2] - a[:, :2]
    np.testing.assert_allclose(se2.shear(step), f, atol=1e-12)


@pytest.mark.parametrize("scale", [1e-6, 1e-3, 9e-3, 1.1e-2, 0.3, 2.5])
def test_v_coefficients_and_derivatives(scale: float, rng: np.random.Generator) -> None:
    phi = rng.uniform(-1.0, 1.0, size=50) * scale
    a, b, da, db = se2.v_coefficients(phi, derivatives=True)
    a2, b2 = se2.v_coefficients(phi)
    np.testing.assert_array_equal(a, a2)
    np.testing.assert_array_equal(b, b2)
    # oracle: closed forms in extended precision where they do not cancel (long double)
    p = phi.astype(np.longdouble)
    np.testing.assert_allclose(a, np.sin(p) / p, rtol=1e-12)
    big = np.abs(phi) > 1e-3
    np.testing.assert_allclose(b[big], ((1 - np.cos(p)) / p)[big], rtol=1e-9)
    # derivatives against central differences of the function itself
    h = 1e-6
    ap, bp = se2.v_coefficients(phi + h)
    am, bm = se2.v_coefficients(phi - h)
    np.testing.assert_allclose(da, (ap - am) / (2 * h), atol=1e-8)
    np.testing.assert_allclose(db, (bp - bm) / (2 * h), atol=1e-8)


def test_v_coefficients_continuous_across_the_cut_off() -> None:
    eps = np.spacing(1e-2)
    below = se2.v_coefficients(np.array([1e-2 - eps, -1e-2 + eps]), derivatives=True)
    above = se2.v_coefficients(np.array([1e-2 + eps, -1e-2 - eps]), derivatives=True)
    for lo, hi in zip(below, above, strict=True):
        np.testing.assert_allclose(lo, hi, rtol=1e-11, atol=1e-15)


angles = st.one_of(
    st.floats(-1e6, 1e6, allow_nan=False),
    st.sampled_from([math.pi, -math.pi, math.nextafter(math.pi, 0), math.nextafter(-math.pi, -4)]),
    st.sampled_from([3 * math.pi, -3 * math.pi, 0.0, -0.0, 1e300, -1e300, math.nan]),
    st.floats(-1e-300, 1e-300),
)


@settings(max_examples=200, deadline=None)
@given(angles)
def test_scalar_wrap_is_wrap_angle_bit_for_bit(a):
    """The scalar twin used by the EKF's loop returns wrap_angle's bits, signed zeros and
    the exact ±π edges included."""
    got, want = se2.wrap_angle_float(a), se2.wrap_angle(a)
    assert isinstance(got, float)
    assert np.float64(got).tobytes() == np.asarray(want, dtype=np.float64).tobytes()


@settings(max_examples=200, deadline=None)
@given(poses, poses)
def test_minus_is_the_vector_difference_with_the_heading_wrapped(a, b):
    d = se2.minus(a, b)
    np.testing.assert_array_equal(d[:, :2], a[:, :2] - b[:, :2])  # exactly a − b
    assert np.all(d[:, 2] >= -np.pi) and np.all(d[:, 2] < np.pi)
    # the heading differs from θ_a − θ_b by a whole number of turns
    turns = (a[:, 2] - b[:, 2] - d[:, 2]) / (2 * np.pi)
    np.testing.assert_allclose(turns, np.round(turns), atol=1e-12)
    # not the group's ⊖: same heading (bit for bit), translation rotated into b's frame
    om = se2.ominus(a, b)
    np.testing.assert_array_equal(d[:, 2], om[:, 2])
    c, s = np.cos(b[:, 2]), np.sin(b[:, 2])
    rotated = np.column_stack((c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]))
    np.testing.assert_allclose(rotated, om[:, :2], rtol=1e-12, atol=1e-9)


def test_minus_by_hand_broadcasts_and_does_not_alias():
    a = np.array([[1.0, 2.0, 3.0], [0.0, 0.0, -3.0]])
    b = np.array([0.5, -1.0, -3.0])
    d = se2.minus(a, b)
    np.testing.assert_allclose(d, [[0.5, 3.0, 6.0 - 2 * np.pi], [-0.5, 1.0, 0.0]])
    assert d is not a and not np.shares_memory(d, a)
    one = se2.minus([0.0, 0.0, np.pi], [0.0, 0.0, 0.0])
    assert one.shape == (3,) and one[2] == -np.pi  # π wraps to −π
