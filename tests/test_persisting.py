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
    pe = PersistingError(0.5 * b.sensor.sigma_range, 0.5 * b.sensor.sigma_bearing, 3.0, 4.0)
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
