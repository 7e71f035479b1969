"""Victoria Park (iSAM/GTSAM text): full least squares from odometry, EKF-SLAM + recovery,
and the two landmark maps compared with ``map-compare``.

There is no ground truth. The oracles are consistency (χ² per degree of freedom of the
least-squares solution near 1 with the file's own noise), the same minimum reached from two
unrelated starts (chained odometry, grown incrementally; and the EKF-SLAM + recovery
result), and, for the map comparison, that two estimators from the same measurements agree
locally far better than the measurement noise (σ = 0.63 m per landmark sighting).
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from conftest import require_data

from slamrel.backends.least_squares import solve_graph, solve_graph_incremental
from slamrel.formats.isam import isam_log_bundle, read_isam

pytestmark = pytest.mark.realdata


@pytest.fixture(scope="module")
def vp():
    return read_isam(require_data("victoria_park", "victoria_park.txt"), noise="covariance")


@pytest.fixture(scope="module")
def least_squares(vp):
    return solve_graph_incremental(vp.graph, batch=500)


@pytest.fixture(scope="module")
def ekf(vp):
    from recovery.recover import recover
    from slamrel.backends.ekf_slam import ekf_slam_bundle

    slam, _ = ekf_slam_bundle(isam_log_bundle(vp))
    return slam, recover(slam, method="smoother", max_outlier_run=None)


def test_least_squares_converges_from_odometry(vp, least_squares):
    g = vp.graph
    assert (g.n_poses, g.n_landmarks, g.pl_k.size) == (6969, 151, 3640)
    sol = least_squares
    assert sol.converged
    residuals = 3 * g.pp_i.size + 2 * g.pl_k.size + 3  # + the gauge prior
    dof = residuals - 3 * g.n_poses - 2 * g.n_landmarks
    assert 0.5 < 2 * sol.cost[-1] / dof < 1.5  # measured 0.89


@pytest.mark.slow
def test_grown_and_fixed_step_schemes_reach_one_minimum(vp, least_squares):
    """The default geometric growth (500 poses, x2) and the fixed 500-pose step it replaced
    end at the same minimum, cost 3091.97 (measured before the sparse Cholesky back-ends)."""
    fixed = solve_graph_incremental(vp.graph, batch=500, growth=1.0)
    for sol in (least_squares, fixed):
        assert sol.converged
        assert sol.cost[-1] == pytest.approx(3091.97, abs=0.01)
    np.testing.assert_allclose(least_squares.poses, fixed.poses, atol=1e-4)
    np.testing.assert_allclose(least_squares.landmarks, fixed.landmarks, atol=1e-4)


def test_two_starts_reach_one_minimum(vp, least_squares, ekf):
    slam, rec = ekf
    assert (slam.map_ids == vp.landmark_ids).all()
    warm = dataclasses.replace(
        vp.graph, poses=np.array(rec.trajectory.poses), landmarks=np.array(slam.map_xy)
    )
    sol = solve_graph(warm)
    assert sol.converged
    assert sol.cost[-1] == pytest.approx(least_squares.cost[-1], rel=1e-6)
    np.testing.assert_allclose(sol.landmarks, least_squares.landmarks, atol=1e-3)


def test_ekf_slam_and_recovery_run(ekf):
    slam, rec = ekf
    assert slam.map_ids.size == 151 and np.isfinite(slam.map_xy).all()
    assert len(rec.trajectory) == 6969 and rec.counts.used == 3640


@pytest.mark.slow
def test_cli_chain_and_map_compare(vp, tmp_path, capsys):
    """What a user runs; the maps keep the file's landmark ids through g2o, so map-compare
    associates them by id."""
    from slamrel.cli import main

    src = str(require_data("victoria_park", "victoria_park.txt"))
    g2o, log, ls, slam = (str(tmp_path / n) for n in ("vp.g2o", "log", "ls", "slam"))
    assert (
        main(["import", "isam", src, "-o", g2o, "--bundle", log, "-q", "--noise", "covariance"])
        == 0
    )
    assert main(["solve", g2o, "-o", ls, "-q"]) == 0
    assert main(["slam", log, "-o", slam, "-q"]) == 0
    out = tmp_path / "mc.json"
    assert (
        main(["map-compare", f"{slam}/map.csv", f"{ls}/landmarks.csv", "--json", str(out), "-q"])
        == 0
    )
    res = json.loads(out.read_text())
    assert res["association"]["matched"] == 151
    edges = res["translation"]["abs"]
    # measured: median 0.067 m, mean 0.24 m, max 8.0 m (long edges across the park)
    assert edges["median"] < 0.15 and edges["mean"] < 0.5
    assert res["relations"] == 434
