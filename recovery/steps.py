"""The time grid of a recovery: one pose per control/odometry time and per measurement time.

The grid is the sorted union of the control (or odometry) times and the times of the
measurements inside ``[t_first, t_last]``. Every grid interval lies inside one control row and
becomes one motion increment ``u_k`` (body frame) with covariance ``Σ_k``:

* velocity model: the row's ``(v, ω)`` held over the piece; a row of duration ``Δt`` cut into
  pieces of duration ``a`` (a measurement fell inside it) gives each piece the control
  covariance ``M Δt / a``, which keeps the row's total pose variance (to first order: the
  pieces' Jacobians scale with ``a``). Uncut rows get ``M`` exactly.
* odometry model: a piece covering the fraction ``f`` of the step gets the constant-twist
  increment ``exp(f log u)`` and covariance ``f Σ``.

Measurements outside the span are counted, never used.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from recovery.bundle import Bundle
from recovery.models import increment_covariance, velocity_increment
from relation_metric import se2
from relation_metric.arrays import Array
from relation_metric.errors import InputError
from relation_metric.trajectory import readonly

__all__ = ["Steps", "build_steps"]


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


def build_steps(bundle: Bundle) -> Steps:
    """Cut the bundle's controls or odometry at the measurement times (see module doc)."""
    if bundle.motion.type == "velocity":
        assert bundle.controls is not None
        tc = bundle.controls[:, 0]
    else:
        assert bundle.odometry is not None
        tc = bundle.odometry.timestamps
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
    if bundle.motion.type == "velocity":
        v, w = bundle.controls[row, 1], bundle.controls[row, 2]  # type: ignore[index]
        u, _ = velocity_increment(v, w, piece)
        aux = np.column_stack((v, w, piece, row_dt / piece))
        sigma = increment_covariance(bundle.motion, u, aux)
    else:
        o = bundle.odometry.poses  # type: ignore[union-attr]
        u_row = se2.between(o[row], o[row + 1])
        f = piece / row_dt
        whole = f == 1.0
        u = np.where(whole[:, None], u_row, se2.exp(f[:, None] * se2.log(u_row)))
        sigma = increment_covariance(bundle.motion, u_row, f)
    return Steps(times=times, u=u, sigma=sigma, measurement_grid=grid)
