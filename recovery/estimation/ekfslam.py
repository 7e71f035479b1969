"""A reference EKF-SLAM for planar range-bearing landmark SLAM.

State ``[x, y, θ, l_1x, l_1y, …]`` with a dense joint covariance (Smith, Self & Cheeseman;
Dissanayake et al. 2001). The motion comes as increments on a time grid
(:func:`recovery.steps.build_steps`: the bundle's velocity or odometry model, cut at the
measurement times), so the filter and the offline recovery share one implementation of the
motion and sensor models (:mod:`recovery.models`). Per step the pose is predicted
``x ← x ∘ u`` (``F = ∂(x ∘ u)/∂x``, ``Q = Rot(θ) Σ Rot(θ)ᵀ``); per measurement a landmark is
either initialised from the inverse sensor model or updated with the range-bearing model,
bearing innovation wrapped.

Data association is *known* (the landmark ids given with the measurements) or
*nearest neighbour* with a χ² gate on the innovation; in the latter mode every decision is
kept, and when the true ids are given the wrong ones are recorded as such. For experiments
on degraded maps a seeded fraction of the known associations can be corrupted on purpose
(``corrupt_fraction``), and the filter's assumed noise can be scaled (``noise_scale``).

The filter keeps no trajectory by design; ``online`` poses (the pose estimate after each
step's updates) are stored for validation only.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2

from recovery.models import SensorModel, process_noise, range_bearing
from recovery.steps import Steps
from relation_metric import se2
from relation_metric.arrays import Array
from relation_metric.errors import DivergenceError, InputError
from relation_metric.trajectory import Trajectory, readonly

__all__ = ["EkfSlamResult", "ekf_slam"]

UNASSOCIATED = -1
# Rows of the covariance per block of the in-place update (see _update).
_UPDATE_ROWS = 32


@dataclass(frozen=True)
class EkfSlamResult:
    """What an EKF-SLAM run leaves behind.

    Attributes
    ----------
    landmark_ids : ndarray of int, shape (M,)
        Ids of the mapped landmarks (the given ids with known association; 0..M−1 in order
        of creation with nearest-neighbour association).
    map_xy : ndarray, shape (M, 2)
    map_covariance : ndarray, shape (2M, 2M)
        Joint covariance of the map, landmarks in ``landmark_ids`` order.
    association : ndarray of int, shape (K,)
        Landmark id each measurement was associated with (−1: rejected).
    wrong_association : ndarray of bool, shape (K,)
        True where the association is known to be wrong (corrupted on purpose, or a
        nearest-neighbour decision that disagrees with the true ids).
    online : Trajectory
        The filter's pose after each step (validation only).
    online_covariance : ndarray, shape (N, 3, 3)
    """

    landmark_ids: NDArray[np.int64]
    map_xy: Array
    map_covariance: Array
    association: NDArray[np.int64]
    wrong_association: NDArray[np.bool_]
    online: Trajectory
    online_covariance: Array


def ekf_slam(
    steps: Steps,
    measurements: Array,
    landmarks: Array,
    *,
    sensor: SensorModel,
    initial_pose: Array,
    initial_covariance: Array,
    association: Literal["known", "nn"] = "known",
    gate: float = 0.99,
    new_landmark_gate: float = 0.9999,
    outlier_gate: float | None = None,
    max_rejected_run: int = 10,
    true_ids: NDArray[np.int64] | None = None,
    corrupt_fraction: float = 0.0,
    noise_scale: float = 1.0,
    seed: int = 0,
) -> EkfSlamResult:
    """Run EKF-SLAM over a log.

    Parameters
    ----------
    steps : recovery.steps.Steps
        The motion on the time grid (``build_steps(bundle)``): increments ``u_k`` and their
        body-frame covariances ``Σ_k``, and the grid index of every measurement (−1: outside
        the motion's time span, not used).
    measurements : ndarray, shape (J, 2)
        ``[range, bearing]``, in time order.
    landmarks : ndarray, shape (J,)
        Landmark id of each measurement for ``association="known"`` (ignored, may be NaN,
        for ``"nn"``).
    sensor : recovery.models.SensorModel
    initial_pose, initial_covariance : ndarray, shapes (3,) and (3, 3)
    association : {"known", "nn"}
    gate, new_landmark_gate : float
        χ² probabilities (2 dof): with ``"nn"`` a measurement is associated with the nearest
        landmark (Mahalanobis) inside ``gate``, starts a new landmark outside
        ``new_landmark_gate`` and is rejected in between.
    outlier_gate : float, optional
        χ² probability (2 dof) of a validation gate on the updates of *known* associations:
        a measurement of a mapped landmark whose normalised innovation squared exceeds it is
        rejected (association −1 in the result, so recovery does not use it either).
        ``None`` (default) uses every measurement. Real sensors have outliers that a
        Gaussian filter cannot absorb (MRCLAM: a few per cent beyond 5 σ); a gate trades
        them for the risk of rejecting good data when the filter is overconfident, so the
        rejected count is always reported.
    max_rejected_run : int
        With ``outlier_gate``: after this many consecutive rejections the filter takes the
        next measurement whatever its innovation. A run of rejections means the pose, not
        the measurements, is wrong (a bump, wheel slip); without this rule a gated filter
        never recovers from it (MRCLAM dataset 7, robot 5, ~700 s: 0.9 rad of unmodelled
        turn).
    true_ids : ndarray of int, shape (J,), optional
        True landmark of each measurement, to record wrong associations.
    corrupt_fraction : float
        Fraction of known associations replaced on purpose by another, seeded, landmark id.
    noise_scale : float
        Factor on every standard deviation the filter assumes (an inflated-noise filter).
    seed : int
        For ``corrupt_fraction``.

    Returns
    -------
    EkfSlamResult

    Raises
    ------
    DivergenceError
        On a non-finite state or an innovation covariance that is not positive definite;
        the message names the time and the measurement.
    """
    z = np.asarray(measurements, dtype=np.float64).reshape(-1, 2)
    grid = np.asarray(steps.measurement_grid, dtype=np.int64)
    if grid.shape[0] != z.shape[0]:
        raise InputError(f"{z.shape[0]} measurements but {grid.shape[0]} grid indices")
    used = grid >= 0
    if np.any(np.diff(grid[used]) < 0):
        raise InputError("measurements must be sorted by time")
    if not (0.0 <= corrupt_fraction < 1.0):
        raise InputError(f"corrupt_fraction must be in [0, 1), got {corrupt_fraction}")
    ids_in = np.asarray(landmarks, dtype=np.float64).copy()
    wrong = np.zeros(z.shape[0], dtype=bool)
    if association == "known":
        if not np.isfinite(ids_in[used]).all():
            raise InputError("known association needs a landmark id for every measurement")
        if corrupt_fraction > 0:
            rng = np.random.default_rng(seed)
            pool = np.unique(ids_in[used])
            pick = used & (rng.random(z.shape[0]) < corrupt_fraction)
            other = pool[rng.integers(0, pool.size, pick.sum())]
            same = other == ids_in[pick]
            other[same] = pool[(np.searchsorted(pool, other[same]) + 1) % pool.size]
            ids_in[pick] = other
            wrong[pick] = pool.size > 1
    elif association != "nn":
        raise InputError(f"association must be 'known' or 'nn', got {association!r}")
    sig_u = np.asarray(steps.sigma) * noise_scale**2
    r_cov = sensor.covariance * noise_scale**2
    g_in = chi2.ppf(gate, 2)
    g_new = chi2.ppf(new_landmark_gate, 2)
    if outlier_gate is not None and not 0.0 < outlier_gate < 1.0:
        raise InputError(f"outlier_gate must be in (0, 1), got {outlier_gate}")
    g_out = np.inf if outlier_gate is None else float(chi2.ppf(outlier_gate, 2))
    if max_rejected_run < 1:
        raise InputError(f"max_rejected_run must be at least 1, got {max_rejected_run}")
    run = 0  # consecutive rejections

    t = steps.times
    n_poses = t.size
    inc = steps.u
    cap = 3 + 2 * (int(np.unique(ids_in[used]).size) if association == "known" else int(used.sum()))
    mu = np.zeros(cap)
    cov = np.zeros((cap, cap))
    mu[:3] = np.asarray(initial_pose, dtype=np.float64)
    cov[:3, :3] = np.asarray(initial_covariance, dtype=np.float64)
    n = 3  # used size of the state
    slot_of: dict[int, int] = {}  # landmark id -> state offset
    ids_out: list[int] = []
    assoc_out = np.full(z.shape[0], UNASSOCIATED, dtype=np.int64)
    online = np.empty((n_poses, 3))
    online_cov = np.empty((n_poses, 3, 3))
    order = np.flatnonzero(used)
    starts = np.searchsorted(grid[order], np.arange(n_poses + 1))
    for k in range(n_poses):
        if k > 0:
            u = inc[k - 1]
            fx = se2.compose_jacobian(mu[:3], u)
            q = process_noise(mu[2], sig_u[k - 1])
            mu[:3] = se2.compose(mu[:3], u)
            # P_xx ← F P_xx Fᵀ + Q, P_xm ← F P_xm
            top = fx @ cov[:3, :n]
            pxx = top[:, :3] @ fx.T + q
            pxx = 0.5 * (pxx + pxx.T)  # 3×3: the covariance stays exactly symmetric
            cov[:3, :n] = top
            cov[:n, :3] = top.T
            cov[:3, :3] = pxx
        for m in order[starts[k] : starts[k + 1]]:
            meas = z[m]
            if association == "known":
                lid = int(ids_in[m])
                slot = slot_of.get(lid)
            else:
                slot, lid = _nearest(mu, cov, n, meas, r_cov, g_in, g_new, len(ids_out))
                if slot == -2:  # ambiguous: rejected
                    continue
            if slot is None or slot < 0:
                slot = n
                _initialise(mu, cov, n, meas, r_cov)
                n += 2
                slot_of[lid] = slot
                ids_out.append(lid)
            else:
                g = g_out if run < max_rejected_run else np.inf
                if not _update(mu, cov, n, slot, meas, r_cov, t[k], int(m), g):
                    run += 1
                    continue  # outside the validation gate: rejected
                run = 0
            assoc_out[m] = lid
        online[k] = mu[:3]
        online_cov[k] = cov[:3, :3]
        if not np.isfinite(mu[:n]).all():
            raise DivergenceError(f"non-finite state at t={float(t[k]):.6f} s (step {k})")
    m_count = len(ids_out)
    ids_arr = np.asarray(ids_out, dtype=np.int64)
    if association == "nn" and true_ids is not None:
        wrong = _nn_mistakes(assoc_out, np.asarray(true_ids, dtype=np.int64))
    return EkfSlamResult(
        landmark_ids=readonly(ids_arr, np.int64),
        map_xy=readonly(mu[3:n].reshape(m_count, 2)),
        map_covariance=readonly(0.5 * (cov[3:n, 3:n] + cov[3:n, 3:n].T)),
        association=readonly(assoc_out, np.int64),
        wrong_association=readonly(wrong, np.bool_),
        online=Trajectory(t, online),
        online_covariance=readonly(online_cov),
    )


def _initialise(mu: Array, cov: Array, n: int, meas: Array, r_cov: Array) -> None:
    r, b = meas
    th = mu[2] + b
    c, s = np.cos(th), np.sin(th)
    mu[n : n + 2] = mu[:2] + r * np.array([c, s])
    gx = np.array([[1.0, 0.0, -r * s], [0.0, 1.0, r * c]])
    gz = np.array([[c, -r * s], [s, r * c]])
    cross = gx @ cov[:3, :n]  # (2, n)
    cov[n : n + 2, :n] = cross
    cov[:n, n : n + 2] = cross.T
    pll = gx @ cov[:3, :3] @ gx.T + gz @ r_cov @ gz.T
    cov[n : n + 2, n : n + 2] = 0.5 * (pll + pll.T)


def _update(
    mu: Array,
    cov: Array,
    n: int,
    slot: int,
    meas: Array,
    r_cov: Array,
    t: float,
    m: int,
    gate: float = np.inf,
) -> bool:
    """EKF update with one range-bearing measurement; False (no update) when ``νᵀS⁻¹ν > gate``.

    The covariance update is written in a symmetric form, in place, one block of rows at a
    time: with ``S = L Lᵀ`` (Cholesky) and ``W = P Hᵀ L⁻ᵀ`` (n × 2),
    ``P ← P − K S Kᵀ = P − W Wᵀ``. Each element ``W_i·W_j`` is the same two products summed
    in the same order as ``W_j·W_i``, so an exactly symmetric ``P`` stays exactly symmetric
    (predict and initialise keep their small blocks symmetric) and no ``0.5·(P + Pᵀ)`` pass
    over the whole matrix is needed. Rows are done :data:`_UPDATE_ROWS` at a time so the
    temporary stays in cache and the matrix is read and written once (memory-bound: the
    second BLAS thread does not pay at these shapes, so blocks are kept small enough that
    OpenBLAS uses one).
    """
    h, hx, hl = range_bearing(mu[:3], mu[slot : slot + 2])
    nu = meas - h
    nu[1] = se2.wrap_angle(nu[1])
    pht = cov[:n, :3] @ hx.T + cov[:n, slot : slot + 2] @ hl.T  # (n, 2)
    s = hx @ pht[:3] + hl @ pht[slot : slot + 2] + r_cov
    s = 0.5 * (s + s.T)
    try:
        l_inv = np.linalg.inv(np.linalg.cholesky(s))  # S = L Lᵀ; fails unless S is PD
    except np.linalg.LinAlgError:
        raise DivergenceError(
            f"innovation covariance not positive definite at t={float(t):.6f} s (measurement {m})"
        ) from None
    white = l_inv @ nu  # L⁻¹ν: νᵀS⁻¹ν = |L⁻¹ν|²
    if gate < np.inf and float(white @ white) > gate:
        return False
    w = pht @ l_inv.T  # (n, 2): K = W L⁻¹, K S Kᵀ = W Wᵀ
    mu[:n] += w @ white
    mu[2] = se2.wrap_angle(mu[2])
    wt = np.ascontiguousarray(w.T)
    for i in range(0, n, _UPDATE_ROWS):
        j = min(i + _UPDATE_ROWS, n)
        cov[i:j, :n] -= w[i:j] @ wt
    return True


def _nearest(
    mu: Array, cov: Array, n: int, meas: Array, r_cov: Array, g_in: float, g_new: float, count: int
) -> tuple[int | None, int]:
    """Nearest landmark by Mahalanobis distance, vectorised over all landmarks."""
    if count == 0:
        return None, 0
    lms = mu[3:n].reshape(count, 2)
    dx = lms[:, 0] - mu[0]
    dy = lms[:, 1] - mu[1]
    qd = dx * dx + dy * dy
    rr = np.sqrt(qd)
    h = np.column_stack((rr, se2.wrap_angle(np.arctan2(dy, dx) - mu[2])))
    hl = np.stack(
        (np.column_stack((dx / rr, dy / rr)), np.column_stack((-dy / qd, dx / qd))), axis=1
    )
    hx = np.concatenate((-hl, np.tile(np.array([[0.0], [-1.0]]), (count, 1, 1))), axis=2)
    idx = 3 + 2 * np.arange(count)
    pxx = cov[:3, :3]
    pxl = np.stack((cov[:3, idx], cov[:3, idx + 1]), axis=2)  # (3, count, 2)
    pll = np.stack(
        (
            np.stack((cov[idx, idx], cov[idx, idx + 1]), axis=1),
            np.stack((cov[idx + 1, idx], cov[idx + 1, idx + 1]), axis=1),
        ),
        axis=1,
    )  # (count, 2, 2)
    s = (
        hx @ pxx @ np.swapaxes(hx, 1, 2)
        + hx @ np.swapaxes(pxl, 0, 1) @ np.swapaxes(hl, 1, 2)
        + hl @ np.swapaxes(np.swapaxes(pxl, 0, 1), 1, 2) @ np.swapaxes(hx, 1, 2)
        + hl @ pll @ np.swapaxes(hl, 1, 2)
        + r_cov
    )
    nu = meas[None, :] - h
    nu[:, 1] = se2.wrap_angle(nu[:, 1])
    d2 = np.einsum("ka,kab,kb->k", nu, np.linalg.inv(s), nu)
    best = int(np.argmin(d2))
    if d2[best] <= g_in:
        return 3 + 2 * best, best
    if d2[best] > g_new:
        return None, count
    return -2, -1


def _nn_mistakes(assoc: NDArray[np.int64], true_ids: NDArray[np.int64]) -> NDArray[np.bool_]:
    """A decision is wrong when its landmark's majority true id differs from the measurement's."""
    used = assoc >= 0
    wrong = np.zeros(assoc.shape, dtype=bool)
    if not used.any():
        return wrong
    a, tr = assoc[used], true_ids[used]
    pairs, counts = np.unique(np.column_stack((a, tr)), axis=0, return_counts=True)
    order = np.lexsort((-counts, pairs[:, 0]))
    first = np.concatenate(([True], np.diff(pairs[order, 0]) != 0))
    majority = dict(zip(pairs[order][first, 0].tolist(), pairs[order][first, 1].tolist()))
    wrong[used] = np.array([majority[x] for x in a.tolist()]) != tr
    return wrong
