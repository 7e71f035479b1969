"""The recovered covariance on a map made from the log, against the exact posterior.

In the linear-limit world (:mod:`slamrel.simulation.linear_gaussian`) the EKF-SLAM is a Kalman
filter and the joint posterior of poses and landmarks given the log is the Gaussian of
``Jᵀ W J``: the oracle. The map estimate ``m̂`` is a function of the log, so the poses given
``m̂`` and the log are the poses given the log: the oracle of a recovered pose covariance is the
poses' marginal of that joint posterior, and of its mean the posterior mean.
"""

from __future__ import annotations

import numpy as np
import pytest

from recovery.recover import recover
from relation_metric.consistency import nees_band, pose_nees
from relation_metric.errors import InputError
from slamrel.backends.ekf_slam import ekf_slam_bundle
from slamrel.simulation.linear_gaussian import exact_posterior, linear_world


def _slam(seed: int):  # type: ignore[no-untyped-def]
    log = linear_world(seed)
    slam, _ = ekf_slam_bundle(log)
    return log, slam, exact_posterior(log, slam.map_ids)


def _expected_nees(stated: np.ndarray, true: np.ndarray) -> float:
    """``E[eᵀ C⁻¹ e] = tr(C⁻¹ P)`` for an error of covariance ``P``, mean over poses 1.."""
    return float(np.mean(np.einsum("nij,nji->n", np.linalg.inv(stated[1:]), true[1:])))


def test_ekf_slam_is_the_exact_posterior_in_the_linear_world() -> None:
    _, slam, ex = _slam(7)
    sm = ex.map_covariance()
    assert np.abs(slam.map_covariance - sm).max() < 1e-3 * np.abs(sm).max()
    sd = np.sqrt(np.diag(sm)).reshape(-1, 2)
    assert np.abs((slam.map_xy - ex.mean[3 * ex.poses :].reshape(-1, 2)) / sd).max() < 1e-2


def test_deconditioning_removes_exactly_the_logs_information() -> None:
    """``Λ_prior = Σ_m⁻¹ − (D − Bᵀ A⁻¹ B)`` is the landmarks' own prior (none: 0), and the
    poses' marginal with it is the law of total covariance ``A⁻¹ + A⁻¹ B Σ_m Bᵀ A⁻¹``."""
    _, slam, ex = _slam(8)
    a, b, d = ex.blocks()
    sigma_m = slam.map_covariance
    a_inv_b = np.linalg.solve(a, b)
    log_info = d - b.T @ a_inv_b  # what the log says about the map, the poses marginalised
    prior = np.linalg.inv(sigma_m) - log_info
    assert np.abs(prior).max() < 1e-3 * np.abs(log_info).max()
    # with it, the joint information is the oracle's, so the poses' marginal is too
    joint = np.block([[a, b], [b.T, d + prior]])
    n3 = a.shape[0]
    marginal = np.linalg.inv(joint)[:n3, :n3]
    total = np.linalg.inv(a) + a_inv_b @ sigma_m @ a_inv_b.T
    scale = np.abs(ex.covariance[:n3, :n3]).max()
    assert np.abs(marginal - ex.covariance[:n3, :n3]).max() < 1e-3 * scale
    assert np.abs(total - ex.covariance[:n3, :n3]).max() < 1e-3 * scale
    # the independent prior counts the log's information about the map twice
    twice = np.linalg.inv(np.block([[a, b], [b.T, d + np.linalg.inv(sigma_m)]]))[:n3, :n3]
    assert np.trace(twice) < 0.9 * np.trace(ex.covariance[:n3, :n3])


@pytest.mark.parametrize("method", ["smoother", "batch"])
def test_deconditioned_covariance_is_the_oracle(method: str) -> None:
    _, slam, ex = _slam(9)
    oracle = ex.pose_covariances()
    dec = recover(slam, method=method, map_prior="deconditioned", robust=None)
    ind = recover(slam, method=method, robust=None)
    scale = np.abs(oracle[1:]).max()
    assert np.abs(dec.covariances[1:] - oracle[1:]).max() < 1e-3 * scale
    assert _expected_nees(dec.covariances, oracle) == pytest.approx(3.0, abs=1e-3)
    assert _expected_nees(ind.covariances, oracle) > 3.6  # the double counting, measured 4.4
    # the trajectory is the posterior mean, and the same under both priors
    np.testing.assert_array_equal(dec.trajectory.poses, ind.trajectory.poses)
    err = dec.trajectory.poses - ex.pose_means()
    err[:, 2] = (err[:, 2] + np.pi) % (2 * np.pi) - np.pi
    assert np.abs(err[1:] / np.sqrt(np.einsum("nii->ni", oracle[1:]))).max() < 1e-2


def test_deconditioned_map_prior_is_reported_and_checked() -> None:
    _, slam, _ = _slam(10)
    rep = recover(slam, map_prior="deconditioned", robust=None).report()
    assert rep["map_prior"] == "deconditioned" and "twice" in str(rep["map_prior_rule"])
    assert "map_prior" not in recover(slam, robust=None).report()  # earlier reports' bytes
    with pytest.raises(InputError, match="needs the smoother or the batch"):
        recover(slam, method="filter", map_prior="deconditioned")
    with pytest.raises(InputError, match="unknown map prior"):
        recover(slam, map_prior="from-log")


@pytest.mark.slow
def test_deconditioned_nees_is_chi2_consistent_over_100_runs() -> None:
    """100 seeded runs: ``Σ_r ε_rk ~ χ²(3R)`` at each pose ``k`` for a consistent recovery."""
    runs = 100
    values = []
    for seed in range(2000, 2000 + runs):
        log = linear_world(seed)
        slam, _ = ekf_slam_bundle(log)
        rec = recover(slam, map_prior="deconditioned")
        assert log.groundtruth is not None
        values.append(pose_nees(rec.trajectory.poses[1:], log.groundtruth.poses[1:],
                                rec.covariances[1:]))  # fmt: skip
    mean_k = np.mean(values, axis=0)  # the run average at each pose
    lo, hi = nees_band(3, runs, probability=0.99)
    inside = float(np.mean((mean_k >= lo) & (mean_k <= hi)))
    assert inside >= 0.9, (inside, mean_k.mean())
    assert 2.7 < float(mean_k.mean()) < 3.3
