"""The reference EKF-SLAM with first-estimate Jacobians (FEJ-EKF, Huang, Mourikis &
Roumeliotis 2008): in the small-noise limit it is the same filter as the standard EKF (both
the Kalman filter of the linearised system); on a run where the standard EKF grows
overconfident, the FEJ-EKF's NEES follows the χ² law (the oracle: true errors against stated
covariances)."""

from __future__ import annotations

import numpy as np
import pytest

from relation_metric.consistency import pose_nees
from relation_metric.errors import InputError
from slamrel.backends.ekf_slam import ekf_slam_bundle
from slamrel.pipeline import simulate_run_input
from slamrel.simulation.linear_gaussian import linear_world


def test_fej_is_the_standard_filter_in_the_linear_limit() -> None:
    log = linear_world(21)
    std, _ = ekf_slam_bundle(log)
    fej, _ = ekf_slam_bundle(log, jacobians="fej")
    assert std.map_covariance is not None and fej.map_covariance is not None
    sd = np.sqrt(np.diag(std.map_covariance)).reshape(-1, 2)
    assert np.abs((fej.map_xy - std.map_xy) / sd).max() < 1e-2
    scale = np.abs(std.map_covariance).max()
    assert np.abs(fej.map_covariance - std.map_covariance).max() < 1e-3 * scale


def test_fej_needs_known_associations() -> None:
    with pytest.raises(InputError, match="'fej' with known associations"):
        ekf_slam_bundle(linear_world(22), association="nn", jacobians="fej")


def test_fej_keeps_the_filter_consistent_where_the_standard_one_is_not() -> None:
    """simple1, noise c, seed 15: online NEES mean over its dof, standard 13.9, FEJ 0.93."""
    q = {}
    for jac in ("standard", "fej"):
        inp = simulate_run_input("simple1", noise="c", seed=15, jacobians=jac)  # type: ignore[arg-type]
        truth = inp.bundle.groundtruth
        assert truth is not None and inp.online is not None and inp.online_covariance is not None
        e = pose_nees(inp.online.poses[1:], truth.poses[1:], inp.online_covariance[1:])
        q[jac] = float(np.mean(e)) / 3
    assert q["standard"] > 3.0 and 0.5 < q["fej"] < 1.5, q
