"""The filter's and smoother's fast paths give the bits of the plain computations
they replace: the scalar angle wrap, the composed predictions (per-epoch values repeated over
the segments, the rotated step noise without its zero terms), the fill of every grid pose and
the smoother between epochs. Each oracle is the plain version the fast path replaced."""

from __future__ import annotations

import math

import numpy as np
import pytest

from recovery import ekf
from recovery.recover import filter_input
from recovery.smoother import smooth
from relation_metric.se2 import shear
from slamrel.simulation.bundles import simulate_bundle


def bits(x):
    return np.asarray(x, dtype=np.float64).view(np.int64)


def plain_segments(sigma, heading, position, epochs):
    """prepare_segments before its fast path: searched bases, gathered angles, full predict6."""
    n = heading.shape[0]
    base = np.zeros(n, dtype=np.int64)
    base[1:] = epochs[np.searchsorted(epochs, np.arange(n - 1), side="right") - 1]
    dth = heading - heading[base]
    c, s = np.cos(heading[base]), np.sin(heading[base])
    dp = position - position[base]
    local = np.column_stack((c * dp[:, 0] + s * dp[:, 1], -s * dp[:, 0] + c * dp[:, 1], dth))
    q = np.zeros((6, n))
    a = base[1:]
    phi = heading[:-1] - heading[a]
    c, s = np.cos(phi), np.sin(phi)
    zero = np.zeros(n - 1)
    qm = ekf.predict6((zero,) * 6, tuple(sigma[:, i, j] for i, j in ekf.SYM6), c, s, zero, zero)
    f0, f1 = -local[1:, 1], local[1:, 0]
    q02, q12, q22 = qm[2], qm[4], qm[5]
    terms = np.array(
        [*qm, f0 * q02, f0 * q12, f0 * q22, f1 * q02, f1 * q12, f1 * q22]
        + [q22 * f0 * f0, q22 * f0 * f1, q22 * f1 * f1]
    )
    cs_ = np.cumsum(terms, axis=1)
    before = np.concatenate((np.zeros((15, 1)), cs_), axis=1)
    a00, a01, a02, a11, a12, a22, c00, c01, c02, c10, c11, c12, g00, g01, g11 = cs_ - before[:, a]
    e0, e1 = f0, f1
    q[0, 1:] = a00 + 2 * e0 * a02 - 2 * c00 + a22 * e0 * e0 - 2 * e0 * c02 + g00
    q[1, 1:] = a01 + e0 * a12 + a02 * e1 - c01 - c10 + a22 * e0 * e1 - e0 * c12 - c02 * e1 + g01
    q[2, 1:] = a02 + e0 * a22 - c02
    q[3, 1:] = a11 + 2 * e1 * a12 - 2 * c11 + a22 * e1 * e1 - 2 * e1 * c12 + g11
    q[4, 1:] = a12 + e1 * a22 - c12
    q[5, 1:] = a22
    return base, local, q


def plain_fill(seg, psi, post_x, post_p):
    """fill before its fast path: searched epochs, cos/sin of the repeated angles."""
    e_of = np.searchsorted(seg.epochs, seg.base)
    ps = psi[e_of]
    c, s = np.cos(ps), np.sin(ps)
    loc = seg.local
    w = np.column_stack((c * loc[:, 0] - s * loc[:, 1], s * loc[:, 0] + c * loc[:, 1], loc[:, 2]))
    pb = tuple(post_p[:, i, j][e_of] for i, j in ekf.SYM6)
    p6 = ekf.predict6(pb, tuple(seg.q), c, s, w[:, 0], w[:, 1])
    covs = np.empty((w.shape[0], 3, 3))
    for col, (i, j) in zip(p6, ekf.SYM6):
        covs[:, i, j] = covs[:, j, i] = col
    return w, post_x[e_of] + w, covs


def plain_smooth(fr):
    """smooth before its fast path: Hillis–Steele scan, then every pose between epochs gathered."""
    ep = fr.segments.epochs
    w = plain_fill(fr.segments, fr.psi, fr.post_poses, fr.post_covariances)[0]
    post_x, post_p, pri_x, pri_p = (
        fr.post_poses, fr.post_covariances, fr.prior_poses, fr.prior_covariances
    )  # fmt: skip
    inv_pri = np.linalg.inv(pri_p)
    gain = post_p[:-1] @ shear(w[ep[1:], :2]).transpose(0, 2, 1) @ inv_pri[1:]
    a = gain.copy()
    b = np.einsum("nij,nj->ni", gain, post_x[1:] - pri_x[1:])
    d = gain @ (post_p[1:] - pri_p[1:]) @ gain.transpose(0, 2, 1)
    n, off = a.shape[0], 1
    while off < n:
        a1, b1, d1, a2, b2, d2 = a[: n - off], b[: n - off], d[: n - off], a[off:], b[off:], d[off:]
        nb, nd, na = (
            b1 + np.einsum("nij,nj->ni", a1, b2),
            d1 + a1 @ d2 @ a1.transpose(0, 2, 1),
            a1 @ a2,
        )
        a[: n - off], b[: n - off], d[: n - off] = na, nb, nd
        off *= 2
    sm_x_e, sm_p_e = post_x.copy(), post_p.copy()
    sm_x_e[:-1] += b
    sm_p_e[:-1] += d
    poses, covs = fr.poses.copy(), fr.covariances.copy()
    poses[ep], covs[ep] = sm_x_e, sm_p_e
    k = np.setdiff1d(np.arange(poses.shape[0]), ep)
    i = np.searchsorted(ep, fr.segments.base[k]) + 1
    to_next = w[ep[i], :2] - w[k, :2]
    pk = fr.covariances[k]
    m = pk.copy()
    m[:, :, 0] -= to_next[:, 1, None] * pk[:, :, 2]
    m[:, :, 1] += to_next[:, 0, None] * pk[:, :, 2]
    ck = m @ inv_pri[i]
    poses[k] = fr.poses[k] + (ck @ (sm_x_e[i] - pri_x[i])[:, :, None])[:, :, 0]
    corr = ck @ (sm_p_e[i] - pri_p[i]) @ ck.transpose(0, 2, 1)
    covs[k] = pk + 0.5 * (corr + corr.transpose(0, 2, 1))
    return poses, covs


def test_rotated_noise_is_predict6_at_zero_bit_for_bit(rng):
    """Dropping predict6's zero terms keeps every bit, signed zeros included."""
    n = 4000
    sigma = rng.choice([0.0, -0.0, 1e-3, -2e-4, 5.0], (n, 3, 3))
    phi = rng.choice([0.0, -0.0, math.pi / 2, -math.pi, 0.3, 2.0], n) + rng.choice([0.0, 1e-9], n)
    c, s = np.cos(phi), np.sin(phi)
    zero = np.zeros(n)
    want = ekf.predict6((zero,) * 6, tuple(sigma[:, i, j] for i, j in ekf.SYM6), c, s, zero, zero)
    out = np.empty((6, n))
    ekf._rotated_noise(sigma, c, s, out)
    assert np.array_equal(bits(out), bits(np.array(want)))


def _inputs(rng, n: int, signed_zeros: bool):
    """Random steps, reference poses and step covariances (some entries ±0)."""
    heading = np.cumsum(rng.normal(0.0, 0.3, n)) + 40.0
    position = np.cumsum(rng.normal(0.0, 1.0, (n, 2)), axis=0)
    g = rng.normal(0.0, 0.1, (n - 1, 3, 3))
    sigma = g @ g.transpose(0, 2, 1)
    if signed_zeros:  # entries and whole steps of ±0 (zero noise at rest)
        i, j = rng.integers(0, 3, (2, 4 * n))
        sigma[rng.integers(0, n - 1, 4 * n), i, j] = rng.choice([0.0, -0.0], 4 * n)
        rest = np.concatenate((np.arange(8), rng.integers(0, n - 1, n // 4)))  # from the start
        sigma[rest] = rng.choice([0.0, -0.0], (rest.shape[0], 3, 3))
        position[:9] = position[0]
    return sigma, heading, position


@pytest.mark.parametrize("signed_zeros", [False, True])
@pytest.mark.parametrize("every", [1, 3, 17, None])
def test_prepare_segments_is_the_plain_computation_bit_for_bit(rng, every, signed_zeros):
    n = 500
    sigma, heading, position = _inputs(rng, n, signed_zeros)
    inner = np.arange(1, n - 1, every) if every else rng.choice(n, 30)
    epochs = np.unique(np.concatenate(([0, n - 1], inner)))
    seg = ekf.prepare_segments(sigma, heading, position, epochs)
    base, local, q = plain_segments(sigma, heading, position, epochs)
    assert np.array_equal(seg.base, base)
    assert np.array_equal(seg.epochs[seg.epoch_of], seg.base)
    assert np.array_equal(bits(seg.local), bits(local))
    assert np.array_equal(bits(seg.q), bits(q))


def _filter_run(seed: int, **kw):  # type: ignore[no-untyped-def]
    b = simulate_bundle(
        seed,
        steps=1500,
        landmarks=30,
        measure_every=4,
        measurement_offset=0.4,
        map_sigma=(0.3, 0.1),
    )
    return ekf.run_filter(filter_input(b, map_mode="marginal"), **kw)


@pytest.mark.parametrize(
    "kw", [{}, {"robust": "redescending", "max_outlier_run": 2}, {"gate": 0.9, "robust": "cauchy"}]
)
def test_fill_and_smoother_are_the_plain_computations_bit_for_bit(kw):
    fr = _filter_run(11, **kw)
    w, poses, covs = plain_fill(fr.segments, fr.psi, fr.post_poses, fr.post_covariances)
    ep = fr.segments.epochs
    poses[ep], covs[ep] = fr.post_poses, fr.post_covariances
    assert np.array_equal(bits(fr.steps), bits(w))
    assert np.array_equal(bits(ekf.world_steps(fr.segments, fr.psi)), bits(w))
    assert np.array_equal(bits(fr.poses), bits(poses))
    assert np.array_equal(bits(fr.covariances), bits(covs))
    sm = smooth(fr)
    sm_poses, sm_covs = plain_smooth(fr)
    assert np.array_equal(bits(sm.poses), bits(sm_poses))
    assert np.array_equal(bits(sm.covariances), bits(sm_covs))


def test_priors_and_posteriors_are_the_loops_values():
    """The loop's flat buffers come back as (E, 3) / (E, 3, 3) arrays, symmetric, each epoch's
    posterior at its grid pose."""
    fr = _filter_run(5)
    e = fr.segments.epochs.shape[0]
    assert fr.prior_poses.shape == fr.post_poses.shape == (e, 3)
    assert fr.prior_covariances.shape == fr.post_covariances.shape == (e, 3, 3)
    for p in (fr.prior_covariances, fr.post_covariances):
        assert np.array_equal(p, p.transpose(0, 2, 1)) and p.flags.writeable
    assert np.array_equal(fr.poses[fr.segments.epochs], fr.post_poses)
    assert np.array_equal(fr.covariances[fr.segments.epochs], fr.post_covariances)
