"""Full least squares on pose graphs with landmarks, and the iSAM text format."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import require_data
from scipy.optimize import least_squares

from relation_metric import se2
from relation_metric.errors import InputError
from slamrel.backends.graph import PoseGraph, _residuals_and_jacobian, _upper_sqrt, solve_graph
from slamrel.importers.isam import read_isam


def small_world(rng, n=30, m=8, noise=0.05):
    steps = np.column_stack((np.full(n - 1, 1.0), np.zeros(n - 1), np.full(n - 1, 2 * np.pi / n)))
    truth = se2.cumulative_compose(steps)
    lms = rng.uniform(-6, 6, (m, 2))
    i = np.arange(n - 1)
    z_pp = se2.between(truth[i], truth[i + 1]) + rng.normal(0, noise, (n - 1, 3))
    k = np.repeat(np.arange(n), m)
    lm = np.tile(np.arange(m), n)
    z_pl = se2.inverse_transform_points(truth[k], lms[lm]) + rng.normal(0, noise, (k.size, 2))
    info3 = np.broadcast_to(np.diag([1 / noise**2] * 3), (n - 1, 3, 3))
    info2 = np.broadcast_to(np.diag([1 / noise**2] * 2), (k.size, 2, 2))
    init = se2.cumulative_compose(z_pp)
    lm0 = se2.transform_points(init[0], se2.inverse_transform_points(truth[0], lms)) + 0.5
    g = PoseGraph(init, lm0, i, i + 1, z_pp, info3, k, lm, z_pl, info2)
    return g, truth, lms


def test_jacobian_matches_finite_differences(rng):
    g, _, _ = small_world(rng, n=8, m=3)
    w_pp, w_pl = _upper_sqrt(g.pp_info), _upper_sqrt(g.pl_info)
    prior = (g.poses[0].copy(), np.eye(3) * 10)
    x = g.poses + rng.normal(0, 0.1, g.poses.shape)
    lm = g.landmarks + rng.normal(0, 0.1, g.landmarks.shape)
    r, jac = _residuals_and_jacobian(g, x, lm, w_pp, w_pl, prior)
    flat = np.concatenate((x.ravel(), lm.ravel()))
    num = np.zeros((r.size, flat.size))
    h = 1e-6
    for c in range(flat.size):
        d = np.zeros_like(flat)
        d[c] = h
        xp = (flat + d)[: x.size].reshape(x.shape)
        lp = (flat + d)[x.size :].reshape(lm.shape)
        xm = (flat - d)[: x.size].reshape(x.shape)
        lmm = (flat - d)[x.size :].reshape(lm.shape)
        num[:, c] = (
            _residuals_and_jacobian(g, xp, lp, w_pp, w_pl, prior)[0]
            - _residuals_and_jacobian(g, xm, lmm, w_pp, w_pl, prior)[0]
        ) / (2 * h)
    np.testing.assert_allclose(jac.toarray(), num, rtol=1e-5, atol=1e-4)


def test_solution_equals_scipy_least_squares(rng):
    g, truth, lms = small_world(rng)
    sol = solve_graph(g)
    assert sol.converged
    w_pp, w_pl = _upper_sqrt(g.pp_info), _upper_sqrt(g.pl_info)
    prior = (g.poses[0].copy(), np.eye(3) / 1e-6)
    n = g.n_poses

    def fun(v):
        return _residuals_and_jacobian(
            g, v[: 3 * n].reshape(n, 3), v[3 * n :].reshape(-1, 2), w_pp, w_pl, prior
        )[0]

    ref = least_squares(
        fun,
        np.concatenate((g.poses.ravel(), g.landmarks.ravel())),
        method="lm",
        xtol=1e-12,
        ftol=1e-12,
    )
    assert 0.5 * np.sum(ref.fun**2) == pytest.approx(sol.cost[-1], rel=1e-6)
    np.testing.assert_allclose(sol.poses[:, :2], ref.x[: 3 * n].reshape(n, 3)[:, :2], atol=1e-5)
    # and it is close to the truth (in the frame of the first pose, which the prior holds)
    est_lms = se2.inverse_transform_points(sol.poses[0], sol.landmarks)
    true_lms = se2.inverse_transform_points(truth[0], lms)
    assert np.abs(est_lms - true_lms).max() < 0.5
    assert np.all(np.diff(sol.cost) <= 0)


def test_graph_validation(rng):
    g, _, _ = small_world(rng, n=5, m=2)
    with pytest.raises(InputError, match="index out of range"):
        PoseGraph(g.poses, g.landmarks, g.pp_i, g.pp_j + 10, g.pp_z, g.pp_info)
    bad_info = np.array(g.pp_info)
    bad_info[0] = -np.eye(3)
    with pytest.raises(InputError, match="positive definite"):
        solve_graph(
            PoseGraph(
                g.poses,
                g.landmarks,
                g.pp_i,
                g.pp_j,
                g.pp_z,
                bad_info,
                g.pl_k,
                g.pl_l,
                g.pl_z,
                g.pl_info,
            )
        )


ISAM = """ODOMETRY 0 1 1.0 0 0 0.01 0 0 0.01 0 0.0001
LANDMARK 1 2 1.0 1.0 0.04 0 0.04
ODOMETRY 1 3 1.0 0 1.5707963 0.01 0 0 0.01 0 0.0001
LANDMARK 3 2 1.0 0.0 0.04 0 0.04
"""


def test_isam_reader_hand_example(tmp_path):
    p = tmp_path / "a.txt"
    p.write_text(ISAM)
    d = read_isam(p)
    np.testing.assert_array_equal(d.pose_ids, [0, 1, 3])
    np.testing.assert_array_equal(d.landmark_ids, [2])
    np.testing.assert_allclose(d.graph.poses[2], [2.0, 0.0, 1.5707963], atol=1e-9)
    np.testing.assert_allclose(d.graph.landmarks[0], [2.0, 1.0])  # first sighting from pose 1
    np.testing.assert_allclose(d.graph.pp_info[0], np.diag([100, 100, 1e4]))
    sq = read_isam(p, noise="sqrt-information")
    np.testing.assert_allclose(sq.graph.pp_info[0], np.diag([1e-4, 1e-4, 1e-8]))
    sol = solve_graph(d.graph)
    # both sightings agree with a landmark at (2, 1): the solution keeps it there
    np.testing.assert_allclose(sol.landmarks[0], [2.0, 1.0], atol=1e-6)


@pytest.mark.parametrize(
    "text,line,msg",
    [
        ("ODOMETRY 0 1 1 0 0 1 0 0 1 0 1\nODOMETRY 1 2 1 0 0 1 0 0 1 0\n", 2, "expected 12 fields"),
        ("ODOMETRY 0 1 1 0 x 1 0 0 1 0 1\n", 1, "expected a number"),
        ("POINT 0 1\n", 1, "unknown record"),
        ("ODOMETRY 0 1 1 0 0 1 0 0 1 0 1\nLANDMARK 7 2 1 1 1 0 1\n", 2, "unknown pose 7"),
    ],
)
def test_isam_bad_input(tmp_path, text, line, msg):
    p = tmp_path / "b.txt"
    p.write_text(text)
    with pytest.raises(InputError) as err:
        read_isam(p)
    assert f"b.txt:{line}:" in str(err.value) and msg in str(err.value)


@pytest.mark.realdata
def test_victoria_park_converges_from_odometry():
    d = read_isam(require_data("victoria_park", "victoria_park.txt"))
    assert (d.graph.n_poses, d.graph.n_landmarks, d.graph.pl_k.size) == (6969, 151, 3640)
    sol = solve_graph(d.graph)
    assert sol.converged
    assert sol.cost[-1] < 0.01 * sol.cost[0]


def test_pose_covariances_equal_dense_inverse(rng):
    from slamrel.backends.graph import pose_covariances

    g, _, _ = small_world(rng, n=10, m=3)
    sol = solve_graph(g)
    w_pp, w_pl = _upper_sqrt(g.pp_info), _upper_sqrt(g.pl_info)
    prior = (g.poses[0].copy(), np.eye(3) / 1e-6)
    _, jac = _residuals_and_jacobian(
        g, np.array(sol.poses), np.array(sol.landmarks), w_pp, w_pl, prior
    )
    dense = np.linalg.inv((jac.T @ jac).toarray())
    cov = pose_covariances(g, sol, [0, 4, 9])
    for k, i in enumerate([0, 4, 9]):
        np.testing.assert_allclose(
            cov[k], dense[3 * i : 3 * i + 3, 3 * i : 3 * i + 3], rtol=1e-6, atol=1e-14
        )


@pytest.mark.realdata
def test_victoria_park_ekf_slam_and_recovery_run(tmp_path):
    from recovery.recover import recover
    from slamrel.importers.isam import isam_log_bundle
    from slamrel.simulate import slam_bundle

    d = read_isam(require_data("victoria_park", "victoria_park.txt"))
    b = isam_log_bundle(d)
    assert b.measurements.shape[0] == 3640 and len(b.odometry) == 6969
    slam, res = slam_bundle(b)
    assert slam.map_ids.size == 151 and np.isfinite(slam.map_xy).all()
    rec = recover(slam, method="smoother", max_outlier_run=None)
    assert len(rec.trajectory) == 6969 and rec.counts["used"] == 3640
