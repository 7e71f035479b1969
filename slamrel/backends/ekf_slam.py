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
(:func:`corrupt_associations`, outside the filter), and the filter's assumed noise can be
scaled (``noise_scale``). :func:`ekf_slam_bundle` runs the filter on a log bundle and returns
the result bundle a filter-based SLAM system would leave behind.

The optional validation gate on known associations (``outlier_gate``): real sensors have
outliers that a Gaussian filter cannot absorb (MRCLAM's residuals have a heavy tail:
benchmarks/README.md); a gate trades them for the risk of rejecting good data when the
filter is overconfident, so the rejected count is always reported (rejected measurements get
association −1, so recovery does not use them either). After ``max_rejected_run``
consecutive rejections the next measurement is taken whatever its innovation: a run of
rejections means the pose, not the measurements, is wrong (a bump, wheel slip); without this
rule a gated filter never recovers from it (seen on MRCLAM dataset 7: benchmarks/README.md).
The recovery filter's ``max_outlier_run`` (:func:`recovery.ekf.run_filter`) answers the same
symptom the other way: it inflates the pose covariance and re-enters, and reports the
stretch.

The filter keeps no trajectory by design; ``online`` poses (the pose estimate after each
step's updates) are stored for validation only.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Literal, NamedTuple

import numpy as np
from numpy.typing import NDArray

from recovery.bundle import Bundle
from recovery.models import MotionModel, SensorModel, process_noise, range_bearing
from recovery.steps import Steps, build_steps
from relation_metric import se2
from relation_metric.arrays import Array
from relation_metric.consistency import chi2_quantile
from relation_metric.errors import DivergenceError, InputError
from relation_metric.trajectory import Trajectory, readonly

__all__ = ["EkfSlamResult", "corrupt_associations", "ekf_slam", "ekf_slam_bundle"]

# The landmark row of a measurement no landmark was associated with (an association array
# entry, not a status: recovery.ekf.MeasurementStatus is what the recovery filter did).
NO_LANDMARK = -1
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
    noise_scale: float = 1.0,
    jacobians: Literal["standard", "fej", "oc"] = "standard",
    iterations: int = 1,
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
        for ``"nn"``); :func:`corrupt_associations` spoils a share of them on purpose.
    sensor : recovery.models.SensorModel
    initial_pose, initial_covariance : ndarray, shapes (3,) and (3, 3)
    association : {"known", "nn"}
    gate, new_landmark_gate : float
        χ² probabilities (2 dof): with ``"nn"`` a measurement is associated with the nearest
        landmark (Mahalanobis) inside ``gate``, starts a new landmark outside
        ``new_landmark_gate`` and is rejected in between.
    outlier_gate : float, optional
        χ² probability (2 dof) of a validation gate on the updates of *known* associations
        (module doc): a measurement of a mapped landmark whose normalised innovation squared
        exceeds it is rejected (association −1). ``None`` (default) uses every measurement.
    max_rejected_run : int
        With ``outlier_gate``: after this many consecutive rejections the filter takes the
        next measurement whatever its innovation (module doc).
    true_ids : ndarray of int, shape (J,), optional
        True landmark of each measurement, to record wrong associations (with ``"known"``:
        the used measurements whose given id differs from it).
    noise_scale : float
        Factor on every standard deviation the filter assumes (an inflated-noise filter).
    jacobians : {"standard", "fej"}
        Where the Jacobians are evaluated: at the latest estimates (the standard EKF), or at
        the *first estimates* (Huang, Mourikis & Roumeliotis 2008, FEJ-EKF): the motion
        Jacobian from the predicted poses ``x̂_{k+1|k} − x̂_{k|k−1}``, the measurement Jacobian
        at the step's predicted pose and the landmark's first estimate, so that the filter's
        linearised system keeps the unobservable directions of the true one (the standard
        EKF gains spurious heading information and becomes overconfident). Or
        *observability-constrained* (``"oc"``, after Huang, Mourikis & Roumeliotis 2010): every
        Jacobian at the latest estimates except the heading columns, the only ones the
        unobservable rotation involves, which are taken at linearisation points that keep it
        unobservable (:meth:`_Filter.observe`; docs/verdict.md): the pose stays consistent
        as with FEJ, and the landmarks, linearised at their latest estimates, stay
        consistent too. ``"fej"`` and ``"oc"``: known associations only.
    iterations : int
        Gauss–Newton iterations of each update (1, the default: the EKF). Above 1 the
        *iterated* update (not with ``"fej"``, whose Jacobians are fixed): each measurement
        relinearised at the damped iterate of its pose–landmark MAP problem
        (:func:`_iterate`; docs/verdict.md measures it with ``"oc"``).

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
    grid, used = _measurement_grid(steps, z.shape[0])
    ids_in = np.asarray(landmarks, dtype=np.float64)
    known = _check_association(association, ids_in, used)
    f = _Filter(
        3 + 2 * (int(np.unique(ids_in[used]).size) if known else int(used.sum())),
        initial_pose,
        initial_covariance,
        sensor.covariance * noise_scale**2,
        _Gates.of(gate, new_landmark_gate, outlier_gate, max_rejected_run),
        jacobians=jacobians,
        iterations=iterations,
    )
    if jacobians not in ("standard", "fej", "oc") or (jacobians != "standard" and not known):
        raise InputError(
            "jacobians: expected 'standard', or 'fej' with known associations, or 'oc' with "
            f"known associations, got {jacobians!r}"
        )
    whole = isinstance(iterations, int) and not isinstance(iterations, bool)
    if not (whole and iterations >= 1) or (iterations > 1 and jacobians == "fej"):
        raise InputError(
            "iterations: expected a whole number >= 1 (1 with jacobians 'fej', whose "
            f"Jacobians are fixed), got {iterations!r}"
        )
    assoc_out, online, online_cov = f.run(
        steps, np.asarray(steps.sigma) * noise_scale**2, z, ids_in if known else None, grid, used
    )
    t = steps.times
    return EkfSlamResult(
        landmark_ids=readonly(np.asarray(f.ids, dtype=np.int64), np.int64),
        map_xy=readonly(f.mu[3 : f.n].reshape(len(f.ids), 2)),
        map_covariance=readonly(0.5 * (f.cov[3 : f.n, 3 : f.n] + f.cov[3 : f.n, 3 : f.n].T)),
        association=readonly(assoc_out, np.int64),
        wrong_association=readonly(_mistakes(assoc_out, ids_in, used, true_ids, known), np.bool_),
        online=Trajectory(t, online),
        online_covariance=readonly(online_cov),
    )


def _measurement_grid(steps: Steps, count: int) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """Each measurement's grid index and whether it is used; InputError when out of order."""
    grid = np.asarray(steps.measurement_grid, dtype=np.int64)
    if grid.shape[0] != count:
        raise InputError(f"{count} measurements but {grid.shape[0]} grid indices")
    used = grid >= 0
    if np.any(np.diff(grid[used]) < 0):
        raise InputError("measurements must be sorted by time")
    return grid, used


def _check_association(association: str, ids: Array, used: NDArray[np.bool_]) -> bool:
    """True for known association (every used measurement has an id), False for ``"nn"``."""
    if association == "known":
        if not np.isfinite(ids[used]).all():
            raise InputError("known association needs a landmark id for every measurement")
        return True
    if association != "nn":
        raise InputError(f"association must be 'known' or 'nn', got {association!r}")
    return False


def _mistakes(
    assoc: NDArray[np.int64],
    ids: Array,
    used: NDArray[np.bool_],
    true_ids: NDArray[np.int64] | None,
    known: bool,
) -> NDArray[np.bool_]:
    """``wrong_association`` of the result (all False without ``true_ids``)."""
    if true_ids is None:
        return np.zeros(assoc.shape, dtype=bool)
    true_ids = np.asarray(true_ids, dtype=np.int64)
    if known:
        return used & (ids != true_ids)
    return _nn_mistakes(assoc, true_ids)


class _Gates(NamedTuple):
    """χ² thresholds (2 dof) of one run, and the rejected-run limit."""

    associate: float
    new_landmark: float
    outlier: float
    max_rejected_run: int

    @classmethod
    def of(cls, gate: float, new: float, outlier: float | None, max_run: int) -> _Gates:
        if outlier is not None and not 0.0 < outlier < 1.0:
            raise InputError(f"outlier_gate must be in (0, 1), got {outlier}")
        if max_run < 1:
            raise InputError(f"max_rejected_run must be at least 1, got {max_run}")
        g_out = np.inf if outlier is None else chi2_quantile(outlier, 2)
        return cls(chi2_quantile(gate, 2), chi2_quantile(new, 2), g_out, max_run)


class _Filter:
    """The state of one run: mean and covariance in buffers of the final size, used size
    ``n``, landmark slots, and the count of consecutive rejections.

    ``jacobians`` (:func:`ekf_slam`): ``"fej"`` and ``"oc"`` take the motion Jacobian's heading
    column from the predicted positions (``prior``, the virtual robot ``r_k``); ``first``
    holds each landmark's first estimate (FEJ) or its virtual position ``λ_i`` (OC)."""

    def __init__(
        self,
        capacity: int,
        pose: Array,
        cov0: Array,
        r_cov: Array,
        gates: _Gates,
        jacobians: str,
        iterations: int = 1,
    ):
        self.jacobians = jacobians
        self.iterations = iterations
        self.prior = np.asarray(pose, dtype=np.float64).copy()  # x̂_{k|k−1} of this step
        self.first = np.zeros(capacity)  # each landmark's first estimate (FEJ) or λ_i (OC)
        self.mu = np.zeros(capacity)
        self.cov = np.zeros((capacity, capacity))
        self.mu[:3] = np.asarray(pose, dtype=np.float64)
        self.cov[:3, :3] = np.asarray(cov0, dtype=np.float64)
        self.n = 3
        self.slot_of: dict[int, int] = {}  # landmark id -> state offset
        self.ids: list[int] = []
        self.r_cov = r_cov
        self.gates = gates
        self.rejected_run = 0

    def run(
        self,
        steps: Steps,
        sig_u: Array,
        z: Array,
        ids: Array | None,
        grid: NDArray[np.int64],
        used: NDArray[np.bool_],
    ) -> tuple[NDArray[np.int64], Array, Array]:
        """Predict along ``steps`` (covariances ``sig_u``), measuring at each grid index.

        ``ids`` None: nearest-neighbour association. Returns each measurement's landmark id
        (−1: rejected or unused) and the pose and its covariance after each step.
        """
        t = steps.times
        assoc_out = np.full(z.shape[0], NO_LANDMARK, dtype=np.int64)
        online = np.empty((t.size, 3))
        online_cov = np.empty((t.size, 3, 3))
        order = np.flatnonzero(used)
        starts = np.searchsorted(grid[order], np.arange(t.size + 1))
        for k in range(t.size):
            if k > 0:
                self.predict(steps.u[k - 1], sig_u[k - 1])
            for m in order[starts[k] : starts[k + 1]]:
                lid = self.observe(z[m], None if ids is None else int(ids[m]), t[k], int(m))
                if lid is not None:
                    assoc_out[m] = lid
            online[k] = self.mu[:3]
            online_cov[k] = self.cov[:3, :3]
            if not np.isfinite(self.mu[: self.n]).all():
                raise DivergenceError(f"non-finite state at t={float(t[k]):.6f} s (step {k})")
        return assoc_out, online, online_cov

    def predict(self, u: Array, sigma: Array) -> None:
        """``x ← x ∘ u``: ``P_xx ← F P_xx Fᵀ + Q``, ``P_xm ← F P_xm``."""
        mu, cov, n = self.mu, self.cov, self.n
        fx = se2.compose_jacobian(mu[:3], u)
        q = process_noise(mu[2], sigma)
        mu[:3] = se2.compose(mu[:3], u)
        if self.jacobians != "standard":  # Φ(x̂_{k+1|k}, x̂_{k|k−1}): between predicted poses
            fx[0, 2] = -(mu[1] - self.prior[1])
            fx[1, 2] = mu[0] - self.prior[0]
        self.prior = mu[:3].copy()
        top = fx @ cov[:3, :n]
        pxx = top[:, :3] @ fx.T + q
        pxx = 0.5 * (pxx + pxx.T)  # 3×3: the covariance stays exactly symmetric
        cov[:3, :n] = top
        cov[:n, :3] = top.T
        cov[:3, :3] = pxx

    def observe(self, meas: Array, lid: int | None, t: float, m: int) -> int | None:
        """Associate (``lid`` None: nearest neighbour), then initialise or update.

        Returns the landmark id, or None when the measurement was rejected.

        OC (docs/verdict.md): the rotation about the origin, ``n_k = [J r_k; 1; J λ_1; …]``
        (``J`` the 90° rotation), stays in the null space of the linearised system when the
        motion Jacobian's heading column is ``J (r_{k+1} − r_k)``, a landmark initialised at
        step ``ℓ`` gets ``λ_i = r_ℓ + (l̂_i − p̂_ℓ)`` (the initialisation Jacobian's heading
        column), and every update's heading column is ``−H_l J (λ_i − r_k)``: the virtual
        robot ``r_k`` is the predicted position ``p̂_{k|k−1}``.
        """
        g = self.gates
        if lid is None:
            args = (self.mu, self.cov, self.n, meas, self.r_cov, g.associate, g.new_landmark)
            slot, lid = _nearest(*args, len(self.ids))
            if slot == -2:  # ambiguous: rejected
                return None
        else:
            slot = self.slot_of.get(lid)
        if slot is None or slot < 0:
            _initialise(self.mu, self.cov, self.n, meas, self.r_cov)
            self.first[self.n : self.n + 2] = self.mu[self.n : self.n + 2]
            if self.jacobians == "oc":  # λ_i = r_ℓ + (l̂_i − p̂_ℓ)
                self.first[self.n : self.n + 2] += self.prior[:2] - self.mu[:2]
            self.slot_of[lid] = self.n
            self.ids.append(lid)
            self.n += 2
            return lid
        gate = g.outlier if self.rejected_run < g.max_rejected_run else np.inf
        # FEJ: the Jacobians at the step's predicted pose and the landmark's first estimate
        first = self.first[slot : slot + 2]
        lin = (self.prior, first) if self.jacobians == "fej" else None
        v = first - self.prior[:2] if self.jacobians == "oc" else None  # OC: λ_i − r_k
        mu, cov, n, r, it = self.mu, self.cov, self.n, self.r_cov, self.iterations
        if not _update(mu, cov, n, slot, meas, r, t, m, gate, lin, v, it):
            self.rejected_run += 1
            return None  # outside the validation gate: rejected
        self.rejected_run = 0
        return lid


def corrupt_associations(
    landmarks: Array, used: NDArray[np.bool_], fraction: float, *, seed: int
) -> NDArray[np.float64]:
    """Replace a seeded share of the known associations by another landmark id (experiments).

    Given the true ids as ``true_ids``, :func:`ekf_slam` records the replaced ones as wrong.

    Parameters
    ----------
    landmarks : ndarray, shape (J,)
        Landmark id of each measurement (finite wherever ``used``).
    used : ndarray of bool, shape (J,)
        Measurements the filter uses (only these are candidates).
    fraction : float
        In ``[0, 1)``: each used measurement is corrupted with this probability; the new id
        is drawn from the used ids and always differs from the old one (unless there is
        only one landmark).
    seed : int

    Returns
    -------
    ndarray, shape (J,)
        The ids to give :func:`ekf_slam`.
    """
    _check_fraction(fraction)
    ids = np.asarray(landmarks, dtype=np.float64).copy()
    if fraction == 0 or not np.isfinite(ids[used]).all():
        return ids  # nothing to do, or ekf_slam's input error
    rng = np.random.default_rng(seed)
    pool = np.unique(ids[used])
    pick = used & (rng.random(ids.shape[0]) < fraction)
    other = pool[rng.integers(0, pool.size, pick.sum())]
    same = other == ids[pick]
    other[same] = pool[(np.searchsorted(pool, other[same]) + 1) % pool.size]
    ids[pick] = other
    return ids


def _check_fraction(fraction: float) -> None:
    if not (0.0 <= fraction < 1.0):
        raise InputError(f"corrupt_fraction must be in [0, 1), got {fraction}")


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
    lin: tuple[Array, Array] | None = None,
    heading_from: Array | None = None,
    iterations: int = 1,
) -> bool:
    """EKF update with one range-bearing measurement; False (no update) when ``νᵀS⁻¹ν > gate``.

    ``iterations`` > 1 (not with ``lin``): the iterated EKF update — the gate is decided at
    the prior as above, then the update is relinearised at the Gauss–Newton iterate of the
    local MAP problem (:func:`_iterate`), ``ν = z − h(x_i) − H_i (x̂ − x_i)``.

    ``lin``: the pose and landmark the Jacobians are evaluated at (FEJ; default the current
    estimates); the innovation is always against the current estimates. ``heading_from``
    (OC): the landmark-minus-robot vector ``v`` the heading column ``−H_l J v`` is taken at,
    every other column at the current estimates.

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
    hx, hl, nu = _linearised(mu[:3], mu[slot : slot + 2], meas, heading_from)
    if lin is not None:
        _, hx, hl = range_bearing(*lin)
    if iterations > 1 and lin is None:
        local = np.array([0, 1, 2, slot, slot + 1])
        x0 = mu[local]
        p5 = cov[np.ix_(local, local)]
        if gate < np.inf:  # the gate is the plain update's, at the prior
            h5 = np.hstack((hx, hl))
            if float(nu @ np.linalg.solve(h5 @ p5 @ h5.T + r_cov, nu)) > gate:
                return False
            gate = np.inf
        xi = _iterate(x0, p5, meas, r_cov, heading_from, iterations)
        hx, hl, nu = _linearised(xi[:3], xi[3:], meas, heading_from, x0)
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


def _linearised(
    pose: Array, landmark: Array, meas: Array, heading_from: Array | None, x0: Array | None = None
) -> tuple[Array, Array, Array]:
    """``H_x``, ``H_l`` at ``pose`` (3,) and ``landmark`` (2,), and the innovation
    ``z − h`` there (bearing wrapped); with ``x0`` (5,: the prior's pose and landmark) the
    innovation of the update linearised at that point, ``z − h − H (x0 − [pose, landmark])``.
    ``heading_from`` (OC): ``H_x``'s heading column ``−H_l J v``."""
    h, hx, hl = range_bearing(pose, landmark)
    if heading_from is not None:  # −H_l J v with J v = [−v_y, v_x]
        hx = hx.copy()
        hx[:, 2] = hl @ np.array([heading_from[1], -heading_from[0]])
    nu = meas - h
    nu[1] = se2.wrap_angle(nu[1])
    if x0 is not None:
        d = x0 - np.concatenate((pose, landmark))
        d[2] = se2.wrap_angle(d[2])
        nu = nu - hx @ d[:3] - hl @ d[3:]
    return hx, hl, nu


def _iterate(
    x0: Array, p5: Array, meas: Array, r_cov: Array, heading_from: Array | None, iterations: int
) -> Array:
    """The damped Gauss–Newton iterate of one update's local MAP problem over the pose and
    the landmark (5 states, prior ``x0``, ``p5``): minimise
    ``J(x) = ‖x − x0‖²_{P⁻¹} + ‖z − h(x)‖²_{R⁻¹}`` (the iterated EKF: Bell & Cathey 1993), each
    step ``x0 + K_i ν_i − x_i`` halved until ``J`` falls (at most 10 halvings; otherwise stop),
    at most ``iterations − 1`` steps. The other states move only through their correlation
    with these five, so this is the whole problem's MAP along them."""
    p_inv = np.linalg.pinv(p5)
    r_inv = np.linalg.inv(r_cov)

    def cost(x: Array) -> float:
        e = meas - range_bearing(x[:3], x[3:])[0]
        e[1] = se2.wrap_angle(e[1])
        d = x - x0
        d[2] = se2.wrap_angle(d[2])
        return float(d @ p_inv @ d + e @ r_inv @ e)

    xi = x0.copy()
    c_i = cost(xi)
    for _ in range(iterations - 1):
        hx, hl, nu = _linearised(xi[:3], xi[3:], meas, heading_from, x0)
        h = np.hstack((hx, hl))
        ph = p5 @ h.T
        step = x0 + ph @ np.linalg.solve(h @ ph + r_cov, nu) - xi
        a = 1.0
        while (c_new := cost(xi + a * step)) >= c_i and a > 1e-3:
            a *= 0.5
        if c_new >= c_i:
            break
        xi, c_i = xi + a * step, c_new
        if float(np.abs(a * step).max()) < 1e-10:
            break
    return xi


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
    # a landmark at the robot's very position (rounding at coordinates far from the origin):
    # no range or bearing is defined, so no measurement can be it (distance inf below)
    at_robot = qd == 0.0
    qd = np.where(at_robot, 1.0, qd)
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
    d2 = np.where(at_robot, np.inf, np.einsum("ka,kab,kb->k", nu, np.linalg.inv(s), nu))
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


def _refuse_missing_ids(bundle: Bundle, used: NDArray[np.bool_]) -> None:
    """Known association: the first used measurement without a landmark id, refused at its
    line of the bundle's measurements.csv (the array-level check names no line)."""
    missing = np.flatnonzero(used & ~np.asarray(bundle.measurement_associated, dtype=bool))
    if not missing.size:
        return
    k = int(missing[0])
    lines = bundle.measurement_lines
    line = None if lines is None else int(lines[k]) or None
    raise InputError(
        f"measurement without a landmark id (unassociated; {missing.size} such in the log's "
        "time span): known association needs one for every measurement; "
        "association='nn' associates them by nearest neighbour",
        path=None if bundle.path is None else Path(bundle.path) / "measurements.csv",
        line=line,
    )


def ekf_slam_bundle(
    bundle: Bundle,
    *,
    association: Literal["known", "nn"] = "known",
    corrupt_fraction: float = 0.0,
    noise_scale: float = 1.0,
    outlier_gate: float | None = None,
    seed: int = 0,
    process_noise_scale: float = 1.0,
    jacobians: Literal["standard", "fej", "oc"] = "standard",
    iterations: int = 1,
) -> tuple[Bundle, EkfSlamResult]:
    """Run :func:`ekf_slam` on ``bundle``'s log; return the SLAM result bundle and the run.

    The returned bundle keeps the log (and ground truth) and replaces the map by the filter's
    final map with its marginals and joint covariance, and the measurements' landmark ids by
    the associations the filter made (empty where it rejected a measurement): what a
    filter-based SLAM system leaves behind, stating ``map_source="log"``. The filter's assumed
    noise is the bundle's models scaled by ``noise_scale``; the bundle records the models it
    used. ``outlier_gate`` is the χ² validation gate on known-association updates; rejected
    measurements are left unassociated in the result bundle and counted in its description.

    Experiment knobs: ``corrupt_fraction`` spoils that share of the known associations
    (seeded by ``seed``, :func:`corrupt_associations`); ``process_noise_scale`` scales the
    motion model's standard deviations only (a filter mis-tuned in its process noise;
    ``noise_scale`` scales motion and sensor alike, which leaves the filter's gains, and so
    its online estimate, unchanged); ``jacobians`` and ``iterations`` as in :func:`ekf_slam`.
    """
    mount = bundle.sensor.mount if bundle.sensor.mounted else None
    if mount is not None and (mount[0] != 0.0 or mount[1] != 0.0):
        raise InputError(
            "sensor_model.mount: slamrel's reference EKF-SLAM models a sensor at the robot's "
            "origin (turned by the mount's heading at most); expected a mount [0, 0, theta] "
            "for slamrel slam",
            path=None if bundle.path is None else Path(bundle.path) / "bundle.json",
        )
    z = bundle.measurements
    if mount is not None:  # a sensor turned by θ_m: its bearing is the robot's less θ_m
        z = z.copy()
        z[:, 1] = se2.wrap_angle(z[:, 1] + mount[2])
    bundle, white_motion = _motion_as_white(bundle)
    if process_noise_scale != 1.0:
        k2, own = process_noise_scale**2, bundle.step_covariances  # a stated C_k too
        bundle = replace(
            bundle,
            motion=_scaled(bundle.motion, process_noise_scale),
            step_covariances=None if own is None else k2 * own,
        )
    steps = build_steps(bundle)
    true_ids = np.where(bundle.measurement_associated, bundle.measurement_landmarks, -1)
    ids = np.where(bundle.measurement_associated, bundle.measurement_landmarks, np.nan)
    _check_fraction(corrupt_fraction)
    if association == "known":
        used = np.asarray(steps.measurement_grid) >= 0
        _refuse_missing_ids(bundle, used)
        ids = corrupt_associations(ids, used, corrupt_fraction, seed=seed)
    res = ekf_slam(
        steps,
        z,
        ids,
        sensor=bundle.sensor,
        initial_pose=bundle.initial_pose,
        initial_covariance=bundle.initial_covariance,
        association=association,
        true_ids=true_ids,
        noise_scale=noise_scale,
        outlier_gate=outlier_gate,
        jacobians=jacobians,
        iterations=iterations,
    )
    m = res.landmark_ids.size
    marg = res.map_covariance.reshape(m, 2, m, 2)[np.arange(m), :, np.arange(m), :]
    sensor = bundle.sensor
    if noise_scale != 1.0:
        sensor = replace(
            sensor,
            sigma_range=noise_scale * sensor.sigma_range,
            sigma_bearing=noise_scale * sensor.sigma_bearing,
        )
    rejected = int(((res.association < 0) & bundle.measurement_associated).sum())
    white = ""
    if sensor.persisting is not None:  # the reference filter's noise is white: say so
        white = (
            "; the log states a persisting measurement error, which this filter does not "
            "model: it took the noise as white of the total sigma (so does this bundle's "
            "sensor model)"
        )
        sensor = replace(sensor, persisting=None)
    own = bundle.step_covariances  # a stated per-step covariance is the filter's noise too
    out = replace(
        bundle,
        motion=_scaled(bundle.motion, noise_scale),
        step_covariances=None if own is None else noise_scale**2 * own,
        sensor=sensor,
        measurement_landmarks=np.where(res.association >= 0, res.association, 0),
        measurement_associated=res.association >= 0,
        map_ids=res.landmark_ids,
        map_xy=res.map_xy,
        map_marginals=marg,
        map_covariance=res.map_covariance,
        map_source="log",  # the map is the filter's estimate from this very log
        description=(bundle.description + "; " if bundle.description else "")
        + f"EKF-SLAM ({association} association, corrupted {corrupt_fraction:g}, "
        f"noise scale {noise_scale:g}"
        + ("" if process_noise_scale == 1.0 else f", process noise scale {process_noise_scale:g}")
        + ("" if outlier_gate is None else f", outlier gate {outlier_gate:g}: {rejected} rejected")
        + ")"
        + white
        + white_motion,
        path=None,
    )
    return out, res


#: The window [s] over which ``slamrel slam`` takes a motion persisting error as white: the
#: window ``import mrclam`` fits its white ``alpha`` over by default, so that on its bundles
#: the filter runs on the 1 s ``alpha`` it ran on before the persisting error was stated.
WHITE_MOTION_WINDOW = 1.0


def _motion_as_white(bundle: Bundle) -> tuple[Bundle, str]:
    """``bundle`` with a stated ``motion_model.persisting`` taken as white noise, and the
    sentence saying so (empty, and the bundle unchanged, when none is stated).

    The reference filter's noise is white: it adds the persisting error's α-equivalent over
    :data:`WHITE_MOTION_WINDOW` with the controls' median period
    (:meth:`~recovery.models.MotionPersisting.alpha_share`) to ``α1`` and ``α3`` and drops
    the key. Only the speed-proportional model (``alpha``) can hold it: the share is
    proportional to ``v²``; with ``sigma`` the bundle is refused."""
    motion = bundle.motion
    if motion.persisting is None:
        return bundle, ""
    where = None if bundle.path is None else Path(bundle.path) / "bundle.json"
    if motion.alpha is None:
        raise InputError(
            "motion_model.persisting: slamrel's reference EKF-SLAM takes a persisting odometry "
            "error as white speed-proportional noise; expected it with alpha (alpha1..alpha4), "
            "not sigma",
            path=where,
        )
    c = bundle.controls
    if c is None or c.shape[0] < 2:
        raise InputError(
            "motion_model.persisting: expected a control log of at least two rows",
            path=where,
        )
    period = float(np.median(np.diff(c[:, 0])))
    d1, d3 = motion.persisting.alpha_share(WHITE_MOTION_WINDOW, period)
    a1, a2, a3, a4 = motion.alpha
    alpha = (a1 + d1, a2, a3 + d3, a4)
    text = (
        "; the log states a persisting odometry error, which this filter does not model: it "
        f"took it as white over {WHITE_MOTION_WINDOW:g} s windows (alpha1 +{d1:.4g}, alpha3 "
        f"+{d3:.4g} at {period:.4g} s control rows: alpha "
        + " ".join(f"{a:.4g}" for a in alpha)
        + "; so does this bundle's motion model)"
    )
    return replace(bundle, motion=replace(motion, alpha=alpha, persisting=None)), text


def _scaled(motion: MotionModel, k: float) -> MotionModel:
    """``motion`` with its standard deviations times ``k`` (``α``, ``pose_noise`` times ``k²``)."""
    if k == 1.0:
        return motion
    return replace(
        motion,
        sigma=None if motion.sigma is None else tuple(k * s for s in motion.sigma),
        alpha=None if motion.alpha is None else tuple(k**2 * a for a in motion.alpha),
        pose_noise=None
        if motion.pose_noise is None
        else tuple(tuple(k**2 * c for c in row) for row in motion.pose_noise),
    )
