"""The reference EKF-SLAM's iterated update (``iterations`` > 1).

Oracles: the iterate is the minimum of the update's local MAP cost (its gradient vanishes, by
central differences, and the cost is below the prior's); a measurement that agrees with the
prediction moves nothing; as the prior shrinks, the iterated update tends to the plain one
(the linearisation error vanishes); refusals name the option.
"""

from __future__ import annotations

import numpy as np
import pytest

import slamrel.backends.ekf_slam as ekf
from recovery.models import range_bearing
from relation_metric import se2
from relation_metric.errors import InputError
from slamrel.backends.ekf_slam import ekf_slam_bundle
from slamrel.simulation.bundles import world_bundle
from slamrel.simulation.worlds import make_world

R = np.diag([0.1**2, 0.04**2])


def _problem(rng: np.random.Generator, scale: float = 1.0):  # type: ignore[no-untyped-def]
    """A pose with a wide heading prior, a landmark 2.5 m ahead, and a measurement of it."""
    x0 = np.array([0.3, -0.2, 0.1, 2.8, 0.1])
    a = rng.normal(size=(5, 5)) * 0.05
    p5 = scale * (a @ a.T + np.diag([0.04, 0.04, 0.04, 0.02, 0.02]))  # heading σ ≈ 0.2 rad
    truth = x0 + rng.multivariate_normal(np.zeros(5), p5)
    z = range_bearing(truth[:3], truth[3:])[0] + rng.multivariate_normal(np.zeros(2), R)
    return x0, p5, z


def _cost(x, x0, p5, z):  # type: ignore[no-untyped-def]
    e = z - range_bearing(x[:3], x[3:])[0]
    e[1] = se2.wrap_angle(e[1])
    d = x - x0
    return float(d @ np.linalg.solve(p5, d) + e @ np.linalg.solve(R, e))


@pytest.mark.parametrize("seed", range(5))
def test_the_iterate_is_the_minimum_of_the_local_map_cost(seed):
    x0, p5, z = _problem(np.random.default_rng(seed))
    xi = ekf._iterate(x0, p5, z, R, None, 20)
    assert _cost(xi, x0, p5, z) < _cost(x0, x0, p5, z)
    h = 1e-6
    grad = np.array(
        [(_cost(xi + h * e, x0, p5, z) - _cost(xi - h * e, x0, p5, z)) / (2 * h) for e in np.eye(5)]
    )
    grad0 = np.array(
        [(_cost(x0 + h * e, x0, p5, z) - _cost(x0 - h * e, x0, p5, z)) / (2 * h) for e in np.eye(5)]
    )
    assert np.abs(grad).max() < 1e-4 * max(1.0, np.abs(grad0).max())


def test_a_measurement_that_agrees_with_the_prediction_moves_nothing():
    x0, p5, _ = _problem(np.random.default_rng(7))
    z = range_bearing(x0[:3], x0[3:])[0]
    assert np.array_equal(ekf._iterate(x0, p5, z, R, None, 10), x0)


def _one_update(iterations: int, scale: float) -> np.ndarray:
    x0, p5, z = _problem(np.random.default_rng(3), scale)
    mu, cov = x0.copy(), p5.copy()
    assert ekf._update(mu, cov, 5, 3, z, R, 0.0, 0, iterations=iterations)
    return np.concatenate((mu, cov.ravel()))


def test_the_iterated_update_tends_to_the_plain_one_as_the_prior_shrinks():
    """The iterated update's change against the plain one falls faster than the prior: the
    second-order term the iteration corrects vanishes with the linearisation error."""
    gaps = []
    for scale in (1.0, 1e-2, 1e-4):
        plain, iterated = _one_update(1, scale), _one_update(10, scale)
        gaps.append(np.abs(iterated - plain).max() / np.sqrt(scale))
    assert gaps[0] > gaps[1] > gaps[2] and gaps[2] < 1e-2 * gaps[0], gaps


@pytest.mark.parametrize(
    ("jacobians", "iterations"), [("standard", 0), ("oc", 2.5), ("fej", 2), ("standard", True)]
)
def test_refusals_name_the_option(jacobians, iterations):
    b = world_bundle(make_world("simple1", noise="a", seed=0))
    with pytest.raises(InputError, match="iterations"):
        ekf_slam_bundle(b, jacobians=jacobians, iterations=iterations)


def test_one_iteration_is_the_plain_filter_bit_for_bit():
    b = world_bundle(make_world("simple1", noise="b", seed=1))  # (that more does something:
    _, plain = ekf_slam_bundle(b, jacobians="oc")  # the linear-limit test above)
    _, one = ekf_slam_bundle(b, jacobians="oc", iterations=1)
    assert np.array_equal(plain.map_covariance, one.map_covariance)
    assert np.array_equal(plain.online.poses, one.online.poses)


def test_cli_takes_iterations_for_a_world_and_refuses_what_cannot_apply(tmp_path):
    """``slam --iterations 3`` writes its bundle; ``--iterations`` with ``--jacobians fej``
    or on a bundle whose map was made already is an option mistake (exit 2)."""
    from slamrel.cli import main

    log = tmp_path / "log"
    assert main(["simulate", "simple1", "-o", str(log), "-q"]) == 0
    assert main(["slam", str(log), "-o", str(tmp_path / "it"), "--iterations", "3", "-q"]) == 0
    assert (tmp_path / "it" / "map.csv").is_file()
    for argv in (
        ["slam", str(log), "-o", str(tmp_path / "x"), "--jacobians", "fej", "--iterations", "2"],
        ["run", str(tmp_path / "it"), "-o", str(tmp_path / "y"), "--iterations", "2"],
    ):
        assert main(argv) == 2
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists()
