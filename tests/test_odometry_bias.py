"""A persisting odometry error in the augmented recovery (recovery.odometry_bias): the motion
Jacobians against finite differences of dead reckoning, the epochs it adds, the limit of a
vanishing bias (the recovery without it), the fill between epochs against the same poses made
epochs, and the NEES of runs drawn with such an error."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pytest

import recovery.odometry_bias as ob
from recovery.ekf import dead_reckoning_segments
from recovery.odometry_bias import motion_jacobians, with_virtual_epochs
from recovery.persisting import run_persisting, smooth_persisting
from recovery.recover import filter_input
from relation_metric import se2
from slamrel.simulation.bundles import simulate_bundle


@dataclass(frozen=True)
class _Motion:  # the four numbers of motion_model.persisting
    sigma_scale: float
    time_constant_scale: float
    sigma_turn: float
    time_constant_turn: float


def _arc(v, w, dt):
    """The velocity model's exact arc, written here (independent of recovery.models)."""
    ww = np.where(np.abs(w) < 1e-12, 1e-12, w)
    return np.column_stack((v / ww * np.sin(ww * dt), v / ww * (1 - np.cos(ww * dt)), ww * dt))


def test_motion_jacobians_are_the_derivatives_of_dead_reckoning():
    """Oracle: central differences of the segments' local poses (prepare_segments on dead
    reckoning) when the speed is scaled by 1 + s and the turn rate gets κ v, reversing
    included: (O1) to rounding, (O2) to its second-order term (the chord's length)."""
    n, dt = 400, 0.05
    k = np.arange(n - 1)
    v = 0.3 + 0.2 * np.sin(0.05 * k)
    v[100:130] *= -1.0
    w = 0.4 * np.cos(0.03 * k)
    epochs = np.array([0, 37, 38, 90, 200, 333, n - 1])
    zero = np.zeros((n - 1, 3, 3))
    jac = motion_jacobians(dead_reckoning_segments(zero, _arc(v, w, dt), epochs), _arc(v, w, dt))
    h = 1e-6
    for col, (dv, dw) in enumerate(((h * v, 0 * w), (0 * v, h * v))):
        hi = dead_reckoning_segments(zero, _arc(v + dv, w + dw, dt), epochs).local
        lo = dead_reckoning_segments(zero, _arc(v - dv, w - dw, dt), epochs).local
        fd = (hi - lo) / (2 * h)
        tol = 1e-7 if col == 0 else 5e-5
        assert np.abs(fd - jac[:, :, col]).max() < tol * np.abs(jac[:, :, col]).max()
    assert np.abs(jac[epochs[1:], 2, 1]).min() > 0  # the heading follows κ over every segment


def test_virtual_epochs_keep_every_epoch_and_bound_the_gaps():
    """Hand example and property: the epochs are kept, none added where the grid is coarser
    than the spacing, and no two consecutive epochs more than the spacing apart otherwise."""
    t = np.array([0.0, 0.4, 0.8, 1.2, 1.6, 2.0, 5.0, 5.3])
    got = with_virtual_epochs(t, np.array([0, 2, 7]), 1.0)
    assert got.tolist() == [0, 2, 5, 6, 7]  # 2.0 s is ≥ 1 s after 0.8; 5.0 one long step
    rng = np.random.default_rng(5)
    t = np.cumsum(rng.uniform(0.01, 0.2, 3000))
    ep = np.unique(np.concatenate(([0, 2999], rng.integers(0, 3000, 40))))
    got = with_virtual_epochs(t, ep, 0.7)
    assert set(ep.tolist()) <= set(got.tolist())
    gaps = np.diff(t[got])
    assert (gaps <= 0.7 + 0.2).all() and gaps.max() > 0.5
    assert ob.epoch_spacing((3.0, 0.5)) == 0.0625 and ob.epoch_spacing((9.0, 8.0)) == 1.0


def _small(seed=3, **kw):
    return simulate_bundle(seed, steps=500, dt=0.1, landmarks=12, measure_every=10, **kw)


def test_vanishing_odometry_bias_is_the_recovery_without_it():
    """Oracle: σ of the odometry bias → 0 adds nothing (the epochs it adds only split the
    prediction), so the filter and the smoother equal the augmented recovery without it."""
    b = _small()
    inp = filter_input(b)
    sig = (0.5 * b.sensor.sigma_range, 0.5 * b.sensor.sigma_bearing)
    plain = run_persisting(inp, sig, (2.0, 2.0))
    tiny = run_persisting(inp, sig, (2.0, 2.0), motion=_Motion(1e-12, 2.0, 1e-12, 3.0))
    assert tiny.post_x.shape[0] > plain.post_x.shape[0]  # epochs were added
    np.testing.assert_allclose(tiny.fr.poses, plain.fr.poses, atol=1e-9)
    np.testing.assert_allclose(tiny.fr.covariances, plain.fr.covariances, rtol=1e-7, atol=1e-15)
    for a, c in zip(smooth_persisting(tiny)[:2], smooth_persisting(plain)[:2], strict=True):
        np.testing.assert_allclose(a, c, rtol=1e-6, atol=1e-12)


def test_fill_between_epochs_equals_the_poses_made_epochs(monkeypatch):
    """Oracle: the closed-form fill of the grid poses between epochs (filter and smoother)
    against the same run with every grid pose an epoch (no fill at all), for a bias held
    exactly (τ 10⁶ s: holding it over a segment is then no approximation). The two are the
    same linear-Gaussian smoother linearised at slightly different points."""
    b = _small(seed=4)
    inp = filter_input(b)
    motion = _Motion(0.1, 1e6, 0.05, 1e6)
    coarse = run_persisting(inp, None, None, motion=motion)
    monkeypatch.setattr(ob, "epoch_spacing", lambda tau: 1e-9)
    import recovery.persisting as rp

    monkeypatch.setattr(rp, "epoch_spacing", lambda tau: 1e-9)
    fine = run_persisting(inp, None, None, motion=motion)
    assert fine.post_x.shape[0] == inp.times.shape[0] > 2 * coarse.post_x.shape[0]
    inner = np.setdiff1d(np.arange(inp.times.shape[0]), coarse.fr.segments.epochs)
    # measured: poses 3.8e-4 m apart (a 33 m run), covariances 1.8e-3 of their largest
    # entry (filter) and 5.8e-4 (smoother); the bias's own share of them is 0.97
    scale = np.abs(fine.fr.covariances[inner]).max()
    d = coarse.fr.poses - fine.fr.poses
    d[:, 2] = se2.wrap_angle(d[:, 2])
    assert np.abs(d[inner]).max() < 1e-3
    assert np.abs(coarse.fr.covariances - fine.fr.covariances)[inner].max() < 5e-3 * scale
    (pc, cc, _), (pf, cf, _) = smooth_persisting(coarse), smooth_persisting(fine)
    d = pc - pf
    d[:, 2] = se2.wrap_angle(d[:, 2])
    assert np.abs(d[inner]).max() < 1e-3
    assert np.abs(cc - cf)[inner].max() < 2e-3 * np.abs(cf[inner]).max()
    # and the bias is felt: without it the covariances are far smaller
    none = run_persisting(inp, None, None, motion=_Motion(1e-12, 1e6, 1e-12, 1e6))
    assert np.abs(none.fr.covariances - fine.fr.covariances)[inner].max() > 0.5 * scale


def test_a_process_switched_off_is_the_other_one_alone():
    """A σ of 0 (motion_model.persisting allows it: that process off) recovers as the other
    process alone: the same poses and covariances as a vanishing σ, finite throughout."""
    b = odometry_bias_world(7, _Motion(0.08, 3.0, 0.0, 5.0))
    inp = filter_input(b)
    off = run_persisting(inp, None, None, motion=_Motion(0.08, 3.0, 0.0, 5.0))
    tiny = run_persisting(inp, None, None, motion=_Motion(0.08, 3.0, 1e-9, 5.0))
    for a, c in zip(smooth_persisting(off)[:2], smooth_persisting(tiny)[:2], strict=True):
        assert np.isfinite(a).all()
        np.testing.assert_allclose(a, c, rtol=1e-6, atol=1e-9)


def _gm(rng, t, sigma, tau):
    """A stationary first-order Gauss–Markov sequence at times ``t`` (the oracle's recursion)."""
    x = np.empty(t.size)
    x[0] = sigma * rng.standard_normal()
    ph = np.exp(-np.diff(t) / tau)
    for i in range(1, t.size):
        x[i] = ph[i - 1] * x[i - 1] + sigma * np.sqrt(1 - ph[i - 1] ** 2) * rng.standard_normal()
    return x


def odometry_bias_world(seed: int, motion: _Motion):
    """A simulated velocity-model run whose stated controls carry a Gauss–Markov speed-scale
    and turn-per-metre error on top of their white noise: the truth moves with
    ``(v (1 + s), ω + κ v)`` of the controls the bundle holds."""
    b = _small(seed=seed, sigma_v=0.02, sigma_omega=0.01)
    rng = np.random.default_rng([4242, seed])
    c = np.array(b.controls)
    s = _gm(rng, c[:, 0], motion.sigma_scale, motion.time_constant_scale)
    kappa = _gm(rng, c[:, 0], motion.sigma_turn, motion.time_constant_turn)
    c[:, 1] = c[:, 1] / (1.0 + s)
    c[:, 2] = c[:, 2] - kappa * c[:, 1]
    return replace(b, controls=c)


@pytest.mark.slow  # 2 × 40 recoveries
def test_stated_odometry_bias_is_consistent_where_white_noise_is_not():
    """Monte Carlo, seeds 200–239: the smoother's mean NEES (dof 3) with the odometry's
    persisting error stated is χ²-consistent (3 within 3 standard errors of the runs' mean);
    the same runs recovered without it are overconfident (measured: 3.15 ± 0.11 against
    1502 ± 195; the stated filter's 3.02)."""
    motion = _Motion(0.08, 3.0, 0.08, 5.0)

    def nees(b, m):
        inp = filter_input(b)
        poses, covs, _ = smooth_persisting(run_persisting(inp, None, None, motion=m))
        e = poses - b.groundtruth.poses_at(inp.times)
        e[:, 2] = se2.wrap_angle(e[:, 2])
        return float(np.einsum("ni,nij,nj->n", e[1:], np.linalg.inv(covs[1:]), e[1:]).mean())

    stated, white = [], []
    for seed in range(200, 240):
        b = odometry_bias_world(seed, motion)
        stated.append(nees(b, motion))
        white.append(nees(b, _Motion(1e-12, 3.0, 1e-12, 5.0)))
    se = np.std(stated, ddof=1) / np.sqrt(len(stated))
    assert abs(np.mean(stated) - 3.0) < 3 * se
    assert np.mean(white) > 3.0 + 6 * np.std(white, ddof=1) / np.sqrt(len(white))


@pytest.mark.filterwarnings("ignore:only .* distinct pose pairs")  # a short simulated run
def test_the_report_says_which_persisting_errors_the_recovery_carried():
    """The run's notes name each stated persisting error with its numbers (and the epochs'
    spacing), and say nothing for a bundle that states none."""
    from recovery.models import MotionPersisting, PersistingError
    from slamrel.pipeline import RunInput, score_bundle

    b = _small(seed=5)
    assert not any("persist" in n for n in score_bundle(RunInput(b, "plain")).notes)
    motion = MotionPersisting(0.08, 3.0, 0.05, 16.0)
    sensor = PersistingError(0.5 * b.sensor.sigma_range, 0.5 * b.sensor.sigma_bearing, 2.0, 4.0)
    b = replace(
        b, motion=replace(b.motion, persisting=motion), sensor=replace(b.sensor, persisting=sensor)
    )
    (note,) = [n for n in score_bundle(RunInput(b, "both")).notes if "persist" in n]
    for words in ("speed scale σ 0.08, τ 3 s", "turn per metre σ 0.05 rad/m, τ 16 s",
                  "at most 0.375 s", "bias per landmark track", "bearing σ"):  # fmt: skip
        assert words in note


def test_a_recovery_too_large_for_the_memory_is_refused_before_work(monkeypatch):
    """The augmented recovery's E × D × D arrays against the budget: refused with the sizes
    named (one clear InputError), before the filter runs."""
    import recovery.batch_refinement as br
    from relation_metric.errors import InputError

    b = _small()
    inp = filter_input(b)
    monkeypatch.setattr(br, "memory_budget", lambda: 1e3)
    # D = 3 + 2 × 12 (the map's error: its covariance is not zero) + 2 (the odometry bias)
    with pytest.raises(InputError, match=r"\d+ epochs x 29 x 29 states"):
        run_persisting(inp, None, None, motion=_Motion(0.1, 3.0, 0.05, 5.0))
