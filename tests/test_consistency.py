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
