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
numpy's per-call overhead exceeds the arithmetic on 3 × 3 matrices (angles are wrapped by
:func:`~relation_metric.se2.wrap_angle_float`, numpy's formula on one float). The result
equals the per-step EKF (``recovery.baseline``) to rounding. The update uses
``P ← P − K S Kᵀ`` (equal to the Joseph form for the optimal gain, cheaper on scalars); the
covariance is checked to be finite and positive definite after every update.

**Divergence is a finding.** Runs of outlying innovations (NIS beyond the gate or the 99.99%
χ² bound) are where the map and the log disagree; after ``max_outlier_run`` of them the
filter is re-entered by inflating its pose covariance and goes on (:func:`run_filter`), and
every such event is returned. An optional M-estimator (Huber or Cauchy weights on the
innovation's Mahalanobis distance, iterated to the fixed point, or the redescending
``(c/d)²`` at the filter's own innovation covariance) down-weights outliers; the plain filter
(no robust weights, no event) is the textbook EKF and equals filterpy's, except for
*near-field* measurements (the landmark inside the 99 % region of its prior position relative
to the pose, where range and bearing are singular): those are used after the epoch's others,
statistically linearised when still near-field (:func:`_linear_first`, :func:`_slr`).

**Pieces.** :func:`run_filter` checks its options and hands over to :func:`_setup` (status of
every measurement, epochs, composed predictions, the map as lists), :func:`_filter_loop` (per
epoch :func:`_predict`, then per measurement :func:`_innovation`, the gate / robust weight /
re-entry decision, :func:`_correct`, :func:`_schmidt_correct`, and :func:`_inflate` after a
re-entry of :class:`_ReentryRule`) and :func:`_result`. The covariance-only pass of the batch
(``linearize_at``) runs the same loop with the mean held at the given poses.
"""

from __future__ import annotations

import functools
import math
import sys
from array import array
from dataclasses import dataclass
from enum import IntEnum

import numpy as np
from numpy.typing import NDArray
from tqdm import tqdm

from recovery.constants import DEFAULT_MAX_OUTLIER_RUN, ROBUST
from relation_metric import se2
from relation_metric.arrays import Array
from relation_metric.consistency import OUTLIER_PROBABILITY, chi2_quantile
from relation_metric.errors import DivergenceError
from relation_metric.se2 import wrap_angle_float
from relation_metric.trajectory import readonly

__all__ = [
    "MeasurementStatus",
    "FilterEvent",
    "USED",
    "GATED",
    "ROBUST",
    "ROBUST_DEFAULTS",
    "REDESCENDING_C",
    "HEAVY_TAIL_C",
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


class MeasurementStatus(IntEnum):
    """What the recovery filter did with each measurement (:attr:`FilterResult.status`).

    :mod:`slamrel.backends.ekf_slam` marks an unassociated measurement with
    ``NO_LANDMARK = −1`` in its association array (a landmark row, not a status).
    """

    USED = 0
    GATED = 1  # beyond the gate, or skipped (non-positive-definite covariance)
    UNASSOCIATED = 2
    OUTSIDE = 3  # outside the span of the controls/odometry


USED, GATED, UNASSOCIATED, OUTSIDE = MeasurementStatus
#: ``c`` of the redescending default: the 99.9 % χ²(2) bound on the standardised distance,
#: ``√χ²₂(0.999) = √(−2 ln 0.001) ≈ 3.717``. A consistent filter's innovation is beyond it with
#: probability 0.1 % and the weights take ``E[1 − w] ≈ 1.4e-4`` of its information, so a clean
#: run is recovered as by the plain EKF (issue 38: within 1 % of the best ``--robust`` choice
#: on healthy runs, where ``c = 1.75`` down-weighted 22–25 % and cost 4–9 %), while wrong
#: associations, far in the tail, are still weighted down (benchmarks/robust_default.py).
REDESCENDING_C = math.sqrt(-2.0 * math.log(1.0 - 0.999))
#: ``c`` of the redescending default when the log's innovations are heavy-tailed (the plain
#: pass's tail beyond the 99.9 % bound, standardised by ``ŝ``, above its Poisson 99.99 %
#: quantile and 0.5 % of the innovations: the map–log lamp's red rule): the default before
#: issue 38, chosen on MRCLAM dataset 7, whose robot 3 it recovers 11 % better than
#: ``REDESCENDING_C`` (0.1178 vs 0.1328 m on global relations).
HEAVY_TAIL_C = 1.75
#: Default ``c`` of each M-estimator on the standardised distance (see ``recover``).
ROBUST_DEFAULTS = {"huber": 1.5, "cauchy": 1.5, "redescending": REDESCENDING_C}


class FilterEvent(IntEnum):
    """Kinds of :attr:`FilterResult.events`."""

    REENTRY = 0
    SKIPPED_S = 1
    SKIPPED_P = 2


#: A measurement is near-field when the singularity of range and bearing (the landmark on the
#: pose) lies inside the 99 % region of the prior relative position (:func:`_linear_first`).
NEAR_FIELD_CHI2 = chi2_quantile(0.99, 2)

REENTRY, SKIPPED_S, SKIPPED_P = FilterEvent
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
    epoch_of : ndarray of int, shape (N,)
        Index into ``epochs`` of ``base`` (``epochs[epoch_of] == base``).
    """

    epochs: NDArray[np.int64]
    base: NDArray[np.int64]
    local: Array
    q: Array
    epoch_of: NDArray[np.int64]


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


def _rotated_noise(sigma: Array, c: Array, s: Array, out: Array) -> None:
    """``Rot(φ) Σ Rot(φ)ᵀ`` of every step, 6 unique entries, into ``out`` (6, N − 1).

    :func:`predict6` with ``P = 0`` and ``Δ = 0``, with its zero terms dropped: adding ``+0``
    only turns ``−0`` into ``+0``, which the ``+ 0.0`` kept after each first term repeats, so
    every entry is bit for bit ``predict6``'s.
    """
    q00, q01, q02, q11, q12, q22 = (sigma[:, i, j] for i, j in SYM6)
    cc, ss, cs = c * c, s * s, c * s
    cs2q01 = 2.0 * cs * q01  # the same product in entries 00 and 11
    out[0] = (cc * q00 + 0.0) - cs2q01 + ss * q11
    out[1] = (cs * (q00 - q11) + 0.0) + (cc - ss) * q01
    out[2] = (c * q02 + 0.0) - s * q12
    out[3] = (ss * q00 + 0.0) + cs2q01 + cc * q11
    out[4] = (s * q02 + 0.0) + c * q12
    out[5] = q22 + 0.0


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
    # pose k >= 1 belongs to the segment of the last epoch before it: runs of equal bases
    runs = np.diff(epochs)
    epoch_of = np.zeros(n, dtype=np.int64)
    epoch_of[1:] = np.repeat(np.arange(epochs.shape[0] - 1), runs)
    base = epochs[epoch_of]
    dth = heading - heading[base]
    h_e = heading[epochs]
    c, s = np.cos(h_e)[epoch_of], np.sin(h_e)[epoch_of]  # = cos, sin of heading[base]
    dp = position - np.take(position, base, axis=0)  # (np.take: faster than numpy's row indexing)
    local = np.column_stack((c * dp[:, 0] + s * dp[:, 1], -s * dp[:, 0] + c * dp[:, 1], dth))
    q = np.zeros((6, n))
    if n < 2:
        return Segments(epochs, base, local, q, epoch_of)
    a = base[1:]  # step m (pose m -> m+1) belongs to the segment of pose m + 1
    phi = heading[:-1] - heading[a]
    # the 15 series; their cumulative sums go to cum[:, 1:] (cum[:, 0] = 0 before any step)
    terms = np.empty((15, n - 1))
    _rotated_noise(sigma, np.cos(phi), np.sin(phi), terms[:6])
    f0, f1 = -local[1:, 1], local[1:, 0]
    q02, q12, q22 = terms[2], terms[4], terms[5]
    np.multiply(f0, (q02, q12, q22), out=terms[6:9])
    np.multiply(f1, (q02, q12, q22), out=terms[9:12])
    g = q22 * f0
    np.multiply(g, f0, out=terms[12])
    np.multiply(g, f1, out=terms[13])
    np.multiply(q22 * f1, f1, out=terms[14])
    cum = np.empty((15, n))
    cum[:, 0] = 0.0
    np.cumsum(terms, axis=1, out=cum[:, 1:])
    # sum over m in [base, k-1] for pose k = m + 1 (the cumulative sum before each segment,
    # repeated over the segment), written over the series themselves
    seg = np.subtract(cum[:, 1:], np.repeat(cum[:, epochs[:-1]], runs, axis=1), out=terms)
    a00, a01, a02, a11, a12, a22 = seg[:6]
    c00, c01, c02, c10, c11, c12 = seg[6:12]
    g00, g01, g11 = seg[12:15]
    e0, e1 = f0, f1  # e(d_k) for pose k = m + 1
    # products used twice are formed once (the same operands, so the same bits)
    t0, t1, ae0, ae1 = 2 * e0, 2 * e1, a22 * e0, a22 * e1
    q[0, 1:] = a00 + t0 * a02 - 2 * c00 + ae0 * e0 - t0 * c02 + g00
    q[1, 1:] = a01 + e0 * a12 + a02 * e1 - c01 - c10 + ae0 * e1 - e0 * c12 - c02 * e1 + g01
    q[2, 1:] = a02 + ae0 - c02
    q[3, 1:] = a11 + t1 * a12 - 2 * c11 + ae1 * e1 - t1 * c12 + g11
    q[4, 1:] = a12 + ae1 - c12
    q[5, 1:] = a22
    return Segments(epochs, base, local, q, epoch_of)


def dead_reckoning_segments(sigma: Array, u: Array, epochs: NDArray[np.int64]) -> Segments:
    """:func:`prepare_segments` on dead reckoning (the increments ``u`` (N − 1, 3) chained
    from the origin): the filter's reference geometry."""
    heading = np.concatenate(([0.0], np.cumsum(u[:, 2])))
    position = se2.cumulative_compose(u)[:, :2]
    return prepare_segments(sigma, heading, position, epochs)


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
    steps : ndarray, shape (N, 3)
        Every grid pose relative to its base epoch in the world frame
        (:func:`world_steps` of ``segments`` and ``psi``).
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
    innovation_det : ndarray, shape (J,)
        ``det S`` of each innovation that has a ``nis`` (NaN else): with the NIS, the
        innovation's Gaussian likelihood (:mod:`recovery.clock_offset` compares it between
        runs whose ``S`` differ).
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
    steps: Array
    order: NDArray[np.int64]
    weights: Array
    events: FilterEvents
    outlier_bound: float
    innovation_det: Array


def _pd(p: tuple) -> bool:
    """Finite and positive definite (leading principal minors) on the 6 unique entries."""
    p00, p01, p02, p11, p12, p22 = p
    m2 = p00 * p11 - p01 * p01
    det = (
        p00 * (p11 * p22 - p12 * p12)
        - p01 * (p01 * p22 - p12 * p02)
        + p02 * (p01 * p12 - p11 * p02)
    )
    return p00 > 0.0 and m2 > 0.0 and det > 0.0 and math.isfinite(det + p22 + p00 + p11)


@dataclass(frozen=True)
class _Rules:
    """What one filter run does with a measurement once its NIS ``v`` is known.

    ``gate``: gated when ``v > gate``; ``outlier``: counts as outlying when ``v > outlier``;
    ``robust_c2``: robust weight when ``v > robust_c2`` (``inf``: never); ``fixed``: the
    covariance-only pass (mean not updated, no gate, no re-entry, weights given).
    """

    gate: float
    outlier: float
    robust: str | None
    robust_c: float
    robust_c2: float
    fixed: bool
    raise_: bool


class _ReentryRule:
    """The re-entry rule of :func:`run_filter`: runs of outlying innovations → inflation ``α``.

    Not to be confused with EKF-SLAM's ``max_rejected_run``
    (:func:`slamrel.backends.ekf_slam.ekf_slam`), which after a run of *gated* measurements
    *force-accepts* the next one: there the filter stops rejecting, here it stops trusting
    its own covariance. Both end a run of disagreement; only this one changes ``P``.
    """

    __slots__ = ("bound", "max_run", "raise_", "ext2", "inp", "run", "start", "nis", "reacquiring")
    nis: list[float]  # the NIS values of the current run

    def __init__(  # type: ignore[no-untyped-def]
        self, bound: float, max_run: int | None, raise_: bool, ext2: float, inp
    ) -> None:
        self.bound, self.max_run, self.raise_, self.ext2, self.inp = (
            bound, max_run, raise_, ext2, inp
        )  # fmt: skip
        self.run, self.start, self.nis = 0, -1, []
        #: after a re-entry until the first measurement within the bound: the filter, not the
        #: measurements, is suspect, so robust weights are suspended (re-acquisition)
        self.reacquiring = False

    def observe(self, v: float, p: tuple, k: int, j: int) -> float:
        """Count measurement ``j`` (NIS ``v``, prior covariance ``p``, grid index ``k``); ``α``
        or 0.

        ``α = max(1, min(median NIS of the run / bound, extent² / max(p_xx, p_yy),
        π² / p_θθ))`` after ``max_run`` consecutive outliers (then the count restarts).
        """
        if not v > self.bound:
            if self.run or self.reacquiring:  # (the common case, an inlier after inliers,
                self.run, self.nis, self.reacquiring = 0, [], False  # changes nothing)
            return 0.0
        if self.run == 0:
            self.start = j
        self.run += 1
        self.nis.append(v)
        if self.max_run is None or self.run < self.max_run:
            return 0.0
        if self.raise_:
            _diverged(
                self.inp,
                self.inp.times[k],
                j,
                f"{self.run} consecutive innovations beyond the χ² bound {self.bound:.2f} "
                f"(since {self.inp.label(self.start)})",
            )
        self.nis.sort()
        alpha = min(
            self.nis[len(self.nis) // 2] / self.bound,
            self.ext2 / max(p[0], p[3], 1e-300),
            math.pi * math.pi / max(p[5], 1e-300),
        )
        self.run, self.nis, self.reacquiring = 0, [], True
        return max(1.0, alpha)


def _predict(pose: tuple, p: tuple, pxm, local, q, psi: float):  # type: ignore[no-untyped-def]
    """Composed prediction from the previous epoch: pose, 6 covariance entries (in place
    on the Schmidt cross-covariance ``pxm``); ``psi`` rotates the segment's local frame."""
    ux, uy, uth = local
    c = math.cos(psi)
    s = math.sin(psi)
    dx = c * ux - s * uy
    dy = s * ux + c * uy
    x, y, th = pose
    th += uth
    if not -math.pi <= th < math.pi:  # keep prior and posterior on one branch
        th = wrap_angle_float(th)
    if pxm is not None:
        pxm[0] -= dy * pxm[2]
        pxm[1] += dx * pxm[2]
    return (x + dx, y + dy, th), predict6(p, q, c, s, dx, dy)


def _relative(  # type: ignore[no-untyped-def]
    pose: tuple, p: tuple, lm: list[float], lm_c: list[float], pxl
) -> tuple[tuple[float, float], tuple[float, float, float]]:
    """The predicted landmark position relative to the pose, ``d̂ = l̂ − x̂`` (2), and its prior
    covariance ``C = P_pp + Σ_l − P_pl − P_plᵀ`` (3 unique entries; ``P_pl``: the Schmidt
    cross-covariance's position rows, ``pxl``, or none)."""
    c00, c01, c11 = p[0] + lm_c[0], p[1] + lm_c[1], p[3] + lm_c[2]
    if pxl is not None:
        (x0, x1), (y0, y1) = pxl[:2].tolist()
        c00, c01, c11 = c00 - 2.0 * x0, c01 - x1 - y0, c11 - 2.0 * y1
    return (float(lm[0] - pose[0]), float(lm[1] - pose[1])), (c00, c01, c11)


def _mahalanobis2(d: tuple, c: tuple) -> float:
    """``dᵀ C⁻¹ d`` (0 when ``C`` is not positive definite: no evidence of linearity)."""
    det = c[0] * c[2] - c[1] * c[1]
    if not (det > 0.0 and c[0] > 0.0):
        return 0.0
    return (c[2] * d[0] * d[0] - 2.0 * c[1] * d[0] * d[1] + c[0] * d[1] * d[1]) / det


def _linear_first(setup: _Setup, lo: int, hi: int, pose: tuple, p: tuple) -> list[int]:
    """Order the measurements ``active[lo:hi]`` of one epoch so that those whose linearisation
    at the prior is meaningless come last (in place; nothing moves in the common case), and
    return those (the *near-field* measurements).

    Range and bearing are singular where the relative position ``l − x`` is zero. With the
    relative position's prior covariance ``C = P_pp + Σ_l − P_pl − P_plᵀ`` (``P_pl`` the
    Schmidt cross-covariance's position rows) and the predicted vector ``d̂ = l̂ − x̂``, a
    measurement is *near-field* when that singularity lies inside the 99 % region of the
    prior, ``d̂ᵀ C⁻¹ d̂ < χ²₂(0.99)`` (:data:`NEAR_FIELD_CHI2`): the EKF's Jacobians at ``x̂``
    then say nothing about the likelihood (measured: complex1/b/72 at t = 152 s, ``‖d̂‖ = 0.04``
    m against ``√tr C = 0.30`` m, whose update sent the pose 0.26 m further from the truth and
    turned 12 of the epoch's 13 NIS into 13–86). Near-field measurements are processed after
    the others, most linear (largest ``d̂ᵀ C⁻¹ d̂``) first, when the epoch's other measurements
    have localised the pose; the order the filter used is ``FilterResult.order``. One still
    near-field when its turn comes is statistically linearised (:func:`_slr`).
    """
    lm_xy, lm_c, lmk, pxm = setup.lm_xy, setup.lm_c, setup.landmark, setup.pxm
    px, py = pose[0], pose[1]
    bound = 2.0 * NEAR_FIELD_CHI2 * (p[0] + p[3])

    def m2_of(j: int) -> float:
        li = lmk[j]
        lm, lc = lm_xy[li], lm_c[li]
        dx, dy = lm[0] - px, lm[1] - py
        # λ_max(C) ≤ 2 (tr P_pp + tr Σ_l): far beyond that, no need for the cross-covariance
        if dx * dx + dy * dy > bound + 2.0 * NEAR_FIELD_CHI2 * (lc[0] + lc[2]):
            return math.inf
        pxl = None if pxm is None else pxm[:, 2 * li : 2 * li + 2]
        return _mahalanobis2(*_relative(pose, p, lm, lc, pxl))

    return near_field_last(setup.active, lo, hi, m2_of)


def near_field_last(active: list[int], lo: int, hi: int, m2_of) -> list[int]:  # type: ignore[no-untyped-def]
    """Move the near-field measurements of ``active[lo:hi]`` (``m2_of(j) < χ²₂(0.99)``,
    :data:`NEAR_FIELD_CHI2`) behind the others, largest ``m2`` first (in place; stable
    otherwise), and return them; shared by :func:`run_filter` and
    :func:`recovery.persisting.run_persisting`."""
    near: list[tuple[float, int, int]] = []
    far: list[int] = []
    for j in active[lo:hi]:
        m2 = m2_of(j)
        if m2 >= NEAR_FIELD_CHI2:
            far.append(j)
        else:
            near.append((-m2, len(near), j))
    if not near:
        return []
    near.sort()
    last = [j for *_, j in near]
    active[lo:hi] = far + last
    return last


def _slr(d: tuple, c: tuple, r: tuple[float, float]) -> tuple | None:  # type: ignore[type-arg]
    """Statistical linear regression of range and bearing on the relative position
    ``d ~ N(d̂, C)`` (``C``: 3 unique entries; the fixed points of :func:`_slr_points`):
    ``(A (4 entries, row by row), predicted range, predicted world bearing, R + Ω (3 unique))``
    or ``None`` when ``C`` is not positive definite.

    ``A = Cov(g(d), d) C⁻¹`` replaces the Jacobian ``∂g/∂d`` (by Stein's lemma the expected
    Jacobian) and ``Ω = Cov(g) − A C Aᵀ``, the linearisation's error, is added to the sensor
    noise (Särkkä, *Bayesian Filtering and Smoothing*, Sec. 5.5/9.3): around the singularity the
    bearing's spread, not its tangent, is what the measurement tells. The heading enters the
    bearing linearly (``−θ``) and the range not at all, so ``H_x = [−A, (0, −1)ᵀ]``,
    ``H_l = A`` keep the structure of :func:`_innovation`. Bearings are averaged as wrapped
    differences from ``atan2(d̂)``.
    """
    c00, c01, c11 = c
    if not (c00 > 0.0 and c00 * c11 - c01 * c01 > 0.0):
        return None
    l00 = math.sqrt(c00)
    l10 = c01 / l00
    l11 = math.sqrt(c11 - l10 * l10)
    u, v, w = _slr_points()
    px = d[0] + l00 * u
    py = d[1] + l10 * u + l11 * v
    g0 = np.hypot(px, py)
    b_ref = math.atan2(d[1], d[0])
    g1 = np.arctan2(py, px) - b_ref
    g1 = (g1 + math.pi) % (2.0 * math.pi) - math.pi
    m0, m1 = float(w @ g0), float(w @ g1)
    e0, e1 = g0 - m0, g1 - m1
    ex, ey = px - d[0], py - d[1]
    # Cov(g, d) (2 × 2) and Cov(g) (3 unique)
    k00, k01 = float(w @ (e0 * ex)), float(w @ (e0 * ey))
    k10, k11 = float(w @ (e1 * ex)), float(w @ (e1 * ey))
    # the points' own covariance of d (≈ C): Ω is then a Schur complement, positive
    # semi-definite by construction
    s00, s01, s11 = float(w @ (ex * ex)), float(w @ (ex * ey)), float(w @ (ey * ey))
    det = s00 * s11 - s01 * s01
    i00, i01, i11 = s11 / det, -s01 / det, s00 / det
    a00, a01 = k00 * i00 + k01 * i01, k00 * i01 + k01 * i11
    a10, a11 = k10 * i00 + k11 * i01, k10 * i01 + k11 * i11
    # Ω = Cov(g) − A C Aᵀ = Cov(g) − A Cov(d, g)
    o00 = float(w @ (e0 * e0)) - (a00 * k00 + a01 * k01)
    o01 = float(w @ (e0 * e1)) - (a00 * k10 + a01 * k11)
    o11 = float(w @ (e1 * e1)) - (a10 * k10 + a11 * k11)
    return (a00, a01, a10, a11), m0, b_ref + m1, (r[0] + o00, o01, r[1] + o11)


@functools.cache
def _slr_points() -> tuple[Array, Array, Array]:
    """Fixed ``N(0, I₂)`` points for :func:`_slr`: 2¹² scrambled Sobol points (seed 0) through
    the normal quantile, with their negatives (8192 points, mean exactly 0). Near the
    singularity the wrapped bearing jumps on the ray opposite ``d̂``, where Gauss–Hermite rules
    converge slowly (15 × 15 nodes: 34 % off a 4·10⁶-sample Monte Carlo, these 1 %:
    tests/test_recovery_near_field.py)."""
    from scipy.stats import norm, qmc

    z = norm.ppf(qmc.Sobol(2, scramble=True, seed=0).random_base2(12))
    z = np.vstack((z, -z))
    return z[:, 0].copy(), z[:, 1].copy(), np.full(z.shape[0], 1.0 / z.shape[0])


def _innovation(pose, p, lm, lm_c, r, z, pxl, slr=None):  # type: ignore[no-untyped-def]
    """Range-bearing innovation of one measurement (scalars).

    Returns ``y (2), S (3 unique), R_eff (3), N = P H_xᵀ (+ P_xl H_lᵀ) as columns (6),
    H (h00, h01, h10, h11)``; ``R_eff = R + H_l Σ_l H_lᵀ``, ``H_x = [[−h00, −h01, 0],
    [−h10, −h11, −1]]``, ``H_l = [[h00, h01], [h10, h11]]``. ``slr``: a statistical
    linearisation (:func:`_slr`) replacing the Jacobian, the prediction and ``R`` (``R + Ω``).
    """
    px, py, pth = pose
    p00, p01, p02, p11, p12, p22 = p
    ca, cb, cd = lm_c
    if slr is None:
        ddx = lm[0] - px
        ddy = lm[1] - py
        qq = ddx * ddx + ddy * ddy
        rng = math.sqrt(qq)
        h00, h01, h10, h11 = ddx / rng, ddy / rng, -ddy / qq, ddx / qq
        bearing = math.atan2(ddy, ddx)
        r00, r01, r11 = r[0], 0.0, r[1]
    else:
        (h00, h01, h10, h11), rng, bearing, (r00, r01, r11) = slr
    t00 = h00 * ca + h01 * cb
    t01 = h00 * cb + h01 * cd
    t10 = h10 * ca + h11 * cb
    t11 = h10 * cb + h11 * cd
    re00 = r00 + t00 * h00 + t01 * h01
    re01 = r01 + t00 * h10 + t01 * h11
    re11 = r11 + t10 * h10 + t11 * h11
    m00, m10 = -h00, -h10  # H_x's leading entries (negated once, not per product)
    a0 = m00 * p00 - h01 * p01
    a1 = m00 * p01 - h01 * p11
    a2 = m00 * p02 - h01 * p12
    b0 = m10 * p00 - h11 * p01 - p02
    b1 = m10 * p01 - h11 * p11 - p12
    b2 = m10 * p02 - h11 * p12 - p22
    s00 = m00 * a0 - h01 * a1 + re00
    s01 = m00 * b0 - h01 * b1 + re01
    s11 = m10 * b0 - h11 * b1 - b2 + re11
    if pxl is not None:  # Schmidt: the pose-landmark cross-covariance enters S and N
        bm = pxl @ np.array([[h00, h10], [h01, h11]])  # P_xl H_lᵀ, 3 × 2
        (c00, c01), (c10, c11), (c20, c21) = bm.tolist()
        hb01 = -h00 * c01 - h01 * c11
        hb10 = -h10 * c00 - h11 * c10 - c20
        s00 += 2.0 * (-h00 * c00 - h01 * c10)
        s01 += hb01 + hb10
        s11 += 2.0 * (-h10 * c01 - h11 * c11 - c21)
        a0, a1, a2, b0, b1, b2 = a0 + c00, a1 + c10, a2 + c20, b0 + c01, b1 + c11, b2 + c21
    y0 = z[0] - rng
    y1 = z[1] - bearing + pth
    if not -math.pi <= y1 < math.pi:
        y1 = wrap_angle_float(y1)
    return (y0, y1), (s00, s01, s11), (re00, re01, re11), (a0, a1, a2, b0, b1, b2), (
        h00, h01, h10, h11
    )  # fmt: skip


def _correct(p: tuple, n: tuple, i: tuple, y: tuple):  # type: ignore[no-untyped-def]
    """``K = N S⁻¹``, ``P ← P − N S⁻¹ Nᵀ``, ``Δx = K y`` on scalars (``i``: S⁻¹ unique).

    Returns ``(P, Δx, K)`` or ``None`` when the posterior is not finite positive definite.
    """
    a0, a1, a2, b0, b1, b2 = n
    i00, i01, i11 = i
    k00 = a0 * i00 + b0 * i01
    k01 = a0 * i01 + b0 * i11
    k10 = a1 * i00 + b1 * i01
    k11 = a1 * i01 + b1 * i11
    k20 = a2 * i00 + b2 * i01
    k21 = a2 * i01 + b2 * i11
    post = (
        p[0] - (a0 * k00 + b0 * k01),
        p[1] - (a0 * k10 + b0 * k11),
        p[2] - (a0 * k20 + b0 * k21),
        p[3] - (a1 * k10 + b1 * k11),
        p[4] - (a1 * k20 + b1 * k21),
        p[5] - (a2 * k20 + b2 * k21),
    )
    if not _pd(post):
        return None
    y0, y1 = y
    dx = (k00 * y0 + k01 * y1, k10 * y0 + k11 * y1, k20 * y0 + k21 * y1)
    return post, dx, (k00, k01, k10, k11, k20, k21)


def _schmidt_correct(pxm: Array, h: tuple, gain: tuple, map_rows: Array) -> None:
    """``P_xm ← P_xm − K (H_x P_xm + H_l Σ_lm)`` in place (``gain``: K's 6 entries row by row,
    ``map_rows``: the landmark's 2 rows of the map covariance)."""
    h00, h01, h10, h11 = h
    hx = np.array([[-h00, -h01, 0.0], [-h10, -h11, -1.0]])
    hl = np.array([[h00, h01], [h10, h11]])
    pxm -= np.array(gain).reshape(3, 2) @ (hx @ pxm + hl @ map_rows)


def _inflate(p: tuple, pxm, alpha: float) -> tuple:  # type: ignore[no-untyped-def]
    """Re-entry: ``P ← α P``, ``P_xm ← √α P_xm`` (in place)."""
    if pxm is not None:
        pxm *= math.sqrt(alpha)
    return tuple(alpha * v for v in p)


def _weighted_inverse(wj: float, s: tuple, re: tuple) -> tuple:
    """``(S + (1/w − 1) R_eff)⁻¹`` (unique entries): the measurement noise divided by ``w``."""
    f = 1.0 / wj - 1.0
    w00, w01, w11 = s[0] + f * re[0], s[1] + f * re[1], s[2] + f * re[2]
    det = w00 * w11 - w01 * w01
    return w11 / det, -w01 / det, w00 / det


@dataclass
class _Setup:
    """Everything the scalar loop reads, as Python lists (no numpy look-up per measurement),
    and the per-measurement outputs it fills (``status``, ``nis``, ``weights``, ``events``)."""

    seg: Segments
    epochs: list[int]
    local: list[list[float]]
    q: list[list[float]]
    active: list[int]
    bounds: list[int]
    lm_xy: list[list[float]]
    lm_c: list[list[float]]
    r: tuple[float, float]
    z: list[list[float]]
    landmark: list[int]
    pxm: Array | None
    lin: list[list[float]] | None
    w_fixed: list[float] | None
    ext2: float
    status: NDArray[np.int64]
    nis: Array
    weights: Array
    events: list[tuple[int, int, int, float]]
    det_s: Array


def _setup(inp: FilterInput, linearize_at: Array | None, use, weights) -> _Setup:  # type: ignore[no-untyped-def]
    """Status of every measurement, the epochs, the composed predictions, the map as lists."""
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
    if linearize_at is not None:
        # the batch's motion factor linearised at the solution: the shear of the actual
        # displacement between consecutive poses, noise rotated by their headings
        lin = np.asarray(linearize_at, dtype=np.float64)
        heading, position = lin[:, 2].copy(), lin[:, :2]
        seg = prepare_segments(inp.sigma, heading, position, epochs)
    else:
        seg = dead_reckoning_segments(inp.sigma, inp.u, epochs)
    m = inp.map_xy.shape[0]
    mapcov = inp.map_covariance
    if mapcov is not None:
        idx = 2 * np.arange(m)
        blocks = mapcov[idx[:, None, None] + [[0], [1]], idx[:, None, None] + [[0, 1]]]
    else:
        blocks = inp.map_marginals
    # re-entry never inflates the position variance beyond the map's extent squared, nor the
    # heading variance beyond π² (a pose that uncertain is not localised at all)
    ext2 = max(float(np.ptp(inp.map_xy, axis=0).max()) if m else 0.0, 1.0) ** 2
    bounds = np.searchsorted(inp.meas_grid[active], epochs, side="left").tolist()
    return _Setup(
        seg=seg,
        epochs=epochs.tolist(),
        local=seg.local[epochs].tolist(),
        q=seg.q[:, epochs].T.tolist(),
        active=active.tolist(),
        bounds=bounds + [active.shape[0]],
        lm_xy=inp.map_xy.tolist(),
        lm_c=blocks.reshape(-1, 4)[:, [0, 1, 3]].tolist(),
        r=(float(inp.r[0, 0]), float(inp.r[1, 1])),
        z=inp.meas_z.tolist(),
        landmark=inp.meas_landmark.tolist(),
        pxm=None if mapcov is None else np.zeros((3, 2 * m)),
        lin=None if linearize_at is None else lin[epochs].tolist(),  # only the epochs are read
        w_fixed=None if weights is None else np.asarray(weights, dtype=np.float64).tolist(),
        ext2=ext2,
        status=status,
        nis=np.full(j_all, np.nan),
        weights=np.ones(j_all),
        det_s=np.full(j_all, np.nan),
        events=[],
    )


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
        χ² bound without a gate, :data:`~relation_metric.consistency.OUTLIER_PROBABILITY`).
        After this many consecutive outlying measurements the map and the log disagree and
        the filter is **re-entered** (see ``on_divergence``); ``None``
        never re-enters (the plain EKF). Not the twin of EKF-SLAM's ``max_rejected_run``
        (:func:`slamrel.backends.ekf_slam.ekf_slam`): that one *force-accepts* a measurement
        after a run of *gated* ones (the gate gives way); this one *inflates the covariance*
        after a run of *outlying* ones, gated or not (the filter's confidence gives way).
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
        After a re-entry the filter *re-acquires*: robust weights (``robust``) are suspended
        until the first measurement within the outlier bound — after a run of outliers the
        filter, not the measurements, is suspect, and down-weighting the measurements that
        disagree with it would keep it off track.
        ``"raise"``: :class:`DivergenceError` instead (the old behaviour).
    robust : {None, "huber", "cauchy", "redescending"}
        M-estimator on the innovation's Mahalanobis distance ``d = √NIS``: the measurement's
        effective noise (sensor plus landmark) is divided by the weight ``w`` (1 for
        ``d ≤ c``, so a healthy run is the plain EKF). ``"huber"`` ``c/d`` and ``"cauchy"``
        ``(c/d)²``, iterated to the fixed point ``w = w(d(w))`` with ``d(w)`` under the
        re-weighted ``S`` (:func:`_robust_weight`) — at the fixed point the pull ``w·y`` of a
        gross outlier stays bounded but does not vanish (Cauchy: ``≈ c √R_eff``);
        ``"redescending"`` ``(c/d)²`` with ``d`` under the filter's own ``S`` (one step,
        no iteration): the pull ``c²/d`` of an innovation falls as it grows, so gross
        outliers barely move the filter (measured on MRCLAM: what lets it match the gated
        EKF, see :func:`recovery.recover.recover`).
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
    if robust_threshold is not None and not (0.0 < robust_threshold < math.inf):
        raise ValueError(f"robust_threshold must be positive and finite, got {robust_threshold}")
    if not _pd(tuple(float(inp.p0[i, j]) for i, j in SYM6)):
        raise DivergenceError(
            f"filter cannot start at t={float(inp.times[0]):.6f} s: the initial covariance is "
            "not finite positive definite"
        )
    setup = _setup(inp, linearize_at, use, weights)
    gate_thr = chi2_quantile(gate, 2) if gate is not None else math.inf
    outlier = gate_thr if gate is not None else chi2_quantile(OUTLIER_PROBABILITY, 2)
    c = float(robust_threshold) if robust_threshold is not None else ROBUST_C
    rules = _Rules(
        gate=gate_thr,
        outlier=outlier,
        robust=robust,
        robust_c=c,
        robust_c2=c * c if robust is not None else math.inf,
        fixed=linearize_at is not None,
        raise_=on_divergence == "raise",
    )
    reentry = _ReentryRule(outlier, max_outlier_run, rules.raise_, setup.ext2, inp)
    bar = tqdm(
        range(len(setup.epochs)),
        desc="filter",
        unit="epoch",
        disable=not progress,
        file=sys.stderr,
        leave=False,
    )
    pri_x, pri_p, post_x, post_p = _filter_loop(inp, setup, rules, reentry, bar)
    bar.close()
    return _result(setup, rules, linearize_at, pri_x, pri_p, post_x, post_p)


def _rows(values: array, width: int) -> Array:
    """(E, width) float64 array (a copy) of the loop's flat ``array('d')``."""
    return np.frombuffer(values, dtype=np.float64).reshape(-1, width).copy()


def _result(setup: _Setup, rules: _Rules, lin, pri_x, pri_p, post_x, post_p) -> FilterResult:  # type: ignore[no-untyped-def]
    """Arrays of the loop's lists; every grid pose filled from its epoch's posterior."""
    seg, epochs = setup.seg, np.asarray(setup.epochs, dtype=np.int64)
    post_xa = _rows(post_x, 3)
    post_p6 = _rows(post_p, 6)
    post_pa = _full(post_p6.T)
    psi = np.asarray(lin, dtype=np.float64)[epochs, 2] if rules.fixed else post_xa[:, 2]
    steps, poses, covs = fill(seg, psi, post_xa, post_p6)
    poses[epochs] = post_xa
    covs[epochs] = post_pa
    if rules.fixed:
        poses = np.array(lin, dtype=np.float64)
    ev = np.array(setup.events, dtype=np.float64).reshape(-1, 4)
    return FilterResult(
        poses=poses,
        covariances=covs,
        segments=seg,
        prior_poses=_rows(pri_x, 3),
        prior_covariances=_full(_rows(pri_p, 6).T),
        post_poses=post_xa,
        post_covariances=post_pa,
        status=readonly(setup.status, np.int64),
        nis=readonly(setup.nis),
        psi=psi,
        steps=steps,
        order=readonly(np.asarray(setup.active, dtype=np.int64), np.int64),
        weights=readonly(setup.weights),
        events=FilterEvents(
            grid=ev[:, 0].astype(np.int64),
            measurement=ev[:, 1].astype(np.int64),
            kind=ev[:, 2].astype(np.int64),
            inflation=ev[:, 3].copy(),
        ),
        outlier_bound=rules.outlier,
        innovation_det=readonly(setup.det_s),
    )


def _decide(setup, rules, reentry, v, p, ysr, k, j) -> tuple[float, float]:  # type: ignore[no-untyped-def]
    """Gate, robust weight and re-entry of a measurement with NIS ``v`` (not the covariance-only
    pass): ``(w, α)``, ``w = 0`` when gated, ``α`` the re-entry's inflation (0: none)."""
    reacquiring = reentry.reacquiring  # read before this measurement is counted
    alpha = reentry.observe(v, p, k, j)
    if alpha:
        setup.events.append((k, j, REENTRY, alpha))
    if v > rules.gate:
        setup.status[j] = GATED
        return 0.0, alpha
    if v > rules.robust_c2 and not reacquiring:
        return _weight(rules, v, *ysr), alpha
    return 1.0, alpha


_SKIPPED = {
    SKIPPED_S: "innovation covariance is not positive definite",
    SKIPPED_P: "pose covariance is not finite positive definite",
}


def _skip(
    inp: FilterInput, setup: _Setup, rules: _Rules, k: int, j: int, kind: FilterEvent
) -> None:
    """A measurement whose ``S`` or posterior is not positive definite: skipped (counted as
    gated) and recorded, or :class:`DivergenceError` (``raise`` mode, covariance-only pass)."""
    if rules.raise_ or rules.fixed:
        _diverged(inp, inp.times[k], j, _SKIPPED[kind])
    setup.status[j] = GATED
    setup.events.append((k, j, kind, 1.0))


def _weight(rules: _Rules, v: float, y: tuple, s: tuple, re: tuple) -> float:
    """Robust weight of an innovation with NIS ``v`` beyond ``c²`` (see :func:`run_filter`)."""
    if rules.robust == "redescending":
        return rules.robust_c2 / v
    return _robust_weight(rules.robust == "cauchy", rules.robust_c, *y, *s, *re)


def _filter_loop(inp: FilterInput, setup: _Setup, rules: _Rules, reentry: _ReentryRule, bar):  # type: ignore[no-untyped-def]
    """The scalar recursion over the epochs: predict, then each measurement of the epoch.

    Returns the priors and posteriors at the epochs (flat ``array('d')``, 3 or 6 values per
    epoch) and fills ``setup.status``, ``setup.nis``, ``setup.weights`` and ``setup.events``
    in place.
    """
    lm_xy, lm_c, r, zz, lmk = setup.lm_xy, setup.lm_c, setup.r, setup.z, setup.landmark
    pxm, mapcov, w_fixed = setup.pxm, inp.map_covariance, setup.w_fixed
    nis, wts, times, dets = setup.nis, setup.weights, inp.times, setup.det_s
    pose = tuple(float(v) for v in inp.x0)
    p = tuple(float(inp.p0[i, j]) for i, j in SYM6)
    # raw doubles (array.array), not lists of tuples: the arrays are read back without
    # chasing 10^5 float objects scattered over the heap
    pri_x, pri_p, post_x, post_p = array("d"), array("d"), array("d"), array("d")
    # locals, not attribute lookups, in the per-epoch loop (10^5 epochs)
    epochs, bounds, local, q, active = (
        setup.epochs,
        setup.bounds,
        setup.local,
        setup.q,
        setup.active,
    )
    fixed = rules.fixed
    lin: list[list[float]] = []  # read only when fixed
    if fixed:
        assert setup.lin is not None  # fixed and setup.lin both mean: linearize_at given
        lin = setup.lin
    for e in bar:
        k = epochs[e]
        if e > 0:
            psi = lin[e - 1][2] if fixed else pose[2]
            pose, p = _predict(pose, p, pxm, local[e], q[e], psi)
        pri_x.extend(pose)
        pri_p.extend(p)
        at = lin[e] if fixed else None
        near = () if fixed else _linear_first(setup, bounds[e], bounds[e + 1], pose, p)
        for j in active[bounds[e] : bounds[e + 1]]:
            li = lmk[j]
            pxl = None if pxm is None else pxm[:, 2 * li : 2 * li + 2]
            slr = None
            if near and j in near:  # still near-field now that the others have been used?
                rel = _relative(pose, p, lm_xy[li], lm_c[li], pxl)
                if _mahalanobis2(*rel) < NEAR_FIELD_CHI2:
                    slr = _slr(*rel, r)
            y, s, re, n, h = _innovation(at or pose, p, lm_xy[li], lm_c[li], r, zz[j], pxl, slr)
            det = s[0] * s[2] - s[1] * s[1]
            if not (det > 0.0 and s[0] > 0.0):
                _skip(inp, setup, rules, k, j, SKIPPED_S)
                continue
            i = (s[2] / det, -s[1] / det, s[0] / det)
            v = y[0] * y[0] * i[0] + 2.0 * y[0] * y[1] * i[1] + y[1] * y[1] * i[2]
            nis[j] = v
            dets[j] = det
            if fixed:
                wj, alpha = 1.0 if w_fixed is None else w_fixed[j], 0.0
            else:
                wj, alpha = _decide(setup, rules, reentry, v, p, (y, s, re), k, j)
            if wj > 0.0:  # 0: gated
                if wj != 1.0:
                    wts[j] = wj
                    i = _weighted_inverse(wj, s, re)
                out = _correct(p, n, i, y)
                if out is None:
                    _skip(inp, setup, rules, k, j, SKIPPED_P)
                else:
                    p, dx, gain = out
                    if not fixed:
                        pose = (pose[0] + dx[0], pose[1] + dx[1], pose[2] + dx[2])
                    if pxm is not None:
                        assert mapcov is not None  # pxm is set exactly with a map covariance
                        _schmidt_correct(pxm, h, gain, mapcov[2 * li : 2 * li + 2])
            if alpha:  # the re-entry: right after the run's last measurement
                p = _inflate(p, pxm, alpha)
        if bounds[e + 1] == bounds[e] and not _pd(p):
            raise DivergenceError(
                f"filter diverged at t={float(times[k]):.6f} s: predicted covariance is not "
                "finite positive definite"
            )
        post_x.extend(pose)
        post_p.extend(p)
    return pri_x, pri_p, post_x, post_p


def _full(cols) -> Array:  # type: ignore[no-untyped-def]
    """Symmetric (N, 3, 3) matrices from their 6 unique entries ``(00, 01, 02, 11, 12, 22)``,
    given as 6 arrays of shape (N,) (e.g. ``p6.T`` of an (N, 6) array)."""
    out = np.empty((cols[0].shape[0], 3, 3))
    for col, (i, j) in zip(cols, SYM6):
        out[:, i, j] = col
        if i != j:
            out[:, j, i] = col
    return out


def _base_rotation(seg: Segments, psi: Array) -> tuple[Array, Array]:
    """``cos ψ_b, sin ψ_b`` of every grid pose's base epoch, shape (N,) each: computed per
    epoch, then repeated (the same values as on the repeated angles, E evaluations, not N)."""
    return np.cos(psi)[seg.epoch_of], np.sin(psi)[seg.epoch_of]


def world_steps(seg: Segments, psi: Array, rotation: tuple[Array, Array] | None = None) -> Array:
    """World-frame pose of every grid pose relative to its base epoch: ``R(ψ) local``, (N, 3).

    ``rotation``: :func:`_base_rotation` of ``psi`` when already computed.
    """
    c, s = _base_rotation(seg, psi) if rotation is None else rotation
    loc = seg.local
    out = np.empty_like(loc)
    out[:, 0] = c * loc[:, 0] - s * loc[:, 1]
    out[:, 1] = s * loc[:, 0] + c * loc[:, 1]
    out[:, 2] = loc[:, 2]
    return out


def fill(
    seg: Segments, psi: Array, post_x: Array, post_p6: Array, shift: Array | None = None
) -> tuple[Array, Array, Array]:
    """Predicted poses and covariances of every grid pose from its base epoch's posterior.

    ``x_k = x⁺_b + [R(ψ_b) local_xy, local_θ]`` and
    ``P_k = S(Δ_k) P⁺_b S(Δ_k)ᵀ + Rot(ψ_b) q_k Rot(ψ_b)ᵀ`` (:func:`predict6`), vectorised.
    ``post_x`` (E, 3) and ``post_p6`` (E, 6) (unique entries) are the epochs' posteriors;
    ``shift`` (N, 3), added to every world step first (an odometry bias's mean,
    :mod:`recovery.odometry_bias`). Returns the world steps (:func:`world_steps`), the poses
    (N, 3) and covariances (N, 3, 3).
    """
    rot = _base_rotation(seg, psi)
    w = world_steps(seg, psi, rot)
    if shift is not None:
        w += shift
    e_of = seg.epoch_of
    poses = np.take(post_x, e_of, axis=0) + w
    pb = np.take(np.ascontiguousarray(post_p6.T), e_of, axis=1)
    p6 = predict6(tuple(pb), tuple(seg.q), rot[0], rot[1], w[:, 0], w[:, 1])
    return w, poses, _full(p6)


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
