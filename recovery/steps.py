"""The time grid of a recovery: one pose per control/odometry time and per measurement time.

The grid is the sorted union of the control (or odometry) times and the times of the
measurements inside ``[t_first, t_last]``. Every grid interval lies inside one control row and
becomes one motion increment ``u_k`` (body frame) with covariance ``Σ_k``:

* velocity model: the row's ``(v, ω)`` held over the piece (``control_stamp`` ``"start"``: row
  ``k`` over ``[t_k, t_{k+1})``; ``"end"``: over ``(t_{k−1}, t_k]``), as the exact arc or, with
  ``integration="euler"``, as the piece of the row's Euler step
  (:func:`recovery.models.euler_increment`); a row of duration ``Δt`` cut into pieces of
  duration ``a`` (a measurement fell inside it) gives each piece the control covariance
  ``M Δt / a``, which keeps the row's total pose variance (to first order: the pieces'
  Jacobians scale with ``a``). Uncut rows get ``M`` exactly.
* odometry model: a piece covering the fraction ``f`` of the step gets the constant-twist
  increment ``exp(f log u)`` and covariance ``f Σ``.
* ``step_covariance`` (either model): as ``pose_noise`` with the row's own ``C_k``
  (``Bundle.step_covariances``: velocity, the control row held over the piece; odometry, the
  row that ends the step).
* ``pose_noise`` (either model): a piece covering the fraction ``f`` of its row gets ``f C``;
  a world-frame ``C`` is turned into the body frame with the piece's dead-reckoning heading
  (``initial_pose`` composed with the increments before it).

Measurements outside the span are counted, never used. Measurement times within
:data:`SNAP_TOLERANCE` of a control time are snapped to it by the reader
(:func:`snap_times`), so float noise in the files does not split the grid.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from recovery.bundle import Bundle
from recovery.models import (
    MotionModel,
    euler_increment,
    increment_covariance,
    velocity_increment,
)
from relation_metric import se2
from relation_metric.arrays import Array
from relation_metric.errors import InputError
from relation_metric.trajectory import readonly

__all__ = ["SNAP_TOLERANCE", "Steps", "build_steps", "log_times", "snap_times"]

#: A measurement time this close to a control/odometry time (but not equal to it) is taken to
#: be that time: float noise of times printed with a few decimals (``0.30000000000000004`` vs
#: ``0.3``), which would otherwise cut a control row into a piece of 10⁻¹⁷ s and one of the rest.
SNAP_TOLERANCE = 1e-6


@dataclass(frozen=True)
class Steps:
    """Motion increments on the recovery grid.

    Attributes
    ----------
    times : ndarray, shape (N,)
    u : ndarray, shape (N − 1, 3)
        Body-frame increments, ``x_{k+1} = x_k ∘ u_k``.
    sigma : ndarray, shape (N − 1, 3, 3)
        Covariance of each increment.
    measurement_grid : ndarray of int, shape (J,)
        Grid index of each bundle measurement, −1 outside the span.
    """

    times: Array
    u: Array
    sigma: Array
    measurement_grid: NDArray[np.int64]

    def __post_init__(self) -> None:
        for name in ("times", "u", "sigma"):
            object.__setattr__(self, name, readonly(getattr(self, name)))
        object.__setattr__(self, "measurement_grid", readonly(self.measurement_grid, np.int64))


def log_times(bundle: Bundle) -> Array:
    """The times of the bundle's motion log: control times or odometry times, (K,)."""
    if bundle.motion.type == "velocity":
        assert bundle.controls is not None
        return bundle.controls[:, 0]
    assert bundle.odometry is not None
    return bundle.odometry.timestamps


def snap_times(t: Array, grid: Array, tolerance: float = SNAP_TOLERANCE) -> tuple[Array, Array]:
    """``t`` with every time within ``tolerance`` of a time of ``grid`` set to that time.

    Parameters
    ----------
    t : ndarray, shape (J,)
    grid : ndarray, shape (K,)
        Sorted times (K ≥ 1).

    Returns
    -------
    snapped : ndarray, shape (J,)
        A new array.
    moved : ndarray, shape (J,)
        The signed change ``snapped − t`` (0 where nothing moved, also at equal times).
    """
    t = np.asarray(t, dtype=np.float64)
    grid = np.asarray(grid, dtype=np.float64)
    k = np.clip(np.searchsorted(grid, t), 1, max(grid.shape[0] - 1, 1))
    lo, hi = grid[k - 1], grid[np.minimum(k, grid.shape[0] - 1)]
    nearest = np.where(np.abs(t - lo) <= np.abs(hi - t), lo, hi)
    snapped = np.where(np.abs(nearest - t) <= tolerance, nearest, t)
    return snapped, snapped - t


def build_steps(bundle: Bundle) -> Steps:
    """Cut the bundle's controls or odometry at the measurement times (see module doc)."""
    tc = log_times(bundle)
    tm = bundle.measurement_times
    inside = (tm >= tc[0]) & (tm <= tc[-1])
    times = np.unique(np.concatenate((tc, tm[inside])))
    if times.shape[0] < 2:
        raise InputError(
            "the controls/odometry span no time; expected increasing times", path=bundle.path
        )
    grid = np.where(inside, np.searchsorted(times, tm), -1)
    start, end = times[:-1], times[1:]
    row = np.searchsorted(tc, start, side="right") - 1
    row_dt = tc[row + 1] - tc[row]
    piece = end - start
    motion = bundle.motion
    if motion.type == "velocity":
        assert bundle.controls is not None
        # control_stamp "end": row k + 1 is held over (t_k, t_{k+1}] (row 0 only opens the log)
        held = bundle.controls[1:] if motion.control_stamp == "end" else bundle.controls
        v, w = held[row, 1], held[row, 2]
        offset = start - tc[row]
        if motion.integration == "euler":
            u, _ = euler_increment(v, w, piece, offset)
        else:
            u, _ = velocity_increment(v, w, piece)
        aux = np.column_stack((v, w, piece, row_dt / piece, offset))
        own = _row_covariances(bundle, row + (motion.control_stamp == "end"))
        sigma = increment_covariance(
            motion, u, aux, heading=_headings(bundle, motion, u), step_covariance=own
        )
    else:
        o = bundle.odometry.poses  # type: ignore[union-attr]
        u_row = se2.between(o[row], o[row + 1])
        f = piece / row_dt
        whole = f == 1.0
        u = np.where(whole[:, None], u_row, se2.exp(f[:, None] * se2.log(u_row)))
        sigma = increment_covariance(
            motion,
            u_row,
            f,
            heading=_headings(bundle, motion, u),
            step_covariance=_row_covariances(bundle, row + 1),
        )
    return Steps(times=times, u=u, sigma=sigma, measurement_grid=grid)


def _row_covariances(bundle: Bundle, rows: NDArray[np.int64]) -> Array | None:
    """The stated covariance of the log row each step belongs to (``step_covariance``
    models only; velocity: the row held over the step, odometry: the row that ends it)."""
    if bundle.step_covariances is None:
        return None
    return bundle.step_covariances[rows]


def _headings(bundle: Bundle, motion: MotionModel, u: Array) -> Array | None:
    """Dead-reckoning heading at the start of each step (world-frame pose noise only)."""
    if "world" not in (motion.pose_noise_frame, motion.step_covariance_frame):
        return None
    before = np.concatenate(([0.0], np.cumsum(u[:-1, 2])))
    return se2.wrap_angle(float(bundle.initial_pose[2]) + before)
