"""A persisting measurement error stated in the bundle (``sensor_model.persisting``): the key
is read and written by the one bundle reader, refused when malformed, and the augmented
recovery (recovery.persisting) is the white one in the limit of a vanishing bias."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from recovery.ekf import run_filter
from recovery.models import PersistingError
from recovery.persisting import run_persisting, smooth_persisting
from recovery.recover import filter_input
from recovery.smoother import smooth
from relation_metric.errors import InputError
from slamrel.formats.bundle import read_bundle, write_bundle
from slamrel.simulation.healthy import healthy_bundle


def _bundle(persisting=None):
    b = healthy_bundle("simple1", 0, "marginal", odometry=None)
    return replace(b, sensor=replace(b.sensor, persisting=persisting))


def test_round_trip_and_refusals(tmp_path):
    b = _bundle()
    common = PersistingError(0.3 * b.sensor.sigma_range, 0.6 * b.sensor.sigma_bearing, 9.0, 2.0)
    pe = PersistingError(
        0.5 * b.sensor.sigma_range, 0.5 * b.sensor.sigma_bearing, 3.0, 4.0, common=common
    )
    write_bundle(tmp_path / "b", replace(b, sensor=replace(b.sensor, persisting=pe)))
    assert read_bundle(tmp_path / "b").sensor.persisting == pe
    write_bundle(tmp_path / "w", b)  # a bundle that does not state it: no key written
    doc = json.loads((tmp_path / "w" / "bundle.json").read_text())
    assert "persisting" not in doc["sensor_model"]
    assert read_bundle(tmp_path / "w").sensor.persisting is None
    for bad, what in (
        (
            {
                "sigma_range": 0.01,
                "sigma_bearing": 0.001,
                "time_constant_range": 0.0,
                "time_constant_bearing": 1.0,
            },
            "time_constant_range",
        ),  # fmt: skip
        (
            {
                "sigma_range": 10.0,
                "sigma_bearing": 0.001,
                "time_constant_range": 1.0,
                "time_constant_bearing": 1.0,
            },
            "not below",
        ),  # fmt: skip
        (
            {"sigma_range": 0.01, "sigma_bearing": 0.001, "time_constant_range": 1.0},
            "missing time_constant_bearing",
        ),  # fmt: skip
        (
            {
                "sigma_range": 0.01,
                "sigma_bearing": 0.001,
                "time_constant_range": 1.0,
                "time_constant_bearing": 1.0,
                "tau": 1.0,
            },
            "tau",
        ),  # fmt: skip
    ):
        doc["sensor_model"]["persisting"] = bad
        (tmp_path / "w" / "bundle.json").write_text(json.dumps(doc, indent=1))
        with pytest.raises(InputError, match=what):
            read_bundle(tmp_path / "w")


def _pose_gap(a, b):
    d = np.asarray(a) - np.asarray(b)
    d[:, 2] = np.angle(np.exp(1j * d[:, 2]))  # the heading on either branch
    return float(np.abs(d).max())


def test_vanishing_bias_is_the_white_filter_and_smoother():
    """Oracle: with σ_b → 0 and an exact map the augmented state adds nothing, so the
    augmented EKF is the plain EKF of recovery.ekf and its RTS smoother the RTS smoother of
    recovery.smoother, to rounding."""
    b = _bundle()
    inp = replace(filter_input(b, map_mode="ignore"), map_covariance=None)
    tiny = (1e-9 * b.sensor.sigma_range, 1e-9 * b.sensor.sigma_bearing)
    white = run_filter(inp)
    aug = run_persisting(inp, tiny, (2.0, 2.0))
    assert _pose_gap(aug.fr.poses, white.poses) < 1e-9
    np.testing.assert_allclose(aug.fr.covariances, white.covariances, rtol=1e-6, atol=1e-14)
    np.testing.assert_allclose(aug.fr.nis, white.nis, rtol=1e-6)
    poses, covs = smooth_persisting(aug)
    ref = smooth(white)
    assert _pose_gap(poses, ref.poses) < 1e-8
    np.testing.assert_allclose(covs, ref.covariances, rtol=1e-5, atol=1e-14)


@pytest.mark.slow  # simple1's 220 landmarks make a 883-dimensional state: ~5 min
def test_smoother_never_less_certain_than_its_filter():
    """Property of a smoother: with most of the noise stated as a slow bias (τ 30 s, the
    map's marginals in the state) every smoothed pose covariance is at most the augmented
    filter's (P_f − P_s positive semi-definite), and the recovery runs end to end."""
    from recovery.recover import recover

    b = _bundle()
    pe = PersistingError(0.9 * b.sensor.sigma_range, 0.9 * b.sensor.sigma_bearing, 30.0, 30.0)
    gm = recover(replace(b, sensor=replace(b.sensor, persisting=pe)), method="smoother")
    assert gm.filter_covariances is not None
    gap = np.linalg.eigvalsh(np.asarray(gm.filter_covariances) - np.asarray(gm.covariances))
    scale = np.trace(gm.filter_covariances, axis1=1, axis2=2)
    assert (gap.min(axis=1) >= -1e-9 * scale).all()
    assert np.isfinite(gm.nis[gm.status == 0]).all()


def _gm_residuals(seed):
    """Residuals drawn from the model itself: 4 landmarks seen in turn (5 s visits, 5 Hz), a
    common Gauss–Markov bias σ 0.5, τ 4 s, one per landmark σ 0.6, τ 15 s, white 0.62
    (total 1), 2,000 s; both components alike."""
    rng = np.random.default_rng([36, seed])
    n, dt = 10000, 0.2
    a_c, a_l = np.exp(-dt / 4.0), np.exp(-dt / 15.0)
    c, own = 0.5 * rng.standard_normal(2), 0.6 * rng.standard_normal((4, 2))
    lm = (np.arange(n) // 25) % 4
    e = np.zeros((n, 2))
    for k in range(n):  # the oracle's recursion (every landmark's bias runs all the time)
        if k:
            c = a_c * c + 0.5 * np.sqrt(1 - a_c**2) * rng.standard_normal(2)
            own = a_l * own + 0.6 * np.sqrt(1 - a_l**2) * rng.standard_normal((4, 2))
        e[k] = c + own[lm[k]]
    e += np.sqrt(1 - 0.25 - 0.36) * rng.standard_normal((n, 2))
    return np.arange(n) * dt, lm, e


def test_fit_recovers_a_known_common_and_per_landmark_bias():
    """Oracle: the model's own parameters, back from residuals drawn from it: over 3 records
    × 2 components the mean fitted σ within 10 %, the mean τ within 40 % (one record's τ
    scatters by ±40 %: a few hundred time constants of data; the common τ comes out 20–30 %
    long here, where different landmarks are never seen at one time and the short lags have
    few cross pairs)."""
    from slamrel.importers.mrclam import fit_persisting

    got = {"sc": [], "sl": [], "tc": [], "tl": []}
    for seed in range(3):
        t, lm, e = _gm_residuals(seed)
        fit = fit_persisting(t, lm, e, (1.0, 1.0), np.ones(t.size, dtype=bool))
        assert fit.common is not None
        got["sc"] += fit.common.sigma
        got["sl"] += fit.sigma
        got["tc"] += fit.common.tau
        got["tl"] += fit.tau
    assert np.mean(got["sc"]) == pytest.approx(0.5, rel=0.1)
    assert np.mean(got["sl"]) == pytest.approx(0.6, rel=0.1)
    assert np.mean(got["tc"]) == pytest.approx(4.0, rel=0.4)
    assert np.mean(got["tl"]) == pytest.approx(15.0, rel=0.4)
