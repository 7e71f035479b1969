"""Batch MAP refinement of a recovered trajectory and its map correction (Gauss–Newton / LM).

Minimises ``½ Σ rᵀ W r + ½ ηᵀ η`` over all grid poses ``X`` (N × 3) and the map coefficients
``η`` (r,) of the landmarks ``m = m̂ + L η`` (``Σ_m = L Lᵀ``, the map uncertainty of
:mod:`recovery.map_uncertainty`; ``r = 0`` for an exact map), with

* a prior ``X₀ − x̄₀`` (angle wrapped), ``W = P₀⁻¹``;
* one motion residual per step ``between(X_k, X_{k+1}) − u_k`` (angle wrapped),
  ``W = (Σ_k + ε_k I)⁻¹`` — the increment model of :mod:`recovery.models`; ``ε_k = 1e-6
  tr(Σ_k)/3 + 1e-14`` regularises the rank-2 covariance of the velocity model (a lateral
  slip with a standard deviation of 0.1% of the model's noise);
* one range-bearing residual per measurement the filter used, ``z − h(X_k, m̂_l + L_l η)``
  (bearing wrapped), ``W = R⁻¹`` (times the filter's robust weight);
* the map prior ``½ ηᵀ η``: the map error is one draw from ``N(0, Σ_m)``, the same at every
  sighting.

**Why the map is in the state.** The map's error is fixed over the run, so the measurements
of all poses share it: their noise is ``v + H_l δm``, correlated across sightings with
covariance ``R ⊗ I + H_L Σ_m H_Lᵀ``. Generalised least squares on the poses with that
noise and this problem with ``η`` marginalised out are the same (Woodbury), so estimating
``η`` is how the map's *joint* uncertainty is used exactly — the same model as the filter's
Schmidt update (:mod:`recovery.ekf`), without its restriction to the past. A map error along a
direction the log does not see (the map's anchoring) stays at its prior and shows only in
the covariance. ``η̂`` (as ``L η̂``, :attr:`BatchResult.map_correction`) is a by-product;
the score of the recovery is that of its poses. When ``Σ_m`` is the posterior of a SLAM run on
the same log (an EKF-SLAM's map), the log's information about the map is counted twice in
this covariance (too small then); ``map_prior="deconditioned"`` gives the poses' covariance by
the law of total covariance instead, ``A⁻¹ + A⁻¹ B Σ_m Bᵀ A⁻¹``, exact for a linear model
(docs/recovery.md). The poses are the same under both: the SLAM map is already the minimiser
the prior is centred on.

**The smoother** of :func:`recovery.recover.recover` is this problem solved from the
extended RTS smoother of the filter run (which linearises along the run:
:mod:`recovery.smoother`) to its statistical resolution: Gauss–Newton steps until one lowers
χ² by less than :data:`~recovery.constants.SMOOTHER_CHI2_RESOLUTION` (one unit). For a
linear-Gaussian model one step from any start is the exact minimum, i.e. the fixed-interval
(RTS) smoother of the map-augmented state (poses plus a static map): this is that smoother in
information form, relinearised where the model is not linear. One step alone is not enough
on this nonlinear model: the second still lowers χ² markedly, and stopping after the first
leaves an error its covariance does not hold (measured on hu-complex1: benchmarks/README.md).
``method="batch"`` iterates to numerical convergence (``tolerance``). (The module is named
for that method; ``slamrel batch``, the scoring of many runs, is another thing:
``slamrel.studies.batch``.)

The minimiser is the estimation layer's :func:`~recovery.lm.levenberg_marquardt`
(Marquardt's damping ``λ diag(H)``, ×10 on a rejected step, ÷10 on an accepted one, up to
``λ = 1e12``; stop when the relative cost decrease or the largest step component falls below
``tolerance``), with two problem-specific choices:

* *nearly undamped*: ``λ`` starts at :data:`LAMBDA_INITIAL` ``= 1e-14`` and is not lowered
  below :data:`LAMBDA_MIN` ``= 1e-16``. ``diag(H)`` of a position is dominated by the stiff
  lateral-slip term, orders of magnitude above the measurement curvatures, so Marquardt's
  scaled damping is huge for the soft directions unless ``λ`` is tiny: from ``λ = 1e-6``
  with the loop's usual floor ``1e-12`` most iterations were damped steps creeping towards
  the minimum, ending in a linear tail (each step half the undamped one); the smoother's
  trajectory is a good start, so the nearly undamped Gauss–Newton steps converge in a few
  iterations, quadratically at the end (the counts: benchmarks/README.md). Should the banded
  Cholesky of the nearly undamped ``H`` fail in rounding, the step is solved again with
  ``1e-12 diag(H)`` added.
* *steps along the chain* (:meth:`Problem.retract <recovery.lm.Problem.retract>`
  is :func:`retract_chain`): the step, computed in absolute poses, moves each motion
  increment by its linear model and the trajectory is recomposed from them, so the stiff
  motion residuals land exactly on their linearisation and only the soft measurement
  residuals carry the nonlinearity. With the old damping it needed fewer iterations than
  the additive step; with the damping above both need about as many, the chain's first step
  leaving the lower cost, and no step is rejected (benchmarks/README.md).

The poses' block ``A`` of the normal equations is block tridiagonal in time order (each
measurement touches one pose), so it is assembled straight into LAPACK's band storage
(bandwidth 5) and each damped step is one banded Cholesky solve (LAPACK ``pbsv``) with
``1 + r`` right-hand sides, ``η`` eliminated by its Schur complement: O(N r) per iteration,
no fill, no ordering. The band is stored *lower* and Fortran-ordered, so ``pbsv`` factorises in
place, faster than the upper form and than ``scipy.linalg.solveh_banded`` (which copied the
C-ordered band): LAPACK's unblocked band Cholesky walks columns, contiguous in the lower form,
strided in the upper. The two forms round differently and reach the same minimum (how far
apart: benchmarks/README.md). SuperLU in the natural order and ``spsolve``'s default (COLAMD
with pivoting) are far slower (timings in benchmarks/README.md). A block
Thomas recursion would be linear too but sequential (a Python loop per pose).

Per-pose covariances are the diagonal blocks of ``H⁻¹`` at the solution: with ``H = [[A, B],
[Bᵀ, C]]`` (poses, map), ``(H⁻¹)_xx = A⁻¹ + Y S⁻¹ Yᵀ``, ``Y = A⁻¹ B``, ``S = C − Bᵀ Y``. The
diagonal blocks of ``A⁻¹`` (the map taken as exact at ``m̂ + L η̂``) come from the extended
filter/RTS covariance recursion linearised at the solution (exact for a block-tridiagonal
information matrix, and vectorised like the smoother; about as long as one filter + smoother
pass, the smoother's mean half skipped: :func:`~recovery.smoother.smoothed_covariances`); the
map's term ``Y S⁻¹ Yᵀ`` from one banded solve with ``r`` right-hand sides (``3N r`` floats of
memory). A vectorised block cyclic reduction of ``A`` itself was faster but inaccurate: the
Schur complements of the information form cancel the stiff terms, leaving covariance errors
orders of magnitude above the covariance-form recursion's (both against a sparse LU solve;
the figures in benchmarks/README.md).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import scipy.linalg
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.linalg.lapack import dpbsv

from recovery.constants import MAP_PRIORS
from recovery.ekf import FilterInput, run_filter
from recovery.lm import Linearisation, LMOptions, levenberg_marquardt, retract_poses
from recovery.map_uncertainty import block_factor, covariance_factor
from recovery.models import range_bearing
from recovery.smoother import smoothed_covariances
from relation_metric import se2
from relation_metric.arrays import Array
from relation_metric.errors import DivergenceError, InputError

__all__ = [
    "BatchResult",
    "JointState",
    "refine",
    "map_factor_of",
    "normal_equations",
    "retract_chain",
    "batch_covariances",
    "check_map_prior",
]


LAMBDA_INITIAL = 1e-14  # LM's first λ: nearly undamped (module doc)
LAMBDA_MIN = 1e-16  # and its floor
#: Dense (3N, r) arrays the joint problem holds at once at its peak: B = G L, the right-hand
#: sides and the solution A⁻¹ B of one step, and V of the covariance pass.
DENSE_COPIES = 4
#: The share of the machine's physical memory the joint problem may take.
MEMORY_SHARE = 0.5


@dataclass(frozen=True)
class BatchResult:
    """Refined poses (N, 3), covariances (N, 3, 3), iterations, costs (½ rᵀ W r + ½ ηᵀη),
    the map correction ``L η`` (M, 2) estimated with them and the poses' map loadings
    ``V`` (N, 3, r) of :meth:`_JointProblem.map_loadings` (their errors' shared part) with
    their link ``T`` (r, r) to the map's own error (:meth:`_JointProblem.map_link`);
    with the deconditioned prior, also the covariances under the independent one (the
    filter's own map model, for the filter-vs-smoother agreement)."""

    poses: Array
    covariances: Array
    iterations: int
    cost_initial: float
    cost_final: float
    map_correction: Array | None = None
    map_loadings: Array | None = None
    independent_covariances: Array | None = None
    map_link: Array | None = None


def regularised_sigma(sigma: Array) -> Array:
    """``Σ_k + ε_k I`` with ``ε_k = 1e-6 tr(Σ_k)/3 + 1e-14`` (see module doc)."""
    eps = 1e-6 * np.trace(sigma, axis1=1, axis2=2) / 3.0 + 1e-14
    return sigma + eps[:, None, None] * np.eye(3)


def _factors(  # type: ignore[no-untyped-def]
    inp: FilterInput, x: Array, used: NDArray[np.int64], robust: Array | None = None
):
    """Residuals, weights and Jacobians of all factors at ``x``, ``(rp, rm, rz, wz, h_x, k)``,
    ``(cos θ_k, sin θ_k)`` (each (N − 1,)) of the motion factors, which :func:`_band`
    reuses (``between`` written out with the same operations, so the same bits), and the
    measurements' landmark Jacobians ``H_l`` (J, 2, 2).

    ``robust`` (J,): the filter's robust weight per measurement; the measurement information
    ``(R + H_l Σ_l H_lᵀ)⁻¹`` is multiplied by it (the filter divides the same matrix by it).
    """
    rp = x[0] - inp.x0
    rp[2] = se2.wrap_angle(rp[2])
    c, s = np.cos(x[:-1, 2]), np.sin(x[:-1, 2])
    dx, dy = x[1:, 0] - x[:-1, 0], x[1:, 1] - x[:-1, 1]
    rm = np.empty_like(inp.u)  # se2.between(x[:-1], x[1:]) − u, bit for bit
    rm[:, 0] = c * dx + s * dy
    rm[:, 1] = -s * dx + c * dy
    rm[:, 2] = se2.wrap_angle(x[1:, 2] - x[:-1, 2])
    rm -= inp.u
    rm[:, 2] = se2.wrap_angle(rm[:, 2])
    k = inp.meas_grid[used]
    li = inp.meas_landmark[used]
    z_hat, h_x, h_l = range_bearing(x[k], inp.map_xy[li])
    rz = inp.meas_z[used] - z_hat
    rz[:, 1] = se2.wrap_angle(rz[:, 1])
    reff = inp.r + h_l @ inp.map_marginals[li] @ h_l.transpose(0, 2, 1)
    wz = np.linalg.inv(reff)
    if robust is not None:
        wz = wz * robust[used][:, None, None]
    return (rp, rm, rz, wz, h_x, k), (c, s), h_l


def _motion_wr(wm: Array, rm: Array) -> Array:
    """``W_k r_k`` of every motion factor, (N − 1, 3)."""
    return np.einsum("nij,nj->ni", wm, rm)


def _cost(rp: Array, wp: Array, rm: Array, wm_rm: Array, rz: Array, wz: Array) -> float:
    """``½ Σ rᵀ W r`` with the motion factors' ``W r`` given (:func:`_motion_wr`)."""
    return 0.5 * float(rp @ wp @ rp + np.sum(rm * wm_rm) + np.einsum("ni,nij,nj->", rz, wz, rz))


def _weights(
    inp: FilterInput, sigma: Array | None = None, *, regularised: Array | None = None
) -> tuple[Array, Array]:
    """Prior information (3, 3) and motion informations (N − 1, 3, 3), symmetric.

    ``regularised``: :func:`regularised_sigma` of ``sigma`` (default ``inp.sigma``) when
    already computed.
    """
    wp = np.asarray(np.linalg.inv(inp.p0 + 1e-15 * np.eye(3)), dtype=np.float64)
    if regularised is None:
        regularised = regularised_sigma(inp.sigma if sigma is None else sigma)
    wm = np.asarray(np.linalg.inv(regularised), dtype=np.float64)
    # ½ (W + Wᵀ) in place, bit for bit: the diagonal is unchanged (½ (a + a) = a exactly),
    # so only the three off-diagonal pairs are averaged (measured in benchmarks/README.md)
    for i, j in ((0, 1), (0, 2), (1, 2)):
        mean = (wm[:, i, j] + wm[:, j, i]) * 0.5
        wm[:, i, j] = mean
        wm[:, j, i] = mean
    return wp, wm


def _rotated_information(w: Array, c: Array, s: Array) -> tuple[Array, ...]:
    """Upper entries ``G00, G01, G11, G02, G12, G22`` (each (K,)) of ``G = P W Pᵀ``,
    ``P = blockdiag(R(θ), 1)``, ``c, s = cos θ, sin θ``, for symmetric ``W`` (K, 3, 3)."""
    a, b, d = w[:, 0, 0], w[:, 0, 1], w[:, 1, 1]
    e, f = w[:, 0, 2], w[:, 1, 2]
    cc, ss, cs = c * c, s * s, c * s
    return (
        cc * a - 2.0 * cs * b + ss * d,
        cs * (a - d) + (cc - ss) * b,
        ss * a + 2.0 * cs * b + cc * d,
        c * e - s * f,
        s * e + c * f,
        w[:, 2, 2],
    )


def _band(  # type: ignore[no-untyped-def]
    inp: FilterInput,
    x: Array,
    used: NDArray[np.int64],
    wp: Array,
    wm: Array,
    robust: Array | None = None,
    factors: tuple[Any, ...] | None = None,
    wm_rm: Array | None = None,
):
    """``H = Jᵀ W J`` in LAPACK lower band storage, the gradient ``Jᵀ W r`` (3N,), the cost.

    ``factors``: :func:`_factors` at ``x`` when already computed; ``wm_rm`` (N − 1, 3):
    ``W r`` of the motion factors when already computed (by :func:`_cost`).

    ``H`` is block tridiagonal with 3 × 3 blocks, so its bandwidth is 5: returned as ``ab``
    (6, 3N), Fortran-ordered (what LAPACK reads, so ``pbsv`` copies nothing), with
    ``ab[i − j, j] = H[i, j]`` for ``i ≥ j`` (the lower form of
    :func:`scipy.linalg.solveh_banded`).

    The motion Jacobians of ``between(x_k, x_{k+1})`` are ``J_b = blockdiag(R_kᵀ, 1)`` and
    ``J_a = −J_b K`` with the shear ``K = I + u e₃ᵀ``, ``u = [−Δy, Δx, 0]``
    (``Δ = t_{k+1} − t_k``). With ``G = J_bᵀ W J_b`` (the information rotated into the
    world frame): ``H_{k+1,k+1} += G``, ``H_kk += Kᵀ G K``, ``H_{k,k+1} = −Kᵀ G``, written out
    entry by entry on (N,) arrays: these ~40 element-wise operations cost less than two
    batched 3 × 3 matrix products (measured in benchmarks/README.md).
    """
    n = x.shape[0]
    (rp, rm, rz, wz, h_x, k), (c, s), _ = factors or _factors(inp, x, used, robust)
    u0, u1 = x[:-1, 1] - x[1:, 1], x[1:, 0] - x[:-1, 0]
    g00, g01, g11, g02, g12, g22 = _rotated_information(wm, c, s)
    gu0, gu1, gu2 = g00 * u0 + g01 * u1, g01 * u0 + g11 * u1, g02 * u0 + g12 * u1  # G u
    k02, k12 = g02 + gu0, g12 + gu1  # Kᵀ G K: G with G u added to its last row and column
    k22 = g22 + gu2 + u0 * k02 + u1 * k12
    jzt_w = -h_x.transpose(0, 2, 1) @ wz
    hz = jzt_w @ -h_x  # each measurement's block of H_kk
    band = np.zeros((n, 3, 6))  # band[k, a, d] = H[3k + a + d, 3k + a] = ab[d, 3k + a]
    for (a, b), here, after in (
        ((0, 0), g00, g00),
        ((0, 1), g01, g01),
        ((1, 1), g11, g11),
        ((0, 2), k02, g02),
        ((1, 2), k12, g12),
        ((2, 2), k22, g22),
    ):
        # H[3k + b, 3k + a] = H[3k + a, 3k + b], a ≤ b: prior and measurements, then motion
        col = np.zeros(n)  # summed contiguously, written to the band once
        col[0] += wp[a, b]
        np.add.at(col, k, hz[:, a, b])
        col[:-1] += here
        col[1:] += after
        band[:, a, b - a] = col
    # H_{k+1,k} = H_{k,k+1}ᵀ, H_{k,k+1} = −Kᵀ G (G with G u added to its last row):
    # H[3k + 3 + b, 3k + a] = H_{k,k+1}[a, b] at band[k, a, 3 + b − a]
    for (a, b), val in (
        ((0, 0), g00),
        ((0, 1), g01),
        ((0, 2), g02),
        ((1, 0), g01),
        ((1, 1), g11),
        ((1, 2), g12),
        ((2, 0), k02),
        ((2, 1), k12),
        ((2, 2), g22 + gu2),
    ):
        np.negative(val, out=band[:-1, a, 3 + b - a])
    if wm_rm is None:
        wm_rm = _motion_wr(wm, rm)
    v0 = c * wm_rm[:, 0] - s * wm_rm[:, 1]  # v = J_bᵀ W r
    v1 = s * wm_rm[:, 0] + c * wm_rm[:, 1]
    g = np.zeros((n, 3))
    g[0] += wp @ rp
    g[1:, 0] += v0
    g[1:, 1] += v1
    g[1:, 2] += wm_rm[:, 2]
    g[:-1, 0] -= v0  # J_aᵀ W r = −Kᵀ v
    g[:-1, 1] -= v1
    g[:-1, 2] -= wm_rm[:, 2] + u0 * v0 + u1 * v1
    np.add.at(g, k, np.einsum("nij,nj->ni", jzt_w, rz))
    cost = _cost(rp, wp, rm, wm_rm, rz, wz)
    return band.reshape(3 * n, 6).T, g.ravel(), cost


def normal_equations(
    inp: FilterInput,
    x: Array,
    used: NDArray[np.int64],
    sigma: Array | None = None,
    robust: Array | None = None,
):  # type: ignore[no-untyped-def]
    """Sparse ``H = Jᵀ W J`` (3N × 3N), gradient ``g = Jᵀ W r`` (3N,) and the cost at ``x``."""
    wp, wm = _weights(inp, sigma)
    ab, g, cost = _band(inp, x, used, wp, wm, robust)
    size = ab.shape[1]
    lower = sp.dia_array((np.ascontiguousarray(ab), -np.arange(6)), shape=(size, size))
    h = (lower + lower.T - sp.diags_array(ab[0])).tocsc()
    return h, g, cost, (wp, wm)


class _BatchProblem:
    """The batch objective as a :class:`~recovery.lm.Problem` on poses (N, 3).

    ``H`` is kept in band storage (:func:`_band`) and the damped normal equations are
    solved by a banded Cholesky (LAPACK ``pbsv``): O(N) for the block-tridiagonal ``H``.
    ``chain``: steps are applied along the chain (:func:`retract_chain`); False adds them to
    the poses (:func:`~recovery.lm.retract_poses`, the step before the chain; tests).
    ``regularised``: :func:`regularised_sigma` of ``inp.sigma`` when already computed.
    """

    def __init__(
        self,
        inp: FilterInput,
        used: NDArray[np.int64],
        robust: Array | None,
        *,
        chain: bool = True,
        regularised: Array | None = None,
    ) -> None:
        self.inp, self.used, self.robust, self.chain = inp, used, robust, chain
        self.wp, self.wm = _weights(inp, regularised=regularised)
        self._trial: tuple[Any, ...] | None = None  # last cost()'s x, factors and W r

    def linearise(self, x: Array) -> Linearisation:
        # an accepted trial is linearised next: reuse the residuals its cost computed
        res, wm_rm = None, None
        if self._trial is not None and self._trial[0] is x:
            res, wm_rm = self._trial[1:]
        ab, g, cost = _band(self.inp, x, self.used, self.wp, self.wm, self.robust, res, wm_rm)
        return Linearisation(cost, g, ab[0], ab)

    def cost(self, x: Array) -> float:
        res = _factors(self.inp, x, self.used, self.robust)
        rp, rm, rz, wz, _, _ = res[0]
        wm_rm = _motion_wr(self.wm, rm)
        self._trial = (x, res, wm_rm)
        return _cost(rp, self.wp, rm, wm_rm, rz, wz)

    def solve(self, lin: Linearisation, damping: Array) -> Array:
        # λ runs down to 1e-16: should the factorisation of the nearly undamped H fail in
        # rounding, retry once with the damping floor of the shared loop (1e-12 diag H)
        for floor in (0.0, 1e-12):
            ab = lin.system.copy(order="F")
            ab[0] += np.maximum(damping, floor * lin.diagonal)
            try:
                return _cholesky_solve(ab, -lin.gradient)
            except np.linalg.LinAlgError:
                pass
        raise DivergenceError(
            "batch refinement: the normal equations are singular (not positive definite)"
        )

    def retract(self, x: Array, delta: Array) -> Array:
        return retract_chain(x, delta) if self.chain else retract_poses(x, delta)


def _cholesky_solve(ab: Array, rhs: Array) -> Array:
    """``H⁻¹ rhs`` for ``H`` in lower band storage ``ab`` (6, 3N), Fortran-ordered: LAPACK
    ``pbsv`` in place (overwrites ``ab`` and ``rhs``; :func:`scipy.linalg.solveh_banded`
    without its checks and copies). Raises ``LinAlgError`` if ``H`` is not positive definite."""
    _, x, info = dpbsv(ab, rhs, lower=1, overwrite_ab=1, overwrite_b=1)
    if info > 0:
        raise np.linalg.LinAlgError(f"leading minor {int(info)} is not positive definite")
    if info < 0:
        raise ValueError(f"illegal value in argument {-int(info)} of pbsv")
    return np.asarray(x, dtype=np.float64)


def retract_chain(x: Array, delta: Array) -> Array:
    """``x ⊞ δ`` along the chain: each motion increment moves by its linear model.

    The step ``δ`` is the Gauss–Newton step in absolute pose coordinates. Instead of adding it
    to every pose, it is mapped to the increments ``d_k = between(x_k, x_{k+1})`` by the motion
    Jacobians, ``δd_k = J_a δx_k + J_b δx_{k+1}``, and the trajectory is recomposed:
    ``x'_0 = x_0 + δx_0``, ``x'_{k+1} = x'_k ∘ (d_k + δd_k)``. So
    ``between(x'_k, x'_{k+1}) = d_k + δd_k`` exactly — the motion residuals land on their
    linear model — and to first order ``x' = x + δ`` (the same step).

    Written as corrections to ``x`` (no recomposition from scratch, so ``δ = 0`` returns
    ``x`` bit for bit and rounding does not accumulate along 10⁵ poses): with ``φ_k = δθ_k``,
    ``Δ_k = t_{k+1} − t_k`` and ``w_k = δt_{k+1} − δt_k − φ_k [−Δ_{k,y}, Δ_{k,x}]``
    (``R(θ_k) δd_k``'s translation), the headings are ``θ'_k = θ_k + φ_k`` (the angle
    increments are linear already) and the positions
    ``t'_k = t_k + δt_0 + Σ_{j<k} (R(φ_j)(Δ_j + w_j) − Δ_j)`` — a cumulative sum, vectorised.

    Parameters
    ----------
    x : ndarray, shape (N, 3)
        Poses ``[x, y, θ]``.
    delta : ndarray, shape (3N,)
        Pose-major step ``[δx_0, δy_0, δθ_0, δx_1, …]``.

    Returns
    -------
    ndarray, shape (N, 3)
        A new array, ``θ`` wrapped into ``[−π, π)``.
    """
    step = delta.reshape(x.shape)
    phi = step[:, 2]
    out = np.empty_like(x)
    c, s = np.cos(phi[:-1]), np.sin(phi[:-1])
    # one coordinate at a time on contiguous (N − 1,) arrays; the same operations as on the
    # (N − 1, 2) blocks, so the same bits
    dx, dy = x[1:, 0] - x[:-1, 0], x[1:, 1] - x[:-1, 1]  # Δ
    ax = dx + (step[1:, 0] - step[:-1, 0])  # Δ + w
    ax += dy * phi[:-1]
    ay = dy + (step[1:, 1] - step[:-1, 1])
    ay -= dx * phi[:-1]
    for i, inc in ((0, (c * ax - s * ay) - dx), (1, (s * ax + c * ay) - dy)):
        out[:, i] = x[:, i] + step[0, i]
        out[1:, i] += np.cumsum(inc)
    out[:, 2] = se2.wrap_angle(x[:, 2] + phi)
    return out


@dataclass(frozen=True)
class JointState:
    """A state of the batch: poses (N, 3) and map coefficients ``η`` (r,), ``m = m̂ + L η``."""

    poses: Array
    eta: Array


class _JointProblem:
    """The batch objective over poses and the map correction, as a :class:`~recovery.lm.Problem`.

    ``½ Σ rᵀ W r`` of :class:`_BatchProblem` with the landmarks at ``m̂ + L η`` (the
    measurements weighted by ``R⁻¹``: the map's uncertainty is in ``η``, not in ``W``), plus
    the prior ``½ ηᵀ η``. The Gauss–Newton matrix is ``[[A, B], [Bᵀ, C]]``: ``A`` the band of
    the poses (:func:`_band`), ``B`` (3N × r) and ``C`` (r × r) dense; each damped step
    eliminates ``η`` by its Schur complement ``C − Bᵀ A⁻¹ B`` — one banded Cholesky of ``A``
    with ``1 + r`` right-hand sides and one r × r Cholesky: O(N r) per step.
    """

    def __init__(
        self,
        inp: FilterInput,
        used: NDArray[np.int64],
        robust: Array | None,
        factor: Array,
        *,
        regularised: Array,
    ) -> None:
        m = inp.map_xy.shape[0]
        zero = np.zeros((m, 2, 2))
        self.inp = replace(inp, map_marginals=zero, map_covariance=None)  # the map is in η
        self.used, self.robust = used, robust
        self.factor = np.asarray(factor, dtype=np.float64)
        self.rank = int(self.factor.shape[1])
        self.wp, self.wm = _weights(self.inp, regularised=regularised)
        self.n_map = m
        k = self.inp.meas_grid[used]
        self.li = self.inp.meas_landmark[used]
        # the sparsity of G = Σ_j H_xᵀ W H_l (3N × 2M): entry (a, b) of measurement j's
        # block at row 3 k_j + a, column 2 l_j + b
        a, b = np.meshgrid(np.arange(3), np.arange(2), indexing="ij")
        self.g_rows = (3 * k[:, None, None] + a).ravel()
        self.g_cols = (2 * self.li[:, None, None] + b).ravel()

    def map_inp(self, eta: Array) -> FilterInput:
        """The filter input with the landmarks at ``m̂ + L η`` (exact)."""
        if not self.rank:
            return self.inp
        shift = (self.factor @ eta).reshape(-1, 2)
        return replace(self.inp, map_xy=self.inp.map_xy + shift)

    def linearise(self, s: JointState) -> Linearisation:
        inp = self.map_inp(s.eta)
        fac = _factors(inp, s.poses, self.used, self.robust)
        ab, g, cost = _band(inp, s.poses, self.used, self.wp, self.wm, self.robust, fac)
        (_, _, rz, wz, h_x, _), _, h_l = fac
        n, r, m = s.poses.shape[0], self.rank, self.n_map
        # ∂h_j/∂η = H_l,j L_l: every product with η's r columns goes through the map's 2M
        # coordinates — B = G L, C = I + Lᵀ D L, ∂/∂η = η − Lᵀ Σ_j H_lᵀ W r — never through
        # per-measurement (J, 2, r) arrays (2J r² flops and J r memory for a dense L)
        wh = wz @ h_l  # W H_l, (J, 2, 2)
        g_map = sp.csr_matrix(
            ((h_x.transpose(0, 2, 1) @ wh).ravel(), (self.g_rows, self.g_cols)),
            shape=(3 * n, 2 * m),
        )  # duplicates (one pose, one landmark, several sightings) are summed
        d = np.zeros((m, 2, 2))
        np.add.at(d, self.li, h_l.transpose(0, 2, 1) @ wh)
        gz = np.zeros((m, 2))
        np.add.at(gz, self.li, (wh.transpose(0, 2, 1) @ rz[..., None])[..., 0])
        b = np.asarray(g_map @ self.factor)
        c = np.eye(r) + self.factor.T @ (d @ self.factor.reshape(m, 2, r)).reshape(2 * m, r)
        g_eta = s.eta - self.factor.T @ gz.reshape(-1)
        cost += 0.5 * float(s.eta @ s.eta)
        diag = np.concatenate((ab[0], np.diagonal(c)))
        return Linearisation(cost, np.concatenate((g, g_eta)), diag, (ab, b, c))

    def cost(self, s: JointState) -> float:
        inp = self.map_inp(s.eta)
        (rp, rm, rz, wz, _, _), _, _ = _factors(inp, s.poses, self.used, self.robust)
        return _cost(rp, self.wp, rm, _motion_wr(self.wm, rm), rz, wz) + 0.5 * float(s.eta @ s.eta)

    def solve(self, lin: Linearisation, damping: Array) -> Array:
        ab0, b, c = lin.system
        nx = ab0.shape[1]
        g_x, g_eta = lin.gradient[:nx], lin.gradient[nx:]
        for floor in (0.0, 1e-12):
            ab = ab0.copy(order="F")
            ab[0] += np.maximum(damping[:nx], floor * lin.diagonal[:nx])
            rhs = np.empty((nx, 1 + self.rank), order="F")
            rhs[:, 0] = g_x
            rhs[:, 1:] = b
            try:
                sol = _cholesky_solve(ab, rhs)
                if not self.rank:
                    return -sol[:, 0]
                y0, y = sol[:, 0], sol[:, 1:]
                schur = c + np.diag(damping[nx:]) - b.T @ y
                d_eta = scipy.linalg.cho_solve(
                    scipy.linalg.cho_factor(schur, lower=True), b.T @ y0 - g_eta
                )
            except np.linalg.LinAlgError:
                continue
            return np.concatenate((-y0 - y @ d_eta, d_eta))
        raise DivergenceError(
            "batch refinement: the normal equations are singular (not positive definite)"
        )

    def retract(self, s: JointState, delta: Array) -> JointState:
        nx = s.poses.size
        return JointState(retract_chain(s.poses, delta[:nx]), s.eta + delta[nx:])

    def map_covariance_term(self, s: JointState, *, deconditioned: bool = False) -> Array:
        """What the map's uncertainty adds to each pose's covariance ``(A⁻¹)_kk``, (N, 3, 3):
        ``V_k V_kᵀ`` of :meth:`map_loadings`."""
        v = self.map_loadings(s)[1 if deconditioned else 0]
        return v @ v.transpose(0, 2, 1)

    @staticmethod
    def map_link(chol: Array, *, deconditioned: bool) -> Array:
        """``T = Cov(ξ, ζ)`` (r, r): how the loadings' ``ξ`` (:meth:`map_loadings`) is tied to
        the map's own error ``m̂ − m = L ζ``, ``ζ ~ N(0, I_r)``, errors taken as estimate −
        truth, so that ``Cov(e_k, m̂ − m) = V_k T Lᵀ`` (what a fit of the map's error, its
        rigid placement say, tells about each pose's: :mod:`recovery.anchoring`).

        Deconditioned (the map is the posterior of this log): the poses given the map are
        ``x | m ~ N(μ_x − A⁻¹ B (m − m̂), A⁻¹)``, so ``e = a − Y ζ``, ``ξ = −ζ``, ``T = −I``.
        Independent (the map a prior the log adds to): the joint solution's error is
        ``H⁻¹`` times the prior's noise, ``ζ``, whose column of ``H⁻¹`` on the poses is
        ``−Y S⁻¹``; with ``V = Y R⁻ᵀ`` (``S = R Rᵀ``, ``chol`` = ``R``) ``T = −R⁻¹``.
        """
        if deconditioned:
            return -np.eye(chol.shape[0])
        return -scipy.linalg.solve_triangular(chol, np.eye(chol.shape[0]), lower=True)

    def map_loadings(self, s: JointState) -> tuple[Array, Array, Array]:
        """``V`` (N, 3, r) under each map prior, ``(independent, deconditioned)``: the poses'
        errors' share of the map's error, ``e_k = a_k + V_k ξ`` with ``ξ ~ N(0, I_r)`` the
        same for every pose, so ``Cov(e_k, e_l) = (A⁻¹)_kl + V_k V_lᵀ``, at ``s`` (undamped),
        with ``Y = A⁻¹ B`` (``−Y`` the poses' sensitivity to ``η``).

        Independent map: ``V = Y S^{-T/2}``, ``(Y S⁻¹ Yᵀ)_kk``, ``S = C − Bᵀ Y`` — the poses'
        block of ``H⁻¹``, the map's prior ``Σ_m`` and the log's information about the map
        added. Deconditioned: ``V = Y``, ``(Y Yᵀ)_kk`` — the law of total covariance
        ``Cov(X | Z) = A⁻¹ + A⁻¹ B Σ_m Bᵀ A⁻¹`` for a map whose ``Σ_m = L Lᵀ`` is already the
        posterior given this log (``η``'s prior stands for ``Cov(m | Z)``, so ``S`` is
        ``I``: the log's information about the map is not added a second time). The third
        array is ``R``, the lower Cholesky factor of ``S`` (:meth:`map_link`).
        """
        n = s.poses.shape[0]
        if not self.rank:
            return np.zeros((n, 3, 0)), np.zeros((n, 3, 0)), np.zeros((0, 0))
        ab0, b, c = self.linearise(s).system
        y = _cholesky_solve(ab0.copy(order="F"), np.asfortranarray(b))
        chol = scipy.linalg.cholesky(c - b.T @ y, lower=True)
        v = scipy.linalg.solve_triangular(chol, y.T, lower=True).T
        return v.reshape(n, 3, self.rank), y.reshape(n, 3, self.rank), chol


def map_factor_of(inp: FilterInput) -> Array:
    """``L`` (2M, r) of the map uncertainty ``inp`` carries: its joint covariance when given,
    else the block-diagonal of its marginals (:mod:`recovery.map_uncertainty`'s rule)."""
    if inp.map_covariance is not None:
        return covariance_factor(inp.map_covariance)
    return block_factor(inp.map_marginals)


def check_map_prior(map_prior: str) -> None:
    """:class:`~relation_metric.errors.InputError` for a ``map_prior`` not in
    :data:`~recovery.constants.MAP_PRIORS`."""
    if map_prior not in MAP_PRIORS:
        raise InputError(
            f"unknown map prior {map_prior!r}; expected one of {', '.join(MAP_PRIORS)}"
        )


def memory_budget() -> float:
    """Bytes the joint problem may use: :data:`MEMORY_SHARE` of the physical memory (8 GiB
    where the system does not say)."""
    try:
        total = float(os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, ValueError, OSError):
        total = 16.0 * 2**30
    return MEMORY_SHARE * total


def check_joint_size(n_poses: int, rank: int) -> None:
    """Refuse, before any work, a joint problem whose dense map terms exceed the memory budget.

    The smoother and the batch hold :data:`DENSE_COPIES` arrays of ``3N × r`` doubles (``N``
    grid poses, ``r`` the rank of the map covariance's factor, ``2M`` for ``M`` landmarks with
    a full covariance). 10⁵ control steps with 2,000 landmarks need 41 GB: the process was
    killed by the system's out-of-memory killer instead of saying so.

    Raises
    ------
    InputError
        Naming the sizes, the memory needed and the budget; the filter needs no such term.
    """
    need = 8.0 * DENSE_COPIES * 3 * n_poses * rank
    budget = memory_budget()
    if need > budget:
        raise InputError(
            f"the smoother and the batch would need {need / 2**30:.1f} GiB for the map's "
            f"uncertainty ({DENSE_COPIES} arrays of 3 x {n_poses} poses x {rank} map "
            f"directions), above the {budget / 2**30:.1f} GiB this machine allows them "
            f"({MEMORY_SHARE:.0%} of its memory); expected a shorter log or fewer landmarks, "
            "or recover with the filter alone (method filter), which holds no such arrays"
        )


def refine(
    inp: FilterInput,
    start: Array,
    *,
    used: NDArray[np.bool_],
    weights: Array | None = None,
    max_iterations: int = 50,
    tolerance: float = 1e-10,
    map_factor: Array | None = None,
    cost_tolerance: float = 0.0,
    map_prior: str = "independent",
) -> BatchResult:
    """Levenberg–Marquardt from ``start`` (N, 3) over all poses and the map correction.

    Parameters
    ----------
    inp : FilterInput
    start : ndarray, shape (N, 3)
        Initial poses (the filter's trajectory; the map correction starts at zero).
    used : ndarray of bool, shape (J,)
        Measurements that enter (those the filter used).
    weights : ndarray, shape (J,), optional
        The filter's robust weights (:attr:`recovery.ekf.FilterResult.weights`): the batch
        uses the same robust model as the filter.
    max_iterations : int
    tolerance : float
        Stop when the relative cost reduction or the largest step falls below it.
    cost_tolerance : float
        Stop after an accepted step that lowers the cost (``½ χ²``) by less than this (0:
        never): the smoother of :func:`recovery.recover.recover` stops at ``½``
        :data:`~recovery.constants.SMOOTHER_CHI2_RESOLUTION`, with ``tolerance`` 0.
    map_factor : ndarray, shape (2M, r), optional
        ``L`` with ``L Lᵀ = Σ_m`` (:class:`recovery.map_uncertainty.MapUncertainty`); by
        default from ``inp`` (:func:`map_factor_of`).
    map_prior : {"independent", "deconditioned"}
        Where the map's error comes from (:data:`~recovery.constants.MAP_PRIORS`). It
        changes the covariances only, never the poses: ``"deconditioned"`` (a map made from
        this log) takes the poses' covariance by the law of total covariance
        (:meth:`_JointProblem.map_covariance_term`).

    Returns
    -------
    BatchResult

    Raises
    ------
    InputError
        For an unknown ``map_prior``.
    """
    check_map_prior(map_prior)
    factor = map_factor_of(inp) if map_factor is None else map_factor
    check_joint_size(int(np.asarray(start).shape[0]), int(np.asarray(factor).shape[1]))
    reg = regularised_sigma(inp.sigma)  # shared by the weights and the covariance pass
    problem = _JointProblem(inp, np.flatnonzero(used), weights, factor, regularised=reg)
    options = LMOptions(
        lambda_initial=LAMBDA_INITIAL,
        lambda_min=LAMBDA_MIN,
        lambda_max=1e12,
        max_tries=100,
        max_iterations=max_iterations,
        ftol=tolerance,
        xtol=tolerance,
        atol=cost_tolerance,
    )
    s0 = JointState(np.array(start, dtype=np.float64), np.zeros(problem.rank))
    res = levenberg_marquardt(problem, s0, options)
    x = res.x.poses
    x[:, 2] = se2.wrap_angle(x[:, 2])
    state = JointState(x, res.x.eta)
    covs = batch_covariances(problem.map_inp(state.eta), x, used, weights, regularised=reg)
    independent, deconditioned, chol = problem.map_loadings(state)
    loadings = deconditioned if map_prior == "deconditioned" else independent
    link = problem.map_link(chol, deconditioned=map_prior == "deconditioned")
    filters_model = None  # the filter's own map model, when the prior is not it
    if map_prior == "deconditioned":
        filters_model = covs + independent @ independent.transpose(0, 2, 1)
    covs = covs + loadings @ loadings.transpose(0, 2, 1)
    shift = (factor @ state.eta).reshape(-1, 2) if problem.rank else np.zeros_like(inp.map_xy)
    return BatchResult(
        x,
        covs,
        res.iterations,
        float(res.costs[0]),
        float(res.costs[-1]),
        map_correction=shift,
        map_loadings=loadings,
        independent_covariances=filters_model,
        map_link=link,
    )


def batch_covariances(
    inp: FilterInput,
    x: Array,
    used: NDArray[np.bool_],
    weights: Array | None = None,
    *,
    regularised: Array | None = None,
) -> Array:
    """Diagonal blocks of ``H⁻¹`` at ``x``: filter + RTS covariance pass linearised at ``x``.

    ``regularised``: :func:`regularised_sigma` of ``inp.sigma`` when already computed. Only
    covariances are smoothed (:func:`~recovery.smoother.smoothed_covariances`).
    """
    sigma = regularised_sigma(inp.sigma) if regularised is None else regularised
    reg = replace(inp, sigma=sigma, map_covariance=None)
    fr = run_filter(reg, linearize_at=x, use=used, weights=weights, max_outlier_run=None)
    return smoothed_covariances(fr)
