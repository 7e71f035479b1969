"""A persisting odometry error in the augmented recovery: speed scale and turn per metre.

A bundle may state that its odometry's errors persist (``motion_model.persisting``,
docs/bundle.md): the robot moves with the commands ``(v (1 + s(t)), ω + κ(t) v)`` plus the
stated white noise, ``s`` (a speed scale, unitless) and ``κ`` (a turn per metre, rad/m) each a
first-order Gauss–Markov process, independent of each other and of the rest (wheel radii that
change with the floor, the load, the tyres' temperature). :mod:`recovery.persisting` carries
``o = [s, κ]`` as two more states; this module gives it what it needs.

Between two epochs the augmented state is predicted with ``o`` held at its value at the first
epoch, then decayed to the second like every other bias (``φ = e^{−Δ/τ}``, process noise
``σ² (1 − φ²)``). So that holding it is a small approximation, a recovery with a persisting
odometry error puts an epoch (with no measurement) wherever two would be more than
:func:`epoch_spacing` apart (:func:`with_virtual_epochs`): an eighth of the shorter time
constant, at most 1 s.

With ``o`` held over a segment, pose ``k``'s position and heading in the frame of its base
epoch ``b`` are linear in ``o`` to first order, with the Jacobian ``B_k`` (3 × 2)
(:func:`motion_jacobians`), from the reference geometry of the segments
(:func:`recovery.ekf.dead_reckoning_segments`: ``w_m`` the displacement of step ``m`` in ``b``'s
frame, ``ℓ_m`` its signed length, ``D_m = Σ_{b ≤ j < m} ℓ_j``, ``J`` the turn by 90°):

    (O1)  ∂local_xy(k)/∂s = local_xy(k),                  ∂local_θ(k)/∂s = 0
    (O2)  ∂local_xy(k)/∂κ = J Σ_{b ≤ m < k} w_m (D_m + ℓ_m / 2),   ∂local_θ(k)/∂κ = D_k

(O1) is exact: the speed scales every step's length, not its direction. (O2) turns each
step's chord by the heading ``κ`` adds up to its middle (the chord's own length change with
``ω`` is second order). Both are segmented cumulative sums, no loop over poses. In the world
frame ``G_k = [R(ψ_b) B_k,xy; B_k,θ]``: the predicted pose is ``x⁺_b ⊕ local_k + G_k ô_b``.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from recovery.ekf import Segments
from relation_metric.arrays import Array

__all__ = ["epoch_spacing", "motion_jacobians", "with_virtual_epochs", "world_jacobians"]


def epoch_spacing(time_constants: tuple[float, float]) -> float:
    """The longest segment [s] a recovery with a persisting odometry error predicts over with
    ``o`` held: an eighth of the shorter time constant, at most 1 s. Holding a Gauss–Markov
    value over ``Δ`` leaves out its variation within the segment (variance ``≈ 2σ²Δ/τ``),
    which the poses inside it do not see; the pose variance that leaves out falls as ``Δ²``.
    Measured (tests/test_odometry_bias.py's Monte Carlo, 40 runs, τ 3 and 5 s): the smoother's
    mean NEES (dof 3) 4.28 ± 0.16 at ``τ/2``, 3.23 ± 0.11 at ``τ/5``, 3.13 ± 0.11 at ``τ/10``
    (the filter's 3.16, 3.01, 3.01)."""
    return min(1.0, min(time_constants) / 8.0)


def with_virtual_epochs(
    times: Array, epochs: NDArray[np.int64], spacing: float
) -> NDArray[np.int64]:
    """``epochs`` (sorted grid indices, first and last included) with grid poses added so that
    no two consecutive epochs are more than ``spacing`` seconds apart where the grid allows
    (a grid step longer than ``spacing`` stays one segment). Vectorised: each grid pose's
    slot ``⌊(t − t_e) / spacing⌋`` since its base epoch; the first pose of each new slot is
    an epoch."""
    t = np.asarray(times, dtype=np.float64)
    n = t.shape[0]
    if n < 2 or not math.isfinite(spacing) or spacing <= 0:
        return epochs
    runs = np.diff(epochs)
    base = np.empty(n, dtype=np.int64)
    base[0] = 0
    base[1:] = np.repeat(epochs[:-1], runs)
    slot = np.floor((t - t[base]) / spacing).astype(np.int64)
    # the slot of the pose before, in the same segment (an epoch is slot 0 of its own)
    before = np.where(base[1:] == np.arange(n - 1), 0, slot[:-1])
    new = np.flatnonzero(slot[1:] > before) + 1  # the first pose of a later slot
    return np.unique(np.concatenate((epochs, new))).astype(np.int64)


def motion_jacobians(seg: Segments, u: Array) -> Array:
    """``B_k`` (N, 3, 2) of every grid pose: (O1) and (O2) of the module doc, columns
    ``(s, κ)``, rows the pose ``(x, y, θ)`` in the frame of its base epoch.

    ``u`` (N − 1, 3): the body-frame increments; a step's signed length is its chord, signed
    by its forward component.
    """
    loc = seg.local
    n = loc.shape[0]
    out = np.zeros((n, 3, 2))
    out[:, :2, 0] = loc[:, :2]
    out[0] = 0.0
    if n < 2:
        return out
    epochs = seg.epochs
    runs = np.diff(epochs)
    steps = np.arange(n - 1)
    b1 = np.repeat(epochs[:-1], runs)  # the base epoch of each step's segment
    start = np.where((steps == b1)[:, None], 0.0, loc[:-1, :2])
    w = loc[1:, :2] - start
    ell = np.hypot(u[:, 0], u[:, 1]) * np.where(u[:, 0] < 0.0, -1.0, 1.0)
    cum = np.concatenate(([0.0], np.cumsum(ell)))
    d_before = cum[:-1] - np.repeat(cum[epochs[:-1]], runs)  # D_m
    out[1:, 2, 1] = d_before + ell  # D_k, k = m + 1
    terms = w * (d_before + 0.5 * ell)[:, None]
    ct = np.zeros((n, 2))
    np.cumsum(terms, axis=0, out=ct[1:])
    summed = ct[1:] - np.repeat(ct[epochs[:-1]], runs, axis=0)
    out[1:, 0, 1] = -summed[:, 1]
    out[1:, 1, 1] = summed[:, 0]
    return out


def world_jacobians(jac: Array, seg: Segments, psi: Array) -> Array:
    """``G_k`` (N, 3, 2): ``B_k`` (:func:`motion_jacobians`) with its position rows turned by
    the heading ``ψ`` (E,) of the base epoch of each pose."""
    c, s = np.cos(psi)[seg.epoch_of], np.sin(psi)[seg.epoch_of]
    out = jac.copy()
    out[:, 0] = c[:, None] * jac[:, 0] - s[:, None] * jac[:, 1]
    out[:, 1] = s[:, None] * jac[:, 0] + c[:, None] * jac[:, 1]
    return out
