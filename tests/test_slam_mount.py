"""The reference EKF-SLAM (``slamrel slam``) on a bundle whose sensor is turned by a mount's
heading, and on one that states a persisting measurement error (the importers' defaults)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from recovery.models import PersistingError
from relation_metric import se2
from relation_metric.errors import InputError
from slamrel.backends.ekf_slam import ekf_slam_bundle
from slamrel.simulation.healthy import healthy_bundle


def _log():
    return healthy_bundle("simple1", 0, "marginal", odometry=None)


def test_a_turned_sensor_gives_the_map_of_the_same_bearings_in_the_robot_frame():
    """Oracle: the log's bearings rewritten in a sensor frame turned by θ_m (each less θ_m)
    with ``mount = [0, 0, θ_m]`` is the same log: the same map, associations and online
    poses (to the rounding of the wrap)."""
    b = _log()
    theta = 0.3
    z = b.measurements.copy()
    z[:, 1] = se2.wrap_angle(z[:, 1] - theta)
    turned = replace(b, measurements=z, sensor=replace(b.sensor, mount=(0.0, 0.0, theta)))
    ref, ref_run = ekf_slam_bundle(b)
    out, run = ekf_slam_bundle(turned)
    np.testing.assert_allclose(out.map_xy, ref.map_xy, atol=1e-9)
    np.testing.assert_allclose(run.online.poses, ref_run.online.poses, atol=1e-9)
    assert np.array_equal(out.measurement_landmarks, ref.measurement_landmarks)
    assert out.sensor.mount == (0.0, 0.0, theta)  # the result keeps the log's sensor
    np.testing.assert_array_equal(out.measurements, z)


def test_a_mount_off_the_robots_origin_is_refused():
    b = _log()
    with pytest.raises(InputError, match=r"mount \[0, 0, theta\]"):
        ekf_slam_bundle(replace(b, sensor=replace(b.sensor, mount=(0.1, 0.0, 0.0))))


def test_a_stated_persisting_error_is_taken_as_white_and_said():
    """The reference filter is white: its map is the one of the same log without the
    persisting model (bit for bit), and the result bundle's sensor model and description
    say it took the total σ as white."""
    b = _log()
    pe = PersistingError(0.5 * b.sensor.sigma_range, 0.5 * b.sensor.sigma_bearing, 3.0, 4.0)
    out, _ = ekf_slam_bundle(replace(b, sensor=replace(b.sensor, persisting=pe)))
    ref, _ = ekf_slam_bundle(b)
    np.testing.assert_array_equal(out.map_xy, ref.map_xy)
    assert out.sensor.persisting is None and out.sensor.sigma_range == b.sensor.sigma_range
    assert "white of the total sigma" in out.description
