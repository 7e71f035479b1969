"""Extended Rauch–Tung–Striebel smoother over the EKF localisation of :mod:`recovery.ekf`.

RTS (Rauch, Tung & Striebel 1965; Särkkä, *Bayesian Filtering and Smoothing*, Alg. 9.3 for
the extended form): ``C_k = P⁺_k F_kᵀ (P⁻_{k+1})⁻¹``,
``x^s_k = x⁺_k + C_k (x^s_{k+1} − x⁻_{k+1})``, ``P^s_k = P⁺_k + C_k (P^s_{k+1} − P⁻_{k+1}) C_kᵀ``,
with the filter's own linearisation ``F_k`` (the unicycle shear), not ``F x`` as a linear
smoother would predict; angle differences are taken on unwrapped headings that stay within a
few milliradians, and the output is wrapped once.

Between two measurement epochs there are no updates, so the gains chain in closed form:
``C_k C_{k+1} ⋯ C_{j−1} = P_k S(p_j − p_k)ᵀ (P⁻_j)⁻¹``. The smoother therefore runs the RTS
recursion over the epochs only — written as a suffix scan (Hillis–Steele doubling) of the
affine maps ``δ ↦ C δ + C g`` and ``Δ ↦ C Δ Cᵀ + C G Cᵀ`` (``g = x⁺ − x⁻``, ``G = P⁺ − P⁻``
the filter's correction at the next epoch; ``δ = x^s − x⁺``, ``Δ = P^s − P⁺``), which compose
in closed form — and then fills every pose between epochs at once.

The smoother works on the filter's own priors and posteriors, so a robust filter run
(M-estimator weights) and the filter's re-entries (covariance inflation where the map and the
log disagree) carry over unchanged: the smoother uses the same robust model as the filter.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from recovery.ekf import FilterResult
from relation_metric.arrays import Array
from relation_metric.se2 import shear

__all__ = ["SmootherResult", "smooth", "smoothed_covariances"]


@dataclass(frozen=True)
class SmootherResult:
    """Smoothed poses (N, 3) (unwrapped) and covariances (N, 3, 3) on the filter's grid."""

    poses: Array
    covariances: Array


def _suffix_scan(a: Array, b: Array, d: Array) -> tuple[Array, Array]:
    """Compose ``T_i ∘ T_{i+1} ∘ … ∘ T_{n−1}`` for all i and apply it to zero.

    ``T_i(δ, Δ) = (A_i δ + b_i, A_i Δ A_iᵀ + D_i)``; the composition of two such maps is
    ``(A₁A₂, A₁ b₂ + b₁, A₁ D₂ A₁ᵀ + D₁)``. Returns ``(b_tot, D_tot)``.
    """
    a, b, d = a.copy(), b.copy(), d.copy()
    n = a.shape[0]
    off = 1
    while off < n:
        a1, b1, d1 = a[: n - off], b[: n - off], d[: n - off]
        a2, b2, d2 = a[off:], b[off:], d[off:]
        nb = b1 + np.einsum("nij,nj->ni", a1, b2)
        nd = d1 + a1 @ d2 @ a1.transpose(0, 2, 1)
        b[: n - off], d[: n - off] = nb, nd
        if 2 * off < n:  # the products are needed by a later round
            a[: n - off] = a1 @ a2
        off *= 2
    return b, d


def smooth(fr: FilterResult) -> SmootherResult:
    """Extended RTS smoothing of a filter run (see module doc).

    Parameters
    ----------
    fr : FilterResult

    Returns
    -------
    SmootherResult
    """
    poses, covs = _smooth(fr, with_poses=True)
    assert poses is not None  # with_poses=True
    return SmootherResult(poses=poses, covariances=covs)


def smoothed_covariances(fr: FilterResult) -> Array:
    """The covariances (N, 3, 3) of :func:`smooth`, bit for bit, without the poses.

    The covariance recursion does not read the means, so this skips the mean half of the
    epoch scan and of the fill between epochs (for the batch's covariance pass, whose
    filter is linearised at given poses).
    """
    return _smooth(fr, with_poses=False)[1]


def _smooth(fr: FilterResult, *, with_poses: bool) -> tuple[Array | None, Array]:
    """Smoothed poses (or None without ``with_poses``) and covariances."""
    seg = fr.segments
    ep = seg.epochs
    n_e = ep.shape[0]
    w = fr.steps  # pose k relative to its base epoch, world frame
    post_x, post_p = fr.post_poses, fr.post_covariances
    pri_x, pri_p = fr.prior_poses, fr.prior_covariances
    # float64 already (returned as is); the stubs type inv() as floating[Any]
    inv_pri = np.asarray(np.linalg.inv(pri_p), dtype=np.float64)
    delta_e = np.zeros((n_e, 3))
    big_e = np.zeros((n_e, 3, 3))
    if n_e > 1:
        step = w[ep[1:], :2]  # displacement epoch i -> i+1
        gain = post_p[:-1] @ shear(step).transpose(0, 2, 1) @ inv_pri[1:]
        g = post_x[1:] - pri_x[1:] if with_poses else np.zeros((n_e - 1, 3))
        gg = post_p[1:] - pri_p[1:]
        b = np.einsum("nij,nj->ni", gain, g)
        d = gain @ gg @ gain.transpose(0, 2, 1)
        delta_e[:-1], big_e[:-1] = _suffix_scan(gain, b, d)
    sm_p_e = post_p + big_e
    covs = np.empty_like(fr.covariances)
    covs[ep] = sm_p_e
    if not with_poses:
        _between_epochs(fr, inv_pri, None, sm_p_e - pri_p, None, covs)
        return None, covs
    sm_x_e = post_x + delta_e
    poses = np.empty_like(fr.poses)
    poses[ep] = sm_x_e
    _between_epochs(fr, inv_pri, sm_x_e - pri_x, sm_p_e - pri_p, poses, covs)
    return poses, covs


def _between_epochs(  # type: ignore[no-untyped-def]
    fr: FilterResult, inv_pri: Array, corr_x: Array | None, corr_p: Array, poses, covs
) -> None:
    """Smoothed poses and covariances of every pose between two epochs, in place.

    ``C_k = P_k S(p_j − p_k)ᵀ (P⁻_j)⁻¹`` towards the next epoch ``j``;
    ``x^s_k = x_k + C_k (x^s_j − x⁻_j)``, ``P^s_k = P_k + C_k (P^s_j − P⁻_j) C_kᵀ``
    (symmetrised). ``inv_pri`` (E, 3, 3): ``(P⁻)⁻¹`` of the epochs; ``corr_x`` (E, 3),
    ``corr_p`` (E, 3, 3): ``x^s − x⁻`` and ``P^s − P⁻`` at the epochs. ``poses`` None: the
    covariances only (``corr_x`` is not read).
    """
    seg, w = fr.segments, fr.steps
    ep = seg.epochs
    is_epoch = np.zeros(covs.shape[0], dtype=bool)
    is_epoch[ep] = True
    k = np.flatnonzero(~is_epoch)
    if not k.size:
        return
    i = seg.epoch_of[k] + 1  # the next epoch
    # np.take: rows gathered faster than by numpy's fancy indexing (benchmarks/README.md)
    to_next = np.take(w, ep[i], axis=0)[:, :2] - np.take(w, k, axis=0)[:, :2]
    pk = np.take(fr.covariances, k, axis=0)
    m = pk.copy()  # P_k S(Δ)ᵀ, with S(Δ)ᵀ = [[1, 0, 0], [0, 1, 0], [−Δy, Δx, 1]]
    m[:, :, 0] -= to_next[:, 1, None] * pk[:, :, 2]
    m[:, :, 1] += to_next[:, 0, None] * pk[:, :, 2]
    ck = m @ np.take(inv_pri, i, axis=0)
    if poses is not None:
        assert corr_x is not None  # given with the poses
        step = (ck @ np.take(corr_x, i, axis=0)[:, :, None])[:, :, 0]
        poses[k] = np.take(fr.poses, k, axis=0) + step
    corr = ck @ np.take(corr_p, i, axis=0) @ ck.transpose(0, 2, 1)
    corr += corr.transpose(0, 2, 1).copy()
    corr *= 0.5
    covs[k] = np.add(pk, corr, out=corr)
