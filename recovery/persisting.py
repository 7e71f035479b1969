"""Recovery with a persisting measurement error: a Gauss–Markov bias per landmark track.

A bundle may state that its range-bearing errors persist along each landmark's track
(``sensor_model.persisting``, docs/bundle.md): the measurement of landmark ``l`` at time
``t`` is ``z = h(x_t, m_l) + b_l(t) + n``, with ``n ~ N(0, R_w)`` white and ``b_l`` a
first-order Gauss–Markov process per landmark and component (range, bearing), independent
of each other and of everything else:

    b_l(t + Δ) = φ(Δ) b_l(t) + w,   φ(Δ) = exp(−Δ/τ),   w ~ N(0, σ_b² (1 − φ²)),
    b_l stationary: Var b_l = σ_b²;  R_w = R − diag(σ_b²)  (R the sensor model's total noise).

The model is linear-Gaussian in ``b``, so the exact treatment is state augmentation
(Bryson & Henrikson 1968; Simon, *Optimal State Estimation*, Sec. 7.2): the filter's state
is the pose, the map's error ``δm`` (a constant with the map's stated covariance as prior,
the independent map prior of :mod:`recovery.batch_refinement`), every landmark's bias and,
when stated, a bias ``c(t)`` common to every landmark (the same Gauss–Markov law with its
own σ and τ; ``z = h + b_l + c + n``): ``D = 3 + 2M + 2M (+ 2)``; plus, when the bundle
states the odometry's persisting error (``motion_model.persisting``), its speed scale and turn
per metre ``o`` (``+ 2``, :mod:`recovery.odometry_bias`, which also says how it moves the
poses; a bundle stating only that one has no ``b``). Between two measurement
epochs the pose follows the composed prediction of :mod:`recovery.ekf` and each bias
decays by ``φ`` with process noise ``σ_b² (1 − φ²)``; each measurement updates the whole
state with ``H = [H_x, H_l, I₂ (, I₂)]`` and ``R_w``. The Rauch–Tung–Striebel recursion of
the augmented state runs over the epochs; every grid pose between two epochs is filled in
closed form
(the bias does not move the pose, so the augmented gain of pose ``k`` towards the next
epoch ``i`` is ``[P_k S(p_i − p_k)ᵀ, S(p_k − p_e) P⁺_{e,x·} Φ_{i←e}] (P⁻_i)⁻¹``, ``e``
the epoch before ``k``, with per-epoch products only, vectorised over the poses).

With ``σ_b → 0`` the model is the white one, and the augmented filter is the Schmidt /
map-augmented EKF of :mod:`recovery.ekf` with the map estimated (the smoother's map
correction). A bundle without ``persisting`` never reaches this module.

Cost: O(E D²) per filter and smoother pass (``E`` epochs) and O(N) for the poses between
epochs; the state holds every landmark's map error and bias, so ``D`` grows with the map
(63 for MRCLAM's 15 landmarks).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from recovery.ekf import (
    NEAR_FIELD_CHI2,
    OUTSIDE,
    UNASSOCIATED,
    USED,
    FilterEvents,
    FilterInput,
    FilterResult,
    _full,
    _mahalanobis2,
    _setup,
    _slr,
    dead_reckoning_segments,
    fill,
    near_field_last,
    predict6,
)
from recovery.odometry_bias import (
    epoch_spacing,
    motion_jacobians,
    with_virtual_epochs,
    world_jacobians,
)
from relation_metric.arrays import Array
from relation_metric.consistency import OUTLIER_PROBABILITY, chi2_quantile
from relation_metric.errors import DivergenceError, InputError
from relation_metric.se2 import wrap_angle, wrap_angle_float

if TYPE_CHECKING:
    from recovery.models import MotionPersisting

__all__ = ["PersistingPass", "run_persisting", "smooth_persisting"]

_EYE2 = np.eye(2)


@dataclass(frozen=True)
class PersistingPass:
    """One augmented filter pass: the pose filter result (grid poses and their marginal
    covariances, NIS, weights, as :class:`~recovery.ekf.FilterResult`) and the augmented
    epoch states for the smoother."""

    fr: FilterResult
    prior_x: Array  # (E, D)
    prior_p: Array  # (E, D, D)
    post_x: Array
    post_p: Array
    phi: Array  # (E − 1, D − 3): the rest-of-state decay from epoch e to e + 1
    #: With an odometry bias stated (recovery.odometry_bias): ``G_k`` (N, 3, 2) of every grid
    #: pose from its base epoch's posterior heading, and the bias's offset in the state.
    motion_g: Array | None = None
    oo: int = -1


def _map_prior(inp: FilterInput) -> Array:
    """The map error's prior covariance (2M, 2M): joint, else the marginals' block diagonal."""
    if inp.map_covariance is not None:
        return np.asarray(inp.map_covariance, dtype=np.float64)
    m = inp.map_xy.shape[0]
    out = np.zeros((m, 2, m, 2))
    out[np.arange(m), :, np.arange(m), :] = inp.map_marginals
    return out.reshape(2 * m, 2 * m)


@dataclass(frozen=True)
class _Layout:
    """Where each part sits in the augmented state
    ``[pose (3), δm (nm), b (2M), c (2), o (2)]`` (``b``, ``c``, ``o`` when stated)."""

    slot: NDArray[np.int64]  # (M_map,) the state slot of each map landmark, −1: not in the log
    m: int  # landmarks in the state
    has_map: bool  # the map's error is a state (its prior is not zero)
    has_c: bool  # a common bias is stated
    nm: int  # 2M with a map error, else 0
    ob: int  # offset of the per-landmark biases
    oc: int  # offset of the common bias
    d: int  # the state's dimension
    var_b: Array  # (d − ob,) the biases' stationary variances
    tau: Array  # (2,) per-landmark time constants (range, bearing) [s]
    tau_c: Array  # (2,) the common bias's
    has_b: bool = True  # per-landmark measurement biases are stated
    oo: int = -1  # offset of the odometry bias o = [s, κ] (recovery.odometry_bias), −1: none
    tau_o: Array | None = None  # (2,) its time constants [s]

    @property
    def has_o(self) -> bool:
        return self.oo >= 0


def _layout(
    inp: FilterInput,
    active: ArrayLike,
    bias_sigma: tuple[float, float] | None,
    bias_tau: tuple[float, float] | None,
    common_sigma: tuple[float, float] | None,
    common_tau: tuple[float, float] | None,
    motion: MotionPersisting | None = None,
) -> tuple[_Layout, Array, Array]:
    """The state's layout, the white part ``R_w`` (2, 2) of the sensor's noise and the map
    error's prior (nm, nm) over the landmarks the log uses."""
    seen = np.unique(inp.meas_landmark[np.asarray(active, dtype=np.int64)])
    slot = np.full(inp.map_xy.shape[0], -1, dtype=np.int64)
    slot[seen] = np.arange(seen.size)
    m = int(seen.size)
    has_b = bias_sigma is not None
    sig_b = np.asarray(bias_sigma if has_b else (0.0, 0.0), dtype=np.float64)
    has_c = common_sigma is not None
    sig_c = np.asarray(common_sigma if has_c else (0.0, 0.0), dtype=np.float64)
    tau_c = np.asarray(common_tau if common_tau is not None else (1.0, 1.0), dtype=np.float64)
    r_w = np.diag(np.diag(np.asarray(inp.r)) - sig_b**2 - sig_c**2)
    if not (np.diag(r_w) > 0).all():
        raise DivergenceError("persisting error: its variance is not below the sensor's total")
    sel = (2 * seen[:, None] + np.arange(2)).ravel()
    smap = _map_prior(inp)[np.ix_(sel, sel)]
    has_map = bool(np.abs(smap).max() > 0.0) if m else False
    nm = 2 * m if has_map else 0
    ob = 3 + nm
    oc = ob + (2 * m if has_b else 0)
    oo = oc + (2 if has_c else 0)
    var_b = np.tile(sig_b**2, m if has_b else 0)
    if has_c:
        var_b = np.concatenate((var_b, sig_c**2))
    tau_o = None
    if motion is not None:
        # a σ of 0 (that process off) as a vanishing one: its state then stays decoupled
        sig_o = np.maximum((motion.sigma_scale, motion.sigma_turn), 1e-12)
        var_b = np.concatenate((var_b, np.square(sig_o)))
        tau_o = np.array([motion.time_constant_scale, motion.time_constant_turn])
    tau = np.asarray(bias_tau if bias_tau is not None else (1.0, 1.0), dtype=np.float64)
    d = oo + (2 if motion is not None else 0)
    lay = _Layout(
        slot, m, has_map, has_c, nm, ob, oc, d, var_b, tau, tau_c,
        has_b=has_b, oo=oo if motion is not None else -1, tau_o=tau_o,
    )  # fmt: skip
    return lay, r_w, smap


def _predict(
    x: Array, p: Array, lay: _Layout, local: Array, q: Array, dt: float, jac: Array | None = None
) -> tuple[Array, Array, Array]:
    """One step of the augmented prediction from one epoch to the next: the pose composed
    by the increment ``local`` (3,) (plus ``jac`` (3, 2) ``· o``, the odometry bias held over
    the segment: :mod:`recovery.odometry_bias`) with the step noise ``q`` (6,), each bias
    decayed by ``φ = exp(−dt/τ)``; returns ``x``, ``p`` (updated in place) and ``φ`` (d − 3,)."""
    c, s = math.cos(x[2]), math.sin(x[2])
    g = None
    if lay.has_o and jac is not None:
        o = slice(lay.oo, lay.oo + 2)
        g = jac.copy()  # G = [R(ψ) B_xy; B_θ]
        g[0], g[1] = c * jac[0] - s * jac[1], s * jac[0] + c * jac[1]
        local = local + jac @ x[o]
    ux, uy, uth = local
    dx, dy = c * ux - s * uy, s * ux + c * uy
    x[0] += dx
    x[1] += dy
    x[2] += uth
    sh = np.array([[1.0, 0.0, -dy], [0.0, 1.0, dx], [0.0, 0.0, 1.0]])
    q6 = predict6((0.0,) * 6, tuple(q), c, s, 0.0, 0.0)
    qf = _full(tuple(np.array([v]) for v in q6))[0]
    ph = np.tile(np.exp(-dt / lay.tau), lay.m if lay.has_b else 0)
    if lay.has_c:
        ph = np.concatenate((ph, np.exp(-dt / lay.tau_c)))
    if lay.has_o:
        ph = np.concatenate((ph, np.exp(-dt / np.asarray(lay.tau_o))))
    phi = np.ones(lay.d - 3)
    phi[lay.nm :] = ph
    x[lay.ob :] *= ph
    if g is None:
        p[:3, :] = sh @ p[:3, :]
        p[:, :3] = p[:, :3] @ sh.T
    else:  # F = I but its pose rows [S, 0, …, G]: F P Fᵀ, rows then columns
        p[:3, :] = sh @ p[:3, :] + g @ p[o, :]
        p[:, :3] = p[:, :3] @ sh.T + p[:, o] @ g.T
    p[3:, :] *= phi[:, None]
    p[:, 3:] *= phi[None, :]
    p[:3, :3] += qf
    idx = np.arange(lay.ob, lay.d)
    p[idx, idx] += lay.var_b * (1.0 - ph * ph)
    return x, p, phi


def _relative(
    x: Array, p: Array, lay: _Layout, map_l: Array, li: int
) -> tuple[tuple[float, float], tuple[float, float, float]]:
    """The landmark relative to the pose and its covariance (3 unique) in the augmented state
    (:func:`recovery.ekf._relative`; the map's correction in the state when it has one)."""
    ml = map_l + (x[3 + 2 * li : 5 + 2 * li] if lay.has_map else 0.0)
    c = p[:2, :2].copy()
    if lay.has_map:
        sl = slice(3 + 2 * li, 5 + 2 * li)
        c += p[sl, sl] - p[:2, sl] - p[sl, :2]
    d = (float(ml[0] - x[0]), float(ml[1] - x[1]))
    return d, (float(c[0, 0]), float(c[0, 1]), float(c[1, 1]))


def _near_m2(x: Array, p: Array, lay: _Layout, inp: FilterInput):  # type: ignore[no-untyped-def]
    """``j ↦ d̂ᵀ C⁻¹ d̂`` of measurement ``j`` at the state ``x``, ``p`` (near-field rule)."""

    def m2(j: int) -> float:
        li = int(lay.slot[inp.meas_landmark[j]])
        return _mahalanobis2(*_relative(x, p, lay, inp.map_xy[inp.meas_landmark[j]], li))

    return m2


def _update(
    x: Array, p: Array, lay: _Layout, z: Array, map_l: Array, li: int, at: Array,
    r_w: Array, c2: float, slr: tuple | None = None,  # type: ignore[type-arg]
) -> tuple[Array, Array, float, float, float]:  # fmt: skip
    """One measurement ``z`` (2,) of the landmark at ``map_l`` (2,), state slot ``li``,
    linearised at ``at`` (d,) (or statistically, ``slr``: :func:`recovery.ekf._slr`); the
    redescending weight beyond ``c2``. Returns ``x``, ``p``, the NIS, the weight and
    ``det S`` (the un-weighted innovation covariance's)."""
    ml = map_l + (at[3 + 2 * li : 5 + 2 * li] if lay.has_map else 0.0)
    ddx, ddy = ml[0] - at[0], ml[1] - at[1]
    if slr is None:
        qq = ddx * ddx + ddy * ddy
        rng = math.sqrt(qq)
        h00, h01, h10, h11 = ddx / rng, ddy / rng, -ddy / qq, ddx / qq
        bearing = math.atan2(ddy, ddx)
    else:
        (h00, h01, h10, h11), rng, bearing, (r00, r01, r11) = slr
        r_w = np.array([[r00, r01], [r01, r11]])
    bi = lay.ob + 2 * li
    y = np.array([z[0] - rng, z[1] - bearing + at[2]])
    h = np.zeros((2, lay.d))
    h[:, :3] = [[-h00, -h01, 0.0], [-h10, -h11, -1.0]]
    if lay.has_map:
        h[:, 3 + 2 * li : 5 + 2 * li] = [[h00, h01], [h10, h11]]
    if lay.has_b:
        h[:, bi : bi + 2] = _EYE2
    if lay.has_c:
        h[:, lay.oc : lay.oc + 2] = _EYE2
    # y = z − h(at) − H (x − at) (the biases enter linearly: H's I₂ blocks)
    dev = x - at
    dev[lay.ob :] = x[lay.ob :]
    y -= h @ dev
    y[1] = wrap_angle_float(y[1])
    ph_t = p @ h.T
    s_m = h @ ph_t + r_w
    s_inv = np.linalg.inv(s_m)
    v = float(y @ s_inv @ y)
    w = 1.0 if v <= c2 else c2 / v
    if w != 1.0:
        s_inv = np.linalg.inv(s_m + (1.0 / w - 1.0) * r_w)
    gain = ph_t @ s_inv
    x += gain @ y
    p -= gain @ ph_t.T
    det = float(s_m[0, 0] * s_m[1, 1] - s_m[0, 1] * s_m[1, 0])
    return x, 0.5 * (p + p.T), v, w, det


def run_persisting(
    inp: FilterInput,
    bias_sigma: tuple[float, float] | None,
    bias_tau: tuple[float, float] | None,
    *,
    robust_threshold: float | None = None,
    common_sigma: tuple[float, float] | None = None,
    common_tau: tuple[float, float] | None = None,
    linearize_at: Array | None = None,
    motion: MotionPersisting | None = None,
) -> PersistingPass:
    """The augmented EKF over the grid (module doc).

    ``inp.r`` is the total measurement noise; its white part is ``inp.r − diag(σ_b²)``.
    ``linearize_at`` (E, D): the augmented states at the epochs (a smoother's) at which the
    measurements are linearised, a pass of the iterated extended smoother (Bell 1994:
    Gauss–Newton on the measurement terms; the motion is composed as before).
    ``robust_threshold``: ``c`` of the redescending weight ``(c/d)²`` on the Mahalanobis
    distance under the augmented filter's own innovation covariance (``None``: plain EKF).
    ``bias_sigma`` ``None``: no per-landmark bias (a bundle that states only ``motion``, the
    odometry's persisting error, :mod:`recovery.odometry_bias`; it adds epochs without
    measurements where two would be further apart than its spacing).
    """
    setup = _setup(inp, None, None, None)
    jac = None
    if motion is not None:
        setup, jac = _with_motion_epochs(setup, inp, motion)
    seg = setup.seg
    epochs = np.asarray(setup.epochs, dtype=np.int64)
    active, bounds = setup.active, setup.bounds
    lay, r_w, smap = _layout(
        inp, active, bias_sigma, bias_tau, common_sigma, common_tau, motion
    )  # fmt: skip
    check_augmented_size(epochs.shape[0], lay.d)
    d, ob = lay.d, lay.ob
    lin = None if linearize_at is None else np.asarray(linearize_at, dtype=np.float64)
    x = np.zeros(d)
    x[:3] = inp.x0
    p = np.zeros((d, d))
    p[:3, :3] = inp.p0
    if lay.has_map:
        p[3:ob, 3:ob] = smap
    p[ob:, ob:] = np.diag(lay.var_b)
    times = inp.times
    n_e = epochs.shape[0]
    prior_x, post_x = np.empty((n_e, d)), np.empty((n_e, d))
    prior_p, post_p = np.empty((n_e, d, d)), np.empty((n_e, d, d))
    phi_all = np.ones((max(n_e - 1, 0), d - 3))
    c2 = math.inf if robust_threshold is None else float(robust_threshold) ** 2
    z_all, lmk = inp.meas_z, inp.meas_landmark
    nis, wts, dets = setup.nis, setup.weights, setup.det_s
    for e in range(n_e):
        k = int(epochs[e])
        if e > 0:
            dt = float(times[k] - times[epochs[e - 1]])
            jk = None if jac is None else jac[k]
            x, p, phi_all[e - 1] = _predict(x, p, lay, seg.local[k], seg.q[:, k], dt, jk)
        prior_x[e], prior_p[e] = x, p
        near: list[int] = []
        if lin is None:  # the near-field rule of recovery.ekf (_linear_first)
            near = near_field_last(active, bounds[e], bounds[e + 1], _near_m2(x, p, lay, inp))
        for j in active[bounds[e] : bounds[e + 1]]:
            li = int(lay.slot[lmk[j]])
            at = x if lin is None else lin[e]  # where h is linearised
            slr = None
            if near and j in near:
                rel = _relative(x, p, lay, inp.map_xy[lmk[j]], li)
                if _mahalanobis2(*rel) < NEAR_FIELD_CHI2:
                    slr = _slr(*rel, (float(r_w[0, 0]), float(r_w[1, 1])))
            x, p, nis[j], w, dets[j] = _update(
                x, p, lay, z_all[j], inp.map_xy[lmk[j]], li, at, r_w, c2, slr
            )  # fmt: skip
            if w != 1.0:
                wts[j] = w
        post_x[e], post_p[e] = x, p
    fr, g = _filter_result(inp, setup, epochs, prior_x, prior_p, post_x, post_p, lay, jac)
    return PersistingPass(fr, prior_x, prior_p, post_x, post_p, phi_all, g, lay.oo)


#: The (E, D, D) arrays an augmented pass and its smoother hold at once (prior, posterior,
#: the priors' inverses, the smoothed covariances).
AUGMENTED_COPIES = 4


def check_augmented_size(epochs: int, d: int) -> None:
    """Refuse, before any work, an augmented recovery whose per-epoch covariances exceed the
    memory budget (:func:`recovery.batch_refinement.memory_budget`): it holds
    :data:`AUGMENTED_COPIES` arrays of ``E × D × D`` doubles (``D = 3 + 4M (+ 2) (+ 2)`` with
    ``M`` landmarks; ``E`` the epochs, more where an odometry bias adds some).

    Raises
    ------
    InputError
        Naming the sizes, the memory needed and the budget.
    """
    from recovery.batch_refinement import MEMORY_SHARE, memory_budget

    need = 8.0 * AUGMENTED_COPIES * epochs * d * d
    budget = memory_budget()
    if need > budget:
        raise InputError(
            f"the recovery with persisting errors would need {need / 2**30:.1f} GiB "
            f"({AUGMENTED_COPIES} arrays of {epochs} epochs x {d} x {d} states), above the "
            f"{budget / 2**30:.1f} GiB this machine allows it ({MEMORY_SHARE:.0%} of its "
            "memory); expected a shorter log, fewer landmarks, or a bundle without "
            "sensor_model.persisting / motion_model.persisting (the white recovery)"
        )


def _with_motion_epochs(setup, inp: FilterInput, motion: MotionPersisting):  # type: ignore[no-untyped-def]
    """``setup`` with the epochs :func:`recovery.odometry_bias.with_virtual_epochs` adds for
    ``motion``'s time constants (segments and measurement bounds recomputed) and the motion
    Jacobians ``B_k`` (N, 3, 2) on them."""
    from dataclasses import replace

    tau = (motion.time_constant_scale, motion.time_constant_turn)
    ep = with_virtual_epochs(
        inp.times, np.asarray(setup.epochs, dtype=np.int64), epoch_spacing(tau)
    )
    seg = dead_reckoning_segments(inp.sigma, inp.u, ep)
    grid = inp.meas_grid[np.asarray(setup.active, dtype=np.int64)]
    bounds = np.searchsorted(grid, ep, side="left").tolist() + [len(setup.active)]
    out = replace(
        setup, seg=seg, epochs=ep.tolist(), bounds=bounds,
        local=seg.local[ep].tolist(), q=seg.q[:, ep].T.tolist(),
    )  # fmt: skip
    return out, motion_jacobians(seg, inp.u)


def _filter_result(  # type: ignore[no-untyped-def]
    inp: FilterInput, setup, epochs: NDArray[np.int64], prior_x: Array, prior_p: Array,
    post_x: Array, post_p: Array, lay: _Layout, jac: Array | None,
) -> tuple[FilterResult, Array | None]:  # fmt: skip
    """The pose filter result of the augmented pass: grid poses filled between the epochs,
    the epochs' own prior and posterior pose blocks, statuses, NIS and weights; with an
    odometry bias, its ``G_k`` (N, 3, 2) (the grid poses filled with it: mean ``+ G_k ô_b``,
    covariance ``+ S P_xo Gᵀ + G P_ox Sᵀ + G P_oo Gᵀ``)."""
    n_e = epochs.shape[0]
    seg, active = setup.seg, setup.active
    nis, wts = setup.nis, setup.weights
    status = setup.status
    status[(inp.meas_landmark < 0)] = UNASSOCIATED
    status[(inp.meas_grid < 0)] = OUTSIDE
    psi_e = post_x[:, 2]
    post6 = post_p[:, :3, :3].reshape(n_e, 9)[:, [0, 1, 2, 4, 5, 8]]
    g = shift = None
    if jac is not None and lay.has_o:  # the bias's mean moves every step (module doc)
        g = world_jacobians(jac, seg, psi_e)
        shift = np.einsum("kij,kj->ki", g, post_x[seg.epoch_of, lay.oo : lay.oo + 2])
    steps, poses, covs = fill(seg, psi_e, post_x[:, :3], post6, shift)
    if g is not None:
        _fill_motion(covs, steps, g, seg.epoch_of, post_p, lay.oo)
    poses[epochs] = post_x[:, :3]
    covs[epochs] = post_p[:, :3, :3]
    empty = np.zeros(0, dtype=np.int64)
    fr = FilterResult(
        poses=poses,
        covariances=covs,
        segments=seg,
        prior_poses=prior_x[:, :3].copy(),
        prior_covariances=prior_p[:, :3, :3].copy(),
        post_poses=post_x[:, :3].copy(),
        post_covariances=post_p[:, :3, :3].copy(),
        status=status,
        nis=nis,
        psi=psi_e,
        steps=steps,
        order=np.asarray(active, dtype=np.int64),
        weights=wts,
        events=FilterEvents(empty, empty, empty, np.zeros(0)),
        outlier_bound=chi2_quantile(OUTLIER_PROBABILITY, 2),
        innovation_det=setup.det_s,
    )
    assert (status[np.asarray(active, dtype=np.int64)] == USED).all()
    return fr, g


def _fill_motion(  # type: ignore[no-untyped-def]
    covs: Array, steps: Array, g: Array, e_of, post_p: Array, oo: int
) -> None:
    """The odometry bias's covariance terms of every filled grid pose, in place: those of
    ``[S_k, G_k]`` against the base epoch's pose–bias blocks (``steps``: the world steps
    from the base epoch, already moved by the bias's mean, which ``S_k`` shears by)."""
    o = slice(oo, oo + 2)
    sk = _shears(steps)
    pxo = post_p[:, :3, o][e_of]  # (N, 3, 2)
    poo = post_p[:, o, o][e_of]
    cross = sk @ pxo @ g.transpose(0, 2, 1)
    covs += cross + cross.transpose(0, 2, 1) + g @ poo @ g.transpose(0, 2, 1)


def _shears(d: Array) -> Array:
    """``S(d)`` (n, 3, 3) of world displacements ``d`` (n, ≥ 2): ``[[1, 0, −d_y], [0, 1, d_x],
    [0, 0, 1]]``, how a pose moved by ``d`` follows a turn of the pose it started from."""
    out = np.zeros((d.shape[0], 3, 3))
    out[:, 0, 0] = out[:, 1, 1] = out[:, 2, 2] = 1.0
    out[:, 0, 2], out[:, 1, 2] = -d[:, 1], d[:, 0]
    return out


def smooth_persisting(run: PersistingPass) -> tuple[Array, Array, Array]:
    """RTS smoothing of the augmented run: poses (N, 3) (wrapped), covariances (N, 3, 3) and
    the smoothed augmented states at the epochs (E, D).

    Over the epochs the augmented recursion ``C_e = P⁺_e F_eᵀ (P⁻_{e+1})⁻¹`` (with an
    odometry bias, ``F_e``'s pose rows hold its ``G`` at the next epoch); every pose between
    two epochs by the closed-form gain of the module doc (:func:`_fill_between`).
    """
    fr = run.fr
    seg, w = fr.segments, fr.steps
    ep = seg.epochs
    n_e = ep.shape[0]
    d = run.post_x.shape[1]
    xs, ps = run.post_x.copy(), run.post_p.copy()
    inv_pri = np.asarray(np.linalg.inv(run.prior_p), dtype=np.float64)
    oo = run.oo
    for e in range(n_e - 2, -1, -1):
        step = w[ep[e + 1], :2]
        f = np.eye(d)
        f[0, 2], f[1, 2] = -step[1], step[0]
        f[3:, 3:] = np.diag(run.phi[e])
        if run.motion_g is not None:
            f[:3, oo : oo + 2] = run.motion_g[ep[e + 1]]
        c = run.post_p[e] @ f.T @ inv_pri[e + 1]
        xs[e] = run.post_x[e] + c @ (xs[e + 1] - run.prior_x[e + 1])
        ps[e] = run.post_p[e] + c @ (ps[e + 1] - run.prior_p[e + 1]) @ c.T
        ps[e] = 0.5 * (ps[e] + ps[e].T)
    poses = np.array(fr.poses, dtype=np.float64)
    covs = np.array(fr.covariances, dtype=np.float64)
    poses[ep], covs[ep] = xs[:, :3], ps[:, :3, :3]
    is_epoch = np.zeros(poses.shape[0], dtype=bool)
    is_epoch[ep] = True
    k = np.flatnonzero(~is_epoch)
    if k.size:
        _fill_between(run, k, xs, ps, inv_pri, poses, covs)
    poses[:, 2] = wrap_angle(poses[:, 2])
    return poses, covs, xs


def _fill_between(
    run: PersistingPass, k: NDArray[np.int64], xs: Array, ps: Array, inv_pri: Array,
    poses: Array, covs: Array,
) -> None:  # fmt: skip
    """The smoothed grid poses ``k`` between epochs, in place: pose ``k`` after epoch ``e``
    gets ``G_k (x^s_i − x⁻_i)`` and ``G_k (P^s_i − P⁻_i) G_kᵀ`` (``i = e + 1``), with the gain
    ``G_k = Cov(x_k, X⁻_i) (P⁻_i)⁻¹``, ``Cov(x_k, X⁻_i) = [A_k, S_k P⁺_{e,x·} Φ]`` and
    ``A_k = P_k S(p_i − p_k)ᵀ``; with an odometry bias ``o`` (``G_k`` of
    :mod:`recovery.odometry_bias`) ``A_k`` gains ``Cov(x_k, o_e) (G_i − S(p_i − p_k) G_k)ᵀ``
    and the rest ``G_k P⁺_{e,o·} Φ`` — per-epoch products only, vectorised over the poses."""
    fr = run.fr
    seg, w = fr.segments, fr.steps
    ep = seg.epochs
    e_of = seg.epoch_of[k]
    i = e_of + 1
    # per epoch pair (e, e + 1): the gain's factors against the smoothed corrections at i
    u = xs[1:] - run.prior_x[1:]  # (E − 1, D)
    mm = ps[1:] - run.prior_p[1:]
    wi = inv_pri[1:]
    rest = run.post_p[:-1, :, 3:] * run.phi[:, None, :]  # P⁺_{e,·rest} Φ
    facs = [wi[:, :3, :], rest[:, :3] @ wi[:, 3:, :]]
    has_o = run.motion_g is not None
    if has_o:
        o = slice(run.oo, run.oo + 2)
        facs.append(rest[:, o] @ wi[:, 3:, :])
    wk = w[k, :2]  # p_k − p_e (world), the shear from epoch e to pose k
    to_next = w[ep[i], :2] - wk
    pk = covs[k]
    am = pk.copy()  # A_k = P_k S(p_i − p_k)ᵀ
    am[:, :, 0] -= to_next[:, 1, None] * pk[:, :, 2]
    am[:, :, 1] += to_next[:, 0, None] * pk[:, :, 2]
    sk = _shears(wk)
    lefts = [am, sk]
    if has_o:
        g = run.motion_g
        assert g is not None
        gk, gi = g[k], g[ep[i]]
        pko = sk @ run.post_p[:, :3, o][e_of] + gk @ run.post_p[:, o, o][e_of]
        ski = _shears(to_next)
        am += pko @ (gi - ski @ gk).transpose(0, 2, 1)
        lefts.append(gk)
    a = [np.einsum("eij,ej->ei", f, u) for f in facs]
    for left, av in zip(lefts, a, strict=True):
        poses[k] += np.einsum("kij,kj->ki", left, av[e_of])
    corr = np.zeros((k.size, 3, 3))
    for li, fi in zip(lefts, facs, strict=True):
        for lj, fj in zip(lefts, facs, strict=True):
            mij = (fi @ mm @ fj.transpose(0, 2, 1))[e_of]
            corr += li @ mij @ lj.transpose(0, 2, 1)
    covs[k] = pk + 0.5 * (corr + corr.transpose(0, 2, 1))
