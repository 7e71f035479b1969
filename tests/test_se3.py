"""SE(3) algebra (relation_metric.se3) and the pose-group parameter (relation_metric.groups)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from relation_metric import se2, se3
from relation_metric.groups import SE2, SE3, common_group, group_of


def random_poses(rng, n, scale=1.0):
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return np.column_stack((rng.normal(size=(n, 3)) * scale, q))


def test_compose_between_inverse_match_matrices(rng):
    a, b = random_poses(rng, 200), random_poses(rng, 200)
    m = se3.to_matrix
    np.testing.assert_allclose(m(se3.compose(a, b)), m(a) @ m(b), atol=1e-12)
    np.testing.assert_allclose(m(se3.between(a, b)), np.linalg.inv(m(a)) @ m(b), atol=1e-12)
    np.testing.assert_allclose(m(se3.inverse(a)), np.linalg.inv(m(a)), atol=1e-12)
    np.testing.assert_allclose(m(se3.ominus(a, b)), np.linalg.inv(m(b)) @ m(a), atol=1e-12)


def test_exp_log_round_trip_and_scipy(rng):
    p = random_poses(rng, 300)
    np.testing.assert_allclose(se3.to_matrix(se3.exp(se3.log(p))), se3.to_matrix(p), atol=1e-12)
    rv = Rotation.from_quat(p[:, 3:]).as_rotvec()
    np.testing.assert_allclose(se3.rotation_vector(p[:, 3:]), rv, atol=1e-12)
    np.testing.assert_allclose(se3.rotation_angle(p[:, 3:]), np.linalg.norm(rv, axis=1), atol=1e-12)
    # exp against the matrix exponential of the twist
    from scipy.linalg import expm

    xi = rng.normal(size=(20, 6))
    for k in range(20):  # oracle only: a loop over 20 samples
        hat = np.zeros((4, 4))
        w = xi[k, 3:]
        hat[:3, :3] = [[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]]
        hat[:3, 3] = xi[k, :3]
        np.testing.assert_allclose(se3.to_matrix(se3.exp(xi[k])), expm(hat), atol=1e-12)


@settings(max_examples=100, deadline=None)
@given(st.floats(1e-12, 1e-3), st.integers(0, 2**31 - 1))
def test_small_angles_are_accurate(angle, seed):
    rng = np.random.default_rng(seed)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    xi = np.concatenate((rng.normal(size=3), angle * axis))
    back = se3.log(se3.exp(xi))
    np.testing.assert_allclose(back, xi, rtol=0, atol=1e-15 + 1e-12 * np.abs(xi).max())
    assert se3.rotation_angle(se3.exp(xi)[3:]) == pytest.approx(angle, rel=1e-12)


def test_euler_zyx_matches_scipy_and_round_trips(rng):
    q = random_poses(rng, 200)[:, 3:]
    rpy = se3.euler_zyx(q)
    np.testing.assert_allclose(rpy, Rotation.from_quat(q).as_euler("ZYX")[:, ::-1], atol=1e-12)
    back = se3.from_euler_zyx(rpy)
    np.testing.assert_allclose(
        Rotation.from_quat(back).as_matrix(), Rotation.from_quat(q).as_matrix(), atol=1e-12
    )


def test_planar_poses_give_the_se2_algebra(rng):
    a = se2.wrap_last(rng.normal(size=(100, 3)) * [2, 2, 3])
    b = se2.wrap_last(rng.normal(size=(100, 3)) * [2, 2, 3])
    la, lb = se3.from_planar(a), se3.from_planar(b)
    np.testing.assert_allclose(se3.to_planar(se3.between(la, lb)), se2.between(a, b), atol=1e-12)
    np.testing.assert_allclose(se3.to_planar(se3.compose(la, lb)), se2.compose(a, b), atol=1e-12)
    np.testing.assert_allclose(SE3.log(la)[:, [0, 1, 5]], se2.log(a), atol=1e-12)
    np.testing.assert_allclose(SE3.error_components(la), SE2.error_components(a), atol=1e-12)
    np.testing.assert_allclose(SE3.parameters(la), SE2.parameters(a), atol=1e-12)


def test_interpolation_midpoint_is_half_the_twist(rng):
    a, b = random_poses(rng, 50), random_poses(rng, 50)
    mid = SE3.interpolate(a, b, np.full(50, 0.5))
    # mid⁻¹ ∘ b equals a⁻¹ ∘ mid (constant twist)
    np.testing.assert_allclose(
        se3.to_matrix(se3.between(mid, b)), se3.to_matrix(se3.between(a, mid)), atol=1e-12
    )
    np.testing.assert_allclose(
        se3.to_matrix(SE3.interpolate(a, b, np.ones(50))), se3.to_matrix(b), atol=1e-12
    )


def test_group_of_and_common_group():
    assert group_of(np.zeros((4, 3))) is SE2
    assert group_of(np.zeros((4, 7))) is SE3
    with pytest.raises(ValueError, match="3 .* or 7"):
        group_of(np.zeros((4, 5)))
    assert common_group(SE2, SE2) is SE2
    assert common_group(SE2, SE3) is SE3
