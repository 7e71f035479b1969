"""The recovered covariance on a map made from the log, against the exact posterior.

In the linear-limit world (:mod:`slamrel.simulation.linear_gaussian`) the EKF-SLAM is a Kalman
filter and the joint posterior of poses and landmarks given the log is the Gaussian of
``Jᵀ W J``: the oracle. The map estimate ``m̂`` is a function of the log, so the poses given
``m̂`` and the log are the poses given the log: the oracle of a recovered pose covariance is the
poses' marginal of that joint posterior, and of its mean the posterior mean.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from recovery.recover import recover
from relation_metric.consistency import nees_band, pose_nees
from relation_metric.errors import InputError
from slamrel.backends.ekf_slam import ekf_slam_bundle
from slamrel.formats.bundle import read_bundle, write_bundle
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
    ind = recover(slam, method=method, robust=None, map_prior="independent")
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
    assert rep["map_prior_reason"] == "asked for (map prior deconditioned)"
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


def test_auto_follows_the_bundles_map_source() -> None:
    """``auto``: de-conditioned exactly when the bundle says its map is the log's and the
    method allows; the same bytes as asking for that prior; the reason is reported."""
    _, slam, _ = _slam(11)
    assert slam.map_source == "log"  # the reference EKF-SLAM states it
    auto = recover(slam, robust=None)
    dec = recover(slam, robust=None, map_prior="deconditioned")
    assert (auto.map_prior, auto.report()["map_prior"]) == ("deconditioned", "deconditioned")
    assert "map_source log" in auto.map_prior_reason
    np.testing.assert_array_equal(auto.covariances, dec.covariances)
    np.testing.assert_array_equal(auto.trajectory.poses, dec.trajectory.poses)
    filt = recover(slam, method="filter", robust=None)  # the filter cannot: independent, said so
    assert filt.map_prior == "independent" and "counts twice" in filt.map_prior_reason
    unstated = recover(replace(slam, map_source=None), robust=None)
    ind = recover(slam, robust=None, map_prior="independent")
    assert unstated.map_prior == "independent" and unstated.map_prior_reason.startswith("assumed")
    np.testing.assert_array_equal(unstated.covariances, ind.covariances)
    np.testing.assert_array_equal(unstated.trajectory.poses, dec.trajectory.poses)
    surveyed = recover(replace(slam, map_source="independent"), robust=None)
    assert surveyed.map_prior == "independent" and "states map_source independent" in (
        surveyed.map_prior_reason
    )
    with pytest.raises(InputError, match="map_source: expected one of log, independent"):
        replace(slam, map_source="surveyed")


def test_map_source_round_trips_and_is_checked_on_disk(tmp_path: Path) -> None:
    _, slam, _ = _slam(12)
    write_bundle(tmp_path / "b", slam)
    text = (tmp_path / "b" / "bundle.json").read_text()
    assert json.loads(text)["map_source"] == "log"
    assert read_bundle(tmp_path / "b").map_source == "log"
    write_bundle(tmp_path / "n", replace(slam, map_source=None))  # unstated: no key at all
    assert "map_source" not in (tmp_path / "n" / "bundle.json").read_text()
    assert read_bundle(tmp_path / "n").map_source is None
    bad = text.replace('"map_source": "log"', '"map_source": "slam"')
    (tmp_path / "b" / "bundle.json").write_text(bad)
    line = bad[: bad.index('"map_source"')].count("\n") + 1
    with pytest.raises(InputError, match="map_source: expected one of 'log', 'independent'") as e:
        read_bundle(tmp_path / "b")
    assert e.value.line == line and str(e.value.path).endswith("bundle.json")


def test_recover_command_states_the_prior_and_why(tmp_path: Path) -> None:
    from slamrel.cli import main

    _, slam, _ = _slam(13)
    write_bundle(tmp_path / "n", replace(slam, map_source=None))
    write_bundle(tmp_path / "l", slam)
    reports = {}
    for name, extra in (("n", []), ("l", []), ("f", ["--map-prior", "deconditioned"])):
        src = tmp_path / ("n" if name == "f" else name)
        rep = tmp_path / f"{name}.json"
        args = ["recover", str(src), "-o", str(tmp_path / f"{name}.txt"), "--report", str(rep)]
        assert main([*args, "-q", *extra]) == 0
        reports[name] = json.loads(rep.read_text())
    assert reports["n"]["map_prior"] == "independent"
    assert reports["n"]["map_prior_reason"].startswith("assumed: the bundle does not state")
    assert reports["l"]["map_prior"] == "deconditioned"
    assert reports["f"]["map_prior"] == "deconditioned"  # asked for, on the unstated bundle
    assert reports["f"]["map_prior_reason"] == "asked for (map prior deconditioned)"
    out = ["recover", str(tmp_path / "l"), "-o", str(tmp_path / "x.txt"), "-q"]
    assert main([*out, "--method", "filter", "--map-prior", "deconditioned"]) == 3
    with pytest.raises(SystemExit) as e:
        main([*out, "--map-prior", "log"])
    assert e.value.code == 2
