"""NEES and χ² bands: hand values and a Monte Carlo property."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from relation_metric.consistency import nees, nees_band, pose_nees, summarize_nees
from relation_metric.errors import InputError


def test_nees_hand_value():
    p = np.array([[[4.0, 0.0], [0.0, 1.0]]])
    assert nees([[2.0, 1.0]], p)[0] == pytest.approx(2.0)  # 4/4 + 1/1
    full = np.array([[[2.0, 1.0], [1.0, 2.0]]])
    e = np.array([[1.0, -1.0]])
    assert nees(e, full)[0] == pytest.approx(float(e[0] @ np.linalg.inv(full[0]) @ e[0]))


def test_pose_nees_wraps_the_angle():
    p = np.eye(3)[None] * 0.01
    v = pose_nees([[0, 0, np.pi - 0.05]], [[0, 0, -np.pi + 0.05]], p)
    assert v[0] == pytest.approx(0.1**2 / 0.01)


def test_band_is_the_chi2_quantile():
    lo, hi = nees_band(3, 50, 0.95)
    assert lo == pytest.approx(chi2.ppf(0.025, 150) / 50)
    assert hi == pytest.approx(chi2.ppf(0.975, 150) / 50)


def test_consistent_gaussian_samples_fall_in_the_band(rng):
    runs, steps, d = 50, 200, 3
    a = rng.normal(size=(runs * steps, d, d))
    cov = a @ np.swapaxes(a, 1, 2) + 0.1 * np.eye(d)
    err = np.einsum("nij,nj->ni", np.linalg.cholesky(cov), rng.normal(size=(runs * steps, d)))
    v = nees(err, cov).reshape(runs, steps)
    s = summarize_nees(v, dof=d)
    assert s.band[0] < s.mean < s.band[1]
    assert 0.9 < s.inside <= 1.0
    over = summarize_nees(nees(err * 1.5, cov).reshape(runs, steps), dof=d)  # overconfident
    assert over.inside < 0.1


def test_non_pd_covariance_is_an_error():
    with pytest.raises(InputError, match="positive definite"):
        nees([[1.0, 0.0]], [[[1.0, 2.0], [2.0, 1.0]]])


# --- Hu, Huang & Dissanayake's whole-estimate NEES -------------------------------------------


@pytest.mark.parametrize(("poses", "gate"), [(82, 280.36), (420, 1340.59)])
def test_nees1_gate_is_the_papers(poses, gate):
    from relation_metric.consistency import nees1, nees_gate

    assert nees_gate(3 * (poses - 1)) == pytest.approx(gate, abs=0.005)
    z = np.zeros((poses, 3))
    t = nees1(z, z, np.eye(3 * (poses - 1)))
    assert (t.dof, round(t.gate, 2), t.value, t.passed) == (3 * (poses - 1), gate, 0.0, True)


def test_joint_nees1_is_the_sum_of_per_pose_nees_when_block_diagonal(rng):
    from scipy.linalg import block_diag

    from relation_metric.consistency import nees1

    n = 12
    a = rng.normal(size=(n - 1, 3, 3))
    blocks = a @ np.swapaxes(a, 1, 2) + 0.1 * np.eye(3)
    truth = rng.normal(size=(n, 3))
    est = truth + rng.normal(0, 0.5, (n, 3))
    est[:, 2] = truth[:, 2] + 3.0  # angle errors near ±π: wrapped the same way both times
    joint = nees1(est, truth, block_diag(*blocks))
    assert joint.value == pytest.approx(pose_nees(est[1:], truth[1:], blocks).sum(), rel=1e-10)
    # with correlations the joint value differs from the per-pose sum
    corr = block_diag(*blocks) + 0.05 * np.ones((3 * (n - 1),) * 2)
    assert nees1(est, truth, corr).value != pytest.approx(joint.value, rel=1e-3)


def test_nees2_is_chi2_distributed_under_its_own_covariance(rng):
    from relation_metric.consistency import nees2

    L = 30
    a = rng.normal(size=(2 * L, 2 * L))
    cov = a @ a.T / (2 * L) + 0.01 * np.eye(2 * L)
    low = np.linalg.cholesky(cov)
    truth = rng.normal(size=(L, 2))
    vals = [
        nees2(truth + (low @ rng.normal(size=2 * L)).reshape(L, 2), truth, cov) for _ in range(2000)
    ]
    v = np.array([t.value for t in vals])
    assert v.mean() == pytest.approx(2 * L, rel=0.03)
    assert np.mean([t.passed for t in vals]) == pytest.approx(0.95, abs=0.015)
    with pytest.raises(InputError, match="not positive definite"):
        nees2(truth, truth, -np.eye(2 * L))
    with pytest.raises(InputError, match=r"\(L >= 1, 2\)"):
        nees2(truth, truth[:-1], cov)


@pytest.mark.parametrize("dof", [1, 2, 3])
def test_chi2_quantile_equals_scipy(dof):
    """The analytic 2-dof quantile −2 ln(1 − p) and the scipy path agree with chi2.ppf."""
    from relation_metric.consistency import chi2_quantile

    for p in (1e-3, 0.025, 0.05, 0.3, 0.5, 0.95, 0.975, 0.999, 0.9999, 1 - 1e-12):
        assert chi2_quantile(p, dof) == pytest.approx(chi2.ppf(p, dof), rel=1e-14)
    assert chi2_quantile(1e-9, dof) == pytest.approx(chi2.ppf(1e-9, dof), rel=1e-8)
    with pytest.raises(InputError):
        chi2_quantile(1.0, dof)
