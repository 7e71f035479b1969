"""EKF localisation in a fixed landmark map, with closed-form prediction between measurements.

The recursion is the textbook EKF localisation with known correspondences (Thrun, Burgard &
Fox, *Probabilistic Robotics*, Table 7.2, generalised to any increment model
``x_{k+1} = x_k ∘ (u_k + n_k)``, ``n_k ~ N(0, Σ_k)``):

* predict ``x ← x ∘ u``, ``P ← F P Fᵀ + Rot(θ) Σ Rot(θ)ᵀ`` with the shear
  ``F = [[1, 0, −Δy], [0, 1, Δx], [0, 0, 1]]`` (``Δ`` the world-frame step);
* update with each associated range-bearing measurement, bearing innovation wrapped,
  ``S = H_x P H_xᵀ + R + H_l Σ_l H_lᵀ`` (the landmark's marginal covariance added to the
  measurement noise), optional χ² gate on ``yᵀ S⁻¹ y`` (2 dof).

With the joint map covariance the update is a Schmidt ("consider") update: the filter carries
the pose–map cross-covariance ``P_xm`` (3 × 2M), the map itself is never changed, the pose
gain is ``K = (P H_xᵀ + P_xl H_lᵀ) S⁻¹`` and ``P_xm ← P_xm − K (H_x P_xm + H_l Σ_lm)``
(Schmidt 1966; Simon, *Optimal State Estimation*, Sec. 7.4).

**Speed.** Shears compose by adding their displacements, so the prediction over all steps
between two measurement epochs is one shear plus an accumulated process noise
``Σ_m S(d_m) Q_m S(d_m)ᵀ``; expanding ``S`` makes that sum a combination of segmented
cumulative sums computed for every grid pose at once with numpy. Only the per-epoch work
(one composed prediction, the updates) runs in a Python loop, written on scalars because
numpy's per-call overhead exceeds the arithmetic on 3 × 3 matrices. The result equals the
per-step EKF (``recovery.baseline``) to rounding. The update uses
``P ← P − K S Kᵀ`` (equal to the Joseph form for the optimal gain, cheaper on scalars); the
covariance is checked to be finite and positive definite after every update.

**Divergence is a finding.** Runs of outlying innovations (NIS beyond the gate or the 99.99%
χ² bound) are where the map and the log disagree; after ``max_outlier_run`` of them the
filter is re-entered by inflating its pose covariance and goes on (:func:`run_filter`), and
every such event is returned. An optional M-estimator (Huber or Cauchy weights on the
innovation's Mahalanobis distance, iterated to the fixed point) down-weights outliers; the
plain filter (no robust weights, no event) is the textbook EKF and equals filterpy's.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from tqdm import tqdm

from relation_metric import se2
from relation_metric.arrays import Array
from relation_metric.consistency import chi2_quantile
from relation_metric.errors import DivergenceError
from relation_metric.trajectory import readonly

__all__ = [
    "USED",
    "GATED",
    "ROBUST",
    "ROBUST_DEFAULTS",
    "REENTRY",
    "EVENT_KINDS",
    "FilterEvents",
    "UNASSOCIATED",
    "OUTSIDE",
    "FilterInput",
    "FilterResult",
    "Segments",
    "prepare_segments",
    "run_filter",
]

USED, GATED, UNASSOCIATED, OUTSIDE = 0, 1, 2, 3
ROBUST = (None, "huber", "cauchy")
#: Default ``c`` of each M-estimator on the standardised distance (see ``recover``).
ROBUST_DEFAULTS = {"huber": 1.5, "cauchy": 1.5}
#: Consecutive outlying innovations after which the filter is re-entered (and a stretch of
#: disagreement between map and log is reported).
DEFAULT_MAX_OUTLIER_RUN = 10
#: Kinds of :attr:`FilterResult.events`.
REENTRY, SKIPPED_S, SKIPPED_P = 0, 1, 2
EVENT_KINDS = {
    REENTRY: "re-entered after consecutive outlying innovations",
    SKIPPED_S: "innovation covariance not positive definite (measurement skipped)",
    SKIPPED_P: "posterior covariance not positive definite (measurement skipped)",
}


@dataclass(frozen=True)
class FilterInput:
    """Everything the filter consumes, as arrays.

    Attributes
    ----------
    times : ndarray, shape (N,)
    u : ndarray, shape (N − 1, 3)
    sigma : ndarray, shape (N − 1, 3, 3)
    x0 : ndarray, shape (3,)
    p0 : ndarray, shape (3, 3)
    meas_grid : ndarray of int, shape (J,)
        Grid index of each measurement, −1 when outside the span.
    meas_z : ndarray, shape (J, 2)
    meas_landmark : ndarray of int, shape (J,)
        Row in the map, −1 when unassociated.
    map_xy : ndarray, shape (M, 2)
    map_marginals : ndarray, shape (M, 2, 2)
    map_covariance : ndarray, shape (2M, 2M) or None
        When given, the Schmidt update is used (its diagonal blocks replace the marginals).
    r : ndarray, shape (2, 2)
        Sensor noise ``diag(σ_r², σ_b²)``.
    meas_labels : list of str, optional
        How to name measurement j in messages (e.g. ``measurements.csv:17``).
    """

    times: Array
    u: Array
    sigma: Array
    x0: Array
    p0: Array
    meas_grid: NDArray[np.int64]
    meas_z: Array
    meas_landmark: NDArray[np.int64]
    map_xy: Array
    map_marginals: Array
    map_covariance: Array | None
    r: Array
    meas_labels: tuple[str, ...] | None = None

    def label(self, j: int) -> str:
        if self.meas_labels is not None:
            return self.meas_labels[j]
        return f"measurement {j}"


@dataclass(frozen=True)
class Segments:
    """Prediction quantities of every grid pose relative to the epoch before it.

    Epochs are the grid poses where measurements are processed (plus the first and last
    pose). For each pose ``k ≥ 1``, ``base[k]`` is the epoch the prediction to ``k`` starts
    from, ``local[k]`` the pose of ``k`` in the frame of that epoch's reference pose and
    ``q[k]`` the process noise accumulated from it, in the same frame.

    Attributes
    ----------
    epochs : ndarray of int, shape (E,)
    base : ndarray of int, shape (N,)
    local : ndarray, shape (N, 3)
    q : ndarray, shape (6, N)
        Unique entries ``(00, 01, 02, 11, 12, 22)`` of the accumulated process noise.
    """

    epochs: NDArray[np.int64]
    base: NDArray[np.int64]
    local: Array
    q: Array


def predict6(p: tuple, q: tuple, c, s, dx, dy) -> tuple:  # type: ignore[no-untyped-def]
    """``S(Δ) P S(Δ)ᵀ + Rot(ψ) Q Rot(ψ)ᵀ`` on the 6 unique entries ``(00, 01, 02, 11, 12, 22)``.

    ``S(Δ) = [[1, 0, −Δy], [0, 1, Δx], [0, 0, 1]]``, ``c, s = cos ψ, sin ψ``. Works on floats
    (the filter loop) and on arrays (every grid pose at once) alike.
    """
    p00, p01, p02, p11, p12, p22 = p
    q00, q01, q02, q11, q12, q22 = q
    cc, ss, cs = c * c, s * s, c * s
    return (
        p00 - 2.0 * dy * p02 + dy * dy * p22 + cc * q00 - 2.0 * cs * q01 + ss * q11,
        p01 + dx * p02 - dy * p12 - dx * dy * p22 + cs * (q00 - q11) + (cc - ss) * q01,
        p02 - dy * p22 + c * q02 - s * q12,
        p11 + 2.0 * dx * p12 + dx * dx * p22 + ss * q00 + 2.0 * cs * q01 + cc * q11,
        p12 + dx * p22 + s * q02 + c * q12,
        p22 + q22,
    )


SYM6 = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


def prepare_segments(
    sigma: Array, heading: Array, position: Array, epochs: NDArray[np.int64]
) -> Segments:
    """Composed predictions from each epoch to every later pose up to the next epoch.

    Parameters
    ----------
    sigma : ndarray, shape (N − 1, 3, 3)
        Body-frame increment covariances.
    heading : ndarray, shape (N,)
        Reference headings (unwrapped) at which the steps are linearised, up to one rotation
        per segment (dead reckoning for the filter, the solution for the batch covariance).
    position : ndarray, shape (N, 2)
        Reference positions (consecutive differences are the steps' displacements).
    epochs : ndarray of int, shape (E,)
        Sorted, starting with 0 and ending with N − 1.

    Returns
    -------
    Segments
        With ``q[k] = Σ_{m=base}^{k−1} S(d_k − d_{m+1}) Q_m S(d_k − d_{m+1})ᵀ``: writing
        ``S(d) = I + e(d) e₃ᵀ``, ``e(d) = [−d_y, d_x, 0]``, the sum expands into segmented
        cumulative sums of ``Q_m``, ``f_m Q_m e₃ᵀ`` and ``Q_m[2,2] f_m f_mᵀ``
        (``f_m = e(d_{m+1})``, positions in the epoch's frame) — 15 scalar series, no loop
        over poses.
    """
    n = heading.shape[0]
    base = np.zeros(n, dtype=np.int64)
    base[1:] = epochs[np.searchsorted(epochs, np.arange(n - 1), side="right") - 1]
    dth = heading - heading[base]
    c, s = np.cos(heading[base]), np.sin(heading[base])
    dp = position - position[base]
    local = np.column_stack((c * dp[:, 0] + s * dp[:, 1], -s * dp[:, 0] + c * dp[:, 1], dth))
    q = np.zeros((6, n))
    if n < 2:
        return Segments(epochs, base, local, q)
    a = base[1:]  # step m (pose m -> m+1) belongs to the segment of pose m + 1
    phi = heading[:-1] - heading[a]
    c, s = np.cos(phi), np.sin(phi)
    zero = np.zeros(n - 1)
    qm = predict6((zero,) * 6, tuple(sigma[:, i, j] for i, j in SYM6), c, s, zero, zero)
    f0, f1 = -local[1:, 1], local[1:, 0]
    q02, q12, q22 = qm[2], qm[4], qm[5]
    terms = np.empty((15, n - 1))
    terms[:6] = qm
    terms[6:9] = f0 * q02, f0 * q12, f0 * q22
    terms[9:12] = f1 * q02, f1 * q12, f1 * q22
    terms[12:15] = q22 * f0 * f0, q22 * f0 * f1, q22 * f1 * f1
    cs_ = np.cumsum(terms, axis=1)
    before = np.concatenate((np.zeros((15, 1)), cs_), axis=1)
    seg = cs_ - before[:, a]  # sum over m in [base, k-1] for pose k = m + 1
    a00, a01, a02, a11, a12, a22 = seg[:6]
    c00, c01, c02, c10, c11, c12 = seg[6:12]
    g00, g01, g11 = seg[12:15]
    e0, e1 = f0, f1  # e(d_k) for pose k = m + 1
    q[0, 1:] = a00 + 2 * e0 * a02 - 2 * c00 + a22 * e0 * e0 - 2 * e0 * c02 + g00
    q[1, 1:] = a01 + e0 * a12 + a02 * e1 - c01 - c10 + a22 * e0 * e1 - e0 * c12 - c02 * e1 + g01
    q[2, 1:] = a02 + e0 * a22 - c02
    q[3, 1:] = a11 + 2 * e1 * a12 - 2 * c11 + a22 * e1 * e1 - 2 * e1 * c12 + g11
    q[4, 1:] = a12 + e1 * a22 - c12
    q[5, 1:] = a22
    return Segments(epochs, base, local, q)


@dataclass(frozen=True)
class FilterEvents:
    """Where the filter had to leave the plain EKF recursion (see :func:`run_filter`).

    Attributes
    ----------
    grid : ndarray of int, shape (V,)
        Grid index of each event.
    measurement : ndarray of int, shape (V,)
        The measurement that triggered it.
    kind : ndarray of int, shape (V,)
        ``REENTRY``, ``SKIPPED_S`` or ``SKIPPED_P`` (:data:`EVENT_KINDS`).
    inflation : ndarray, shape (V,)
        The covariance inflation ``α`` of a re-entry (1 for skips).
    """

    grid: NDArray[np.int64]
    measurement: NDArray[np.int64]
    kind: NDArray[np.int64]
    inflation: Array


@dataclass(frozen=True)
class FilterResult:
    """Output of :func:`run_filter` (angles unwrapped internally; wrap for output).

    Attributes
    ----------
    poses : ndarray, shape (N, 3)
        Filtered pose at every grid time (posterior at epochs).
    covariances : ndarray, shape (N, 3, 3)
    segments : Segments
    prior_poses, prior_covariances : ndarray, shape (E, 3), (E, 3, 3)
        Predicted state at each epoch before its updates.
    post_poses, post_covariances : ndarray, shape (E, 3), (E, 3, 3)
        After its updates.
    psi : ndarray, shape (E,)
        World heading by which each segment's local frame is rotated (the epoch's posterior
        heading, or the linearisation heading).
    status : ndarray of int, shape (J,)
        ``USED``, ``GATED``, ``UNASSOCIATED`` or ``OUTSIDE`` per measurement.
    nis : ndarray, shape (J,)
        Normalised innovation squared of each measurement that reached the update (NaN else),
        against the un-weighted ``S``.
    order : ndarray of int, shape (A,)
        The measurements that reached the filter, in processing order.
    weights : ndarray, shape (J,)
        Robust weight of each measurement (1 for the plain EKF and for every inlier).
    events : FilterEvents
    outlier_bound : float
        The NIS above which a measurement counted as outlying.
    """

    poses: Array
    covariances: Array
    segments: Segments
    prior_poses: Array
    prior_covariances: Array
    post_poses: Array
    post_covariances: Array
    status: NDArray[np.int64]
    nis: Array
    psi: Array
    order: NDArray[np.int64]
    weights: Array
    events: FilterEvents
    outlier_bound: float


def _pd(p00: float, p01: float, p02: float, p11: float, p12: float, p22: float) -> bool:
    """Finite and positive definite (leading principal minors), on scalars."""
    m2 = p00 * p11 - p01 * p01
    det = (
        p00 * (p11 * p22 - p12 * p12)
        - p01 * (p01 * p22 - p12 * p02)
        + p02 * (p01 * p12 - p11 * p02)
    )
    return p00 > 0.0 and m2 > 0.0 and det > 0.0 and math.isfinite(det + p22 + p00 + p11)


def run_filter(
    inp: FilterInput,
    *,
    gate: float | None = None,
    max_outlier_run: int | None = DEFAULT_MAX_OUTLIER_RUN,
    on_divergence: str = "reenter",
    robust: str | None = None,
    robust_threshold: float | None = None,
    linearize_at: Array | None = None,
    use: NDArray[np.bool_] | None = None,
    weights: Array | None = None,
    progress: bool = False,
) -> FilterResult:
    """Run EKF localisation over the whole grid.

    Parameters
    ----------
    inp : FilterInput
    gate : float, optional
        χ² probability of the innovation gate (2 dof); ``None`` uses every measurement.
    max_outlier_run : int, optional
        A measurement is *outlying* when its NIS ``yᵀ S⁻¹ y`` exceeds the gate (or the 99.99%
        χ² bound without a gate). After this many consecutive outlying measurements the map and
        the log disagree and the filter is **re-entered** (see ``on_divergence``); ``None``
        never re-enters (the plain EKF).
    on_divergence : {"reenter", "raise"}
        ``"reenter"`` (default): the re-entry rule — right after the run's last measurement,
        the pose covariance (and the Schmidt cross-covariance, by the square root) is inflated
        by ``α = max(1, median NIS of the run / outlier bound)``, the factor that would have
        brought the run's median innovation back to the bound, around the current mean
        (capped so that the position variance stays below the map's extent squared and the
        heading variance below π²); the run counter restarts, so a lasting
        disagreement inflates again every ``max_outlier_run`` outliers. A measurement whose
        innovation covariance or posterior covariance is not positive definite is skipped
        (counted as gated) and recorded. Every event is returned in :attr:`FilterResult.events`.
        ``"raise"``: :class:`DivergenceError` instead (the old behaviour).
    robust : {None, "huber", "cauchy"}
        M-estimator on the innovation's Mahalanobis distance ``d = √NIS``: the measurement's
        effective noise (sensor plus landmark) is divided by the weight ``w(d)`` —
        Huber ``min(1, c/d)``, Cauchy ``1/(1 + (d/c)²)`` for ``d > c`` — iterated to the
        fixed point ``w = w(d(w))`` (at most 8 iterations; ``d(w)`` uses the re-weighted
        ``S``). Measurements with ``d ≤ c`` are untouched, so a healthy run is the plain EKF.
    robust_threshold : float, optional
        ``c``; default ``√χ²₂(0.99) ≈ 3.03``.
    linearize_at : ndarray, shape (N, 3), optional
        Covariance-only pass linearised at these poses (the mean is not updated, no gating):
        used for the covariances of the batch solution.
    use : ndarray of bool, shape (J,), optional
        With ``linearize_at``: which measurements enter.
    weights : ndarray, shape (J,), optional
        With ``linearize_at``: robust weights of the measurements (from a filter run).
    progress : bool
        Show a tqdm bar over the epochs.

    Returns
    -------
    FilterResult

    Raises
    ------
    DivergenceError
        A non-positive-definite initial covariance; with ``on_divergence="raise"`` also
        non-finite or non-positive-definite covariances and persistent outliers; the message
        names the time and the measurement.
    """
    if on_divergence not in ("reenter", "raise"):
        raise ValueError(f"on_divergence must be 'reenter' or 'raise', got {on_divergence!r}")
    if robust not in ROBUST:
        raise ValueError(f"robust must be one of {ROBUST}, got {robust!r}")
    raise_ = on_divergence == "raise"
    if robust_threshold is not None and not (0.0 < robust_threshold < math.inf):
        raise ValueError(f"robust_threshold must be positive and finite, got {robust_threshold}")
    n = inp.times.shape[0]
    j_all = inp.meas_grid.shape[0]
    status = np.full(j_all, USED, dtype=np.int64)
    status[inp.meas_landmark < 0] = UNASSOCIATED
    status[inp.meas_grid < 0] = OUTSIDE
    if use is not None:
        status[(status == USED) & ~use] = GATED
    active = np.flatnonzero(status == USED)
    active = active[np.argsort(inp.meas_grid[active], kind="stable")]
    epochs = np.unique(np.concatenate(([0, n - 1], inp.meas_grid[active]))).astype(np.int64)

    fixed = linearize_at is not None
    if fixed:
        lin = np.asarray(linearize_at, dtype=np.float64)
        # the batch's motion factor linearised at the solution: the shear of the actual
        # displacement between consecutive poses, noise rotated by their headings
        heading = lin[:, 2].copy()
        position = lin[:, :2]
    else:
        heading = np.concatenate(([0.0], np.cumsum(inp.u[:, 2])))
        chain = se2.cumulative_compose(inp.u)
        position = chain[:, :2]
    seg = prepare_segments(inp.sigma, heading, position, epochs)

    gate_thr = chi2_quantile(gate, 2) if gate is not None else math.inf
    div_thr = gate_thr if gate is not None else chi2_quantile(0.9999, 2)
    rob_c = float(robust_threshold) if robust_threshold is not None else ROBUST_C
    rob_c2 = rob_c * rob_c if robust is not None else math.inf
    cauchy = robust == "cauchy"
    w_fixed = None if weights is None else np.asarray(weights, dtype=np.float64).tolist()
    schmidt = inp.map_covariance is not None
    mapcov = inp.map_covariance
    m = inp.map_xy.shape[0]
    if schmidt:
        assert mapcov is not None
        blocks = (
            np.stack([mapcov[2 * i : 2 * i + 2, 2 * i : 2 * i + 2] for i in range(m)])
            if m
            else np.zeros((0, 2, 2))
        )
        pxm = np.zeros((3, 2 * m))
    else:
        blocks = inp.map_marginals
        pxm = None
    lm_xy = inp.map_xy.tolist()
    # re-entry never inflates the position variance beyond the map's extent squared, nor the
    # heading variance beyond π² (a pose that uncertain is not localised at all)
    ext2 = max(float(np.ptp(inp.map_xy, axis=0).max()) if m else 0.0, 1.0) ** 2
    lm_c = blocks.reshape(-1, 4)[:, [0, 1, 3]].tolist()
    rr, rb = float(inp.r[0, 0]), float(inp.r[1, 1])
    zz = inp.meas_z.tolist()
    lmk = inp.meas_landmark.tolist()
    e_local = seg.local[epochs].tolist()
    e_q = seg.q[:, epochs].T.tolist()
    grid_of_active = inp.meas_grid[active]
    bounds = np.searchsorted(grid_of_active, epochs, side="left").tolist() + [active.shape[0]]
    active_l = active.tolist()
    lin_l = linearize_at.tolist() if fixed else None  # type: ignore[union-attr]
    times = inp.times
    nis = np.full(j_all, np.nan)
    nis_l = nis  # written per measurement
    wts = np.ones(j_all)
    wrap = se2.wrap_angle

    x, y, th = (float(v) for v in inp.x0)
    p0 = np.asarray(inp.p0, dtype=np.float64)
    p00, p01, p02, p11, p12, p22 = (
        float(p0[i, j]) for i, j in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))
    )
    if not _pd(p00, p01, p02, p11, p12, p22):
        raise DivergenceError(
            f"filter cannot start at t={float(inp.times[0]):.6f} s: the initial covariance is "
            "not finite positive definite"
        )
    pri_x: list[tuple[float, float, float]] = []
    pri_p: list[tuple[float, ...]] = []
    post_x: list[tuple[float, float, float]] = []
    post_p: list[tuple[float, ...]] = []
    outlier_run = 0
    run_start = -1
    run_nis: list[float] = []
    pending = 0.0  # covariance inflation of a re-entry, applied before the next measurement
    ev_k: list[int] = []
    ev_j: list[int] = []
    ev_kind: list[int] = []
    ev_a: list[float] = []

    cos, sin, sqrt, atan2, isfinite, PI = (
        math.cos,
        math.sin,
        math.sqrt,
        math.atan2,
        math.isfinite,
        math.pi,
    )  # fmt: skip  (local names: no attribute look-up per measurement)
    iterator = range(epochs.shape[0])
    bar = tqdm(
        iterator, desc="filter", unit="epoch", disable=not progress, file=sys.stderr, leave=False
    )
    for e in bar:
        k = int(epochs[e])
        if e > 0:
            ux, uy, uth = e_local[e]
            psi = lin_l[int(epochs[e - 1])][2] if fixed else th  # type: ignore[index]
            c = cos(psi)
            s = sin(psi)
            dx = c * ux - s * uy
            dy = s * ux + c * uy
            x += dx
            y += dy
            th += uth
            p00, p01, p02, p11, p12, p22 = predict6(
                (p00, p01, p02, p11, p12, p22), e_q[e], c, s, dx, dy
            )
            if not -math.pi <= th < math.pi:  # keep prior and posterior on one branch
                th = float(wrap(th))
            if pxm is not None:
                pxm[0] -= dy * pxm[2]
                pxm[1] += dx * pxm[2]
        pri_x.append((x, y, th))
        pri_p.append((p00, p01, p02, p11, p12, p22))
        if fixed:
            lx_, ly_, lth_ = lin_l[k]  # type: ignore[index]
        for idx in range(bounds[e], bounds[e + 1]):
            if pending:
                p00, p01, p02, p11, p12, p22 = (
                    pending * p00, pending * p01, pending * p02,
                    pending * p11, pending * p12, pending * p22,
                )  # fmt: skip
                if pxm is not None:
                    pxm *= math.sqrt(pending)
                pending = 0.0
            j = active_l[idx]
            li = lmk[j]
            lx, ly = lm_xy[li]
            ca, cb, cd = lm_c[li]
            px, py, pth = (lx_, ly_, lth_) if fixed else (x, y, th)
            ddx = lx - px
            ddy = ly - py
            qq = ddx * ddx + ddy * ddy
            r = sqrt(qq)
            h00, h01, h10, h11 = ddx / r, ddy / r, -ddy / qq, ddx / qq
            t00 = h00 * ca + h01 * cb
            t01 = h00 * cb + h01 * cd
            t10 = h10 * ca + h11 * cb
            t11 = h10 * cb + h11 * cd
            re00 = rr + t00 * h00 + t01 * h01
            re01 = t00 * h10 + t01 * h11
            re11 = rb + t10 * h10 + t11 * h11
            # P H_xᵀ, H_x = [[-h00, -h01, 0], [-h10, -h11, -1]]
            a0 = -h00 * p00 - h01 * p01
            a1 = -h00 * p01 - h01 * p11
            a2 = -h00 * p02 - h01 * p12
            b0 = -h10 * p00 - h11 * p01 - p02
            b1 = -h10 * p01 - h11 * p11 - p12
            b2 = -h10 * p02 - h11 * p12 - p22
            s00 = -h00 * a0 - h01 * a1 + re00
            s01 = -h00 * b0 - h01 * b1 + re01
            s11 = -h10 * b0 - h11 * b1 - b2 + re11
            if pxm is not None:
                pxl = pxm[:, 2 * li : 2 * li + 2]
                bm = pxl @ np.array([[h00, h10], [h01, h11]])  # P_xl H_lᵀ, 3 × 2
                (c00, c01), (c10, c11), (c20, c21) = bm.tolist()
                hb00 = -h00 * c00 - h01 * c10
                hb01 = -h00 * c01 - h01 * c11
                hb10 = -h10 * c00 - h11 * c10 - c20
                hb11 = -h10 * c01 - h11 * c11 - c21
                s00 += 2.0 * hb00
                s01 += hb01 + hb10
                s11 += 2.0 * hb11
                a0 += c00
                a1 += c10
                a2 += c20
                b0 += c01
                b1 += c11
                b2 += c21
            det = s00 * s11 - s01 * s01
            if not (det > 0.0 and s00 > 0.0):
                if raise_ or fixed:
                    _diverged(inp, times[k], j, "innovation covariance is not positive definite")
                status[j] = GATED
                ev_k.append(k), ev_j.append(j), ev_kind.append(SKIPPED_S), ev_a.append(1.0)
                continue
            i00, i01, i11 = s11 / det, -s01 / det, s00 / det
            zr, zb = zz[j]
            y0 = zr - r
            y1 = zb - atan2(ddy, ddx) + pth
            if not -PI <= y1 < PI:
                y1 = float(wrap(y1))
            v = y0 * y0 * i00 + 2.0 * y0 * y1 * i01 + y1 * y1 * i11
            nis_l[j] = v
            wj = 1.0
            if fixed:
                if w_fixed is not None:
                    wj = w_fixed[j]
            else:
                if v > div_thr:
                    if outlier_run == 0:
                        run_start = j
                    outlier_run += 1
                    run_nis.append(v)
                    if max_outlier_run is not None and outlier_run >= max_outlier_run:
                        if raise_:
                            _diverged(
                                inp,
                                times[k],
                                j,
                                f"{outlier_run} consecutive innovations beyond the χ² bound "
                                f"{div_thr:.2f} (since {inp.label(run_start)})",
                            )
                        run_nis.sort()
                        pending = min(
                            run_nis[len(run_nis) // 2] / div_thr,
                            ext2 / max(p00, p11, 1e-300),
                            math.pi * math.pi / max(p22, 1e-300),
                        )
                        pending = max(1.0, pending)
                        ev_k.append(k), ev_j.append(j), ev_kind.append(REENTRY)
                        ev_a.append(pending)
                        outlier_run = 0
                        run_nis = []
                else:
                    outlier_run = 0
                    run_nis = []
                if v > gate_thr:
                    status[j] = GATED
                    continue
                if v > rob_c2:
                    wj = _robust_weight(cauchy, rob_c, y0, y1, s00, s01, s11, re00, re01, re11)
            if wj != 1.0:
                wts[j] = wj
                f = 1.0 / wj - 1.0
                w00, w01, w11 = s00 + f * re00, s01 + f * re01, s11 + f * re11
                det = w00 * w11 - w01 * w01
                i00, i01, i11 = w11 / det, -w01 / det, w00 / det
            # K = N S⁻¹ with N = P H_xᵀ (+ P_xl H_lᵀ): columns (a*, b*)
            k00 = a0 * i00 + b0 * i01
            k01 = a0 * i01 + b0 * i11
            k10 = a1 * i00 + b1 * i01
            k11 = a1 * i01 + b1 * i11
            k20 = a2 * i00 + b2 * i01
            k21 = a2 * i01 + b2 * i11
            # P ← P − K S Kᵀ = P − N S⁻¹ Nᵀ
            n00 = p00 - (a0 * k00 + b0 * k01)
            n01 = p01 - (a0 * k10 + b0 * k11)
            n02 = p02 - (a0 * k20 + b0 * k21)
            n11 = p11 - (a1 * k10 + b1 * k11)
            n12 = p12 - (a1 * k20 + b1 * k21)
            n22 = p22 - (a2 * k20 + b2 * k21)
            # finite and positive definite (leading principal minors; _pd inlined)
            m2 = n00 * n11 - n01 * n01
            d3 = (
                n00 * (n11 * n22 - n12 * n12)
                - n01 * (n01 * n22 - n12 * n02)
                + n02 * (n01 * n12 - n11 * n02)
            )
            if not (n00 > 0.0 and m2 > 0.0 and d3 > 0.0 and isfinite(d3 + n22 + n00 + n11)):
                if raise_ or fixed:
                    _diverged(inp, times[k], j, "pose covariance is not finite positive definite")
                status[j] = GATED
                ev_k.append(k), ev_j.append(j), ev_kind.append(SKIPPED_P), ev_a.append(1.0)
                continue
            p00, p01, p02, p11, p12, p22 = n00, n01, n02, n11, n12, n22
            if not fixed:
                x += k00 * y0 + k01 * y1
                y += k10 * y0 + k11 * y1
                th += k20 * y0 + k21 * y1
            if pxm is not None:
                hx = np.array([[-h00, -h01, 0.0], [-h10, -h11, -1.0]])
                hl = np.array([[h00, h01], [h10, h11]])
                tmp = hx @ pxm + hl @ mapcov[2 * li : 2 * li + 2]  # type: ignore[index]
                pxm -= np.array([[k00, k01], [k10, k11], [k20, k21]]) @ tmp
        if pending:
            p00, p01, p02, p11, p12, p22 = (
                pending * p00, pending * p01, pending * p02,
                pending * p11, pending * p12, pending * p22,
            )  # fmt: skip
            if pxm is not None:
                pxm *= math.sqrt(pending)
            pending = 0.0
        if bounds[e + 1] == bounds[e] and not _pd(p00, p01, p02, p11, p12, p22):
            raise DivergenceError(
                f"filter diverged at t={float(times[k]):.6f} s: predicted covariance is not finite "
                "positive definite"
            )
        post_x.append((x, y, th))
        post_p.append((p00, p01, p02, p11, p12, p22))
    bar.close()

    pri_xa = np.array(pri_x)
    post_xa = np.array(post_x)
    pri_pa = _full(np.array(pri_p))
    post_pa = _full(np.array(post_p))
    psi = lin[epochs, 2] if fixed else post_xa[:, 2]
    poses, covs = fill(seg, psi, post_xa, post_pa)
    poses[epochs] = post_xa
    covs[epochs] = post_pa
    if fixed:
        poses = lin.copy()
    return FilterResult(
        poses=poses,
        covariances=covs,
        segments=seg,
        prior_poses=pri_xa,
        prior_covariances=pri_pa,
        post_poses=post_xa,
        post_covariances=post_pa,
        status=readonly(status, np.int64),
        nis=readonly(nis),
        psi=psi,
        order=readonly(active, np.int64),
        weights=readonly(wts),
        events=FilterEvents(
            grid=np.asarray(ev_k, dtype=np.int64).reshape(-1),
            measurement=np.asarray(ev_j, dtype=np.int64).reshape(-1),
            kind=np.asarray(ev_kind, dtype=np.int64).reshape(-1),
            inflation=np.asarray(ev_a, dtype=np.float64).reshape(-1),
        ),
        outlier_bound=div_thr,
    )


def _full(p6: Array) -> Array:
    out = np.empty((p6.shape[0], 3, 3))
    idx = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))
    for col, (i, j) in enumerate(idx):
        out[:, i, j] = p6[:, col]
        out[:, j, i] = p6[:, col]
    return out


def world_steps(seg: Segments, psi: Array) -> Array:
    """World-frame pose of every grid pose relative to its base epoch: ``R(ψ) local``, (N, 3)."""
    e_of = np.searchsorted(seg.epochs, seg.base)
    ps = psi[e_of]
    c, s = np.cos(ps), np.sin(ps)
    loc = seg.local
    return np.column_stack(
        (c * loc[:, 0] - s * loc[:, 1], s * loc[:, 0] + c * loc[:, 1], loc[:, 2])
    )


def fill(seg: Segments, psi: Array, post_x: Array, post_p: Array) -> tuple[Array, Array]:
    """Predicted poses and covariances of every grid pose from its base epoch's posterior.

    ``x_k = x⁺_b + [R(ψ_b) local_xy, local_θ]`` and
    ``P_k = S(Δ_k) P⁺_b S(Δ_k)ᵀ + Rot(ψ_b) q_k Rot(ψ_b)ᵀ`` (:func:`predict6`), vectorised.
    """
    e_of = np.searchsorted(seg.epochs, seg.base)
    w = world_steps(seg, psi)
    poses = post_x[e_of] + w
    pb = tuple(post_p[:, i, j][e_of] for i, j in SYM6)
    ps = psi[e_of]
    p6 = predict6(pb, tuple(seg.q), np.cos(ps), np.sin(ps), w[:, 0], w[:, 1])
    return poses, _full(np.column_stack(p6))


#: Default robust threshold ``c`` on the Mahalanobis distance: ``√χ²₂(0.99)``.
ROBUST_C = math.sqrt(chi2_quantile(0.99, 2))


def robust_weight_of_distance(cauchy: bool, c: float, d: float) -> float:
    """``w(d)``: 1 for ``d ≤ c``; Huber ``c/d`` or Cauchy-type ``(c/d)²`` beyond."""
    if d <= c:
        return 1.0
    return (c / d) ** 2 if cauchy else c / d


def _robust_weight(  # type: ignore[no-untyped-def]
    cauchy: bool, c: float, y0, y1, s00, s01, s11, re00, re01, re11
) -> float:
    """Fixed point ``w = w(d(w))``, ``d(w)² = yᵀ (S + (1/w − 1) R_eff)⁻¹ y``, on scalars.

    ``g(u) = u − log w(d(eᵘ))`` is increasing in ``u = log w`` (``d`` grows with ``w``);
    ``g(0) > 0`` and ``g(log w(d(1))) ≤ 0`` bracket the root, found by the Illinois variant of
    regula falsi to ``1e-12`` in ``u``.
    """

    def g(u: float) -> float:
        f = math.exp(-u) - 1.0
        w00, w01, w11 = s00 + f * re00, s01 + f * re01, s11 + f * re11
        d2 = (y0 * y0 * w11 - 2.0 * y0 * y1 * w01 + y1 * y1 * w00) / (w00 * w11 - w01 * w01)
        return u - math.log(robust_weight_of_distance(cauchy, c, math.sqrt(max(d2, 1e-300))))

    hi, g_hi = 0.0, g(0.0)
    if g_hi <= 0.0:
        return 1.0
    lo = hi - g_hi  # log w(d(1))
    g_lo = g(lo)
    side = 0
    for _ in range(100):
        if g_lo >= 0.0 or hi - lo <= 1e-12:
            break
        u = (lo * g_hi - hi * g_lo) / (g_hi - g_lo)
        gu = g(u)
        if gu > 0.0:
            hi, g_hi = u, gu
            if side == -1:
                g_lo *= 0.5
            side = -1
        elif gu < 0.0:
            lo, g_lo = u, gu
            if side == 1:
                g_hi *= 0.5
            side = 1
        else:
            return math.exp(u)
    return math.exp(lo if g_lo >= 0.0 else 0.5 * (lo + hi))


def _diverged(inp: FilterInput, t: float, j: int, why: str) -> None:
    raise DivergenceError(f"filter diverged at t={float(t):.6f} s ({inp.label(j)}): {why}")
