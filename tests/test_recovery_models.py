"""recovery.models: every Jacobian against central finite differences, the arc against the
textbook formula, straight-line limit, odometry δ round trip, noise parameterisations."""

from __future__ import annotations

import numpy as np
import pytest

from recovery.models import (
    MotionModel,
    increment_covariance,
    odometry_delta_covariance,
    odometry_deltas,
    odometry_from_deltas,
    process_noise,
    range_bearing,
    velocity_increment,
)
from relation_metric import se2


def fd(fun, x, eps=1e-6):  # type: ignore[no-untyped-def]
    """Central differences of fun at x, shape (out, in)."""
    x = np.asarray(x, dtype=float)
    cols = []
    for i in range(x.size):
        d = np.zeros_like(x)
        d[i] = eps
        diff = np.asarray(fun(x + d)) - np.asarray(fun(x - d))
        cols.append(diff / (2 * eps))
    return np.stack(cols, axis=-1)


@pytest.mark.parametrize("omega", [0.7, -1.3, 0.0249, 0.0251, 1e-3, 1e-5, 1e-9, 0.0])
def test_velocity_jacobian_matches_finite_differences(omega: float) -> None:
    dt = 0.4
    _, j = velocity_increment(1.3, omega, dt)
    num = fd(lambda c: velocity_increment(c[0], c[1], dt)[0], [1.3, omega], eps=1e-4)
    np.testing.assert_allclose(j, num, atol=1e-9)


def test_velocity_arc_equals_probabilistic_robotics_eq_5_9(rng: np.random.Generator) -> None:
    x = np.array([1.0, -2.0, 0.4])
    for v, w, dt in rng.uniform([-2, -2, 0.01], [2, 2, 1.0], (20, 3)):
        u, _ = velocity_increment(v, w, dt)
        got = se2.compose(x, u)
        r = v / w
        exp = [
            x[0] - r * np.sin(x[2]) + r * np.sin(x[2] + w * dt),
            x[1] + r * np.cos(x[2]) - r * np.cos(x[2] + w * dt),
            se2.wrap_angle(x[2] + w * dt),
        ]
        np.testing.assert_allclose(got, exp, atol=1e-12)


def test_velocity_straight_line_limit() -> None:
    u, _ = velocity_increment(2.0, 0.0, 0.5)
    np.testing.assert_allclose(u, [1.0, 0.0, 0.0], atol=0)
    u_small, _ = velocity_increment(2.0, 1e-7, 0.5)
    np.testing.assert_allclose(u_small, [1.0, 2.0 * 0.5 * 0.5e-7 / 2 * 1.0, 5e-8], atol=1e-15)


def test_odometry_deltas_round_trip_and_jacobian(rng: np.random.Generator) -> None:
    u = np.column_stack((rng.uniform(-1, 1, 50), rng.uniform(-1, 1, 50), rng.uniform(-3, 3, 50)))
    delta, j = odometry_deltas(u)
    back = odometry_from_deltas(delta)
    np.testing.assert_allclose(back[:, :2], u[:, :2], atol=1e-12)
    np.testing.assert_allclose(se2.wrap_angle(back[:, 2] - u[:, 2]), 0, atol=1e-12)
    for k in range(5):
        np.testing.assert_allclose(j[k], fd(odometry_from_deltas, delta[k]), atol=1e-8)


def test_odometry_alpha_variances_by_hand() -> None:
    delta = np.array([0.2, 1.5, -0.1])
    m = odometry_delta_covariance(delta, (0.1, 0.2, 0.3, 0.4))
    exp = np.diag(
        [0.1 * 0.04 + 0.2 * 2.25, 0.3 * 2.25 + 0.4 * (0.04 + 0.01), 0.1 * 0.01 + 0.2 * 2.25]
    )
    np.testing.assert_allclose(m, exp, rtol=1e-14)


def test_increment_covariance_parameterisations() -> None:
    # velocity sigma: Σ = J diag(σv², σω²) Jᵀ with J from finite differences
    v, w, dt = 1.1, 0.3, 0.2
    u, _ = velocity_increment(v, w, dt)
    j = fd(lambda c: velocity_increment(c[0], c[1], dt)[0], [v, w])
    sig = increment_covariance(MotionModel("velocity", sigma=(0.1, 0.05)), u, [v, w, dt, 1.0])
    np.testing.assert_allclose(sig, j @ np.diag([0.01, 0.0025]) @ j.T, atol=1e-12)
    # velocity alpha (PR Table 5.3)
    a = (0.1, 0.2, 0.3, 0.4)
    sig = increment_covariance(MotionModel("velocity", alpha=a), u, [v, w, dt, 2.0])
    m = 2.0 * np.diag([0.1 * v * v + 0.2 * w * w, 0.3 * v * v + 0.4 * w * w])
    np.testing.assert_allclose(sig, j @ m @ j.T, atol=1e-12)
    # odometry sigma: diagonal, scaled
    s = increment_covariance(MotionModel("odometry", sigma=(0.1, 0.2, 0.3)), u, 0.5)
    np.testing.assert_allclose(s, 0.5 * np.diag([0.01, 0.04, 0.09]), atol=0)


def test_compose_jacobian_and_process_noise(rng: np.random.Generator) -> None:
    x, u = rng.normal(size=3), rng.normal(size=3)
    np.testing.assert_allclose(
        se2.compose_jacobian(x, u), fd(lambda a: se2.compose(a, u), x), atol=1e-8
    )
    # Q is the covariance of x ∘ (u + n): Jacobian w.r.t. u at small u is Rot(θ)
    sig = np.diag([0.1, 0.2, 0.3])
    ju = fd(lambda b: se2.compose(x, b), np.zeros(3))
    np.testing.assert_allclose(process_noise(x[2], sig), ju @ sig @ ju.T, atol=1e-9)


def test_range_bearing_jacobians(rng: np.random.Generator) -> None:
    for _ in range(10):
        x, lm = rng.normal(size=3), rng.normal(size=2) * 5
        z, hx, hl = range_bearing(x, lm)
        np.testing.assert_allclose(hx, fd(lambda a, lm=lm: range_bearing(a, lm)[0], x), atol=1e-7)
        np.testing.assert_allclose(hl, fd(lambda b, x=x: range_bearing(x, b)[0], lm), atol=1e-7)
        d = lm - x[:2]
        assert z[0] == pytest.approx(np.hypot(*d))
        assert -np.pi <= z[1] < np.pi


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"type": "Velocity", "sigma": (0.1, 0.1)}, "motion_model.type: unknown type 'Velocity'"),
        ({"type": "odometry"}, "exactly one of them"),
        ({"type": "velocity", "sigma": (0.1, 0.1), "alpha": (0, 0, 0, 0)}, "exactly one"),
        ({"type": "velocity", "sigma": (0.1, 0.1, 0.1)}, "motion_model.sigma (velocity)"),
        ({"type": "odometry", "sigma": (0.1, 0.1)}, "expected 3 numbers, got 2"),
        ({"type": "odometry", "alpha": (0.1, 0.1, 0.1)}, "motion_model.alpha (odometry)"),
        ({"type": "velocity", "sigma": (0.1, -0.1)}, "expected finite numbers >= 0, got -0.1"),
        ({"type": "velocity", "sigma": (np.float64(np.nan), 0.1)}, "got nan"),
        ({"type": "velocity", "sigma": 0.1}, "expected 2 numbers"),
    ],
)
def test_motion_model_validates_its_fields(kwargs: dict, message: str) -> None:  # type: ignore[type-arg]
    from relation_metric.errors import InputError

    with pytest.raises(InputError) as err:
        MotionModel(**kwargs)
    assert message in str(err.value) and "np.float64" not in str(err.value)


def test_motion_and_sensor_models_store_floats_and_round_trip() -> None:
    from recovery.models import SensorModel
    from relation_metric.errors import InputError

    m = MotionModel("velocity", sigma=[np.float64(0.1), 1])  # type: ignore[arg-type]
    assert m.sigma == (0.1, 1.0) and all(type(v) is float for v in m.sigma)
    assert m.as_dict() == {
        "type": "velocity",
        "integration": "arc",
        "control_stamp": "start",
        "sigma_v": 0.1,
        "sigma_omega": 1.0,
    }
    o = MotionModel("odometry", alpha=(0.1, 0.2, 0.3, 0.4))
    assert o.as_dict() == {"type": "odometry", "alpha": [0.1, 0.2, 0.3, 0.4]}
    assert SensorModel(0.0, 0.0).covariance.sum() == 0.0  # noise-free simulation allowed
    with pytest.raises(InputError, match="sensor_model.sigma_bearing"):
        SensorModel(0.1, -1.0)
    with pytest.raises(InputError, match="sensor_model.type: unknown type 'bearing_only'"):
        SensorModel(0.1, 0.1, type="bearing_only")
