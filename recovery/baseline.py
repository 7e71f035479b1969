"""The reference: a straightforward per-step EKF localisation loop on filterpy.

One ``filterpy.kalman.ExtendedKalmanFilter`` is predicted over every grid step (the motion
model overrides ``predict_x``; ``F`` and ``Q`` are set per step) and updated with every
associated measurement through filterpy's own ``update`` (Joseph form) with a ``residual``
that wraps the bearing. This is what :func:`recovery.ekf.run_filter` must reproduce (to 1e-9)
and what the benchmark times it against. Marginal map covariances only (no Schmidt update).
"""

from __future__ import annotations

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter
from numpy.typing import NDArray

from recovery.ekf import GATED, OUTSIDE, UNASSOCIATED, USED, FilterInput
from recovery.models import process_noise, range_bearing
from relation_metric import se2
from relation_metric.arrays import Array
from relation_metric.consistency import chi2_quantile

__all__ = ["filterpy_localisation"]


class _UnicycleEKF(ExtendedKalmanFilter):  # type: ignore[misc]
    x: Array  # filterpy's state column (3, 1); filterpy has no type hints

    def predict_x(self, u: Array = 0) -> None:  # type: ignore[assignment]
        self.x = se2.compose(self.x.ravel(), u).reshape(3, 1)


def _residual(a: Array, b: Array) -> Array:
    y = a - b
    y[1] = se2.wrap_angle(y[1])
    return y


def filterpy_localisation(
    inp: FilterInput, *, gate: float | None = None
) -> tuple[Array, Array, NDArray[np.int64]]:
    """Per-step filterpy EKF over the grid of ``inp``.

    Returns
    -------
    poses : ndarray, shape (N, 3)
        Posterior after the updates at each grid time (angle wrapped).
    covariances : ndarray, shape (N, 3, 3)
    status : ndarray of int, shape (J,)
    """
    assert inp.map_covariance is None, "the baseline handles marginal map covariances only"
    n = inp.times.shape[0]
    ekf = _UnicycleEKF(dim_x=3, dim_z=2)
    ekf.x = np.asarray(inp.x0, dtype=np.float64).reshape(3, 1).copy()
    ekf.P = np.asarray(inp.p0, dtype=np.float64).copy()
    thr = chi2_quantile(gate, 2) if gate is not None else np.inf
    status = np.full(inp.meas_grid.shape[0], USED, dtype=np.int64)
    status[inp.meas_landmark < 0] = UNASSOCIATED
    status[inp.meas_grid < 0] = OUTSIDE
    order = np.flatnonzero(status == USED)
    order = order[np.argsort(inp.meas_grid[order], kind="stable")]
    by_grid: dict[int, list[int]] = {}
    for j in order.tolist():
        by_grid.setdefault(int(inp.meas_grid[j]), []).append(j)
    poses = np.empty((n, 3))
    covs = np.empty((n, 3, 3))

    def hjac(x: Array, lm: Array) -> Array:
        return range_bearing(x.ravel(), lm)[1]

    def hx(x: Array, lm: Array) -> Array:
        return range_bearing(x.ravel(), lm)[0].reshape(2, 1)

    for k in range(n):
        if k > 0:
            u = inp.u[k - 1]
            x = ekf.x.ravel()
            ekf.F = se2.compose_jacobian(x, u)
            ekf.Q = process_noise(x[2], inp.sigma[k - 1])
            ekf.predict(u=u)
        for j in by_grid.get(k, ()):
            li = int(inp.meas_landmark[j])
            lm = inp.map_xy[li]
            _, h_x, h_l = range_bearing(ekf.x.ravel(), lm)
            r = inp.r + h_l @ inp.map_marginals[li] @ h_l.T
            if gate is not None:
                y = _residual(inp.meas_z[j].reshape(2, 1), hx(ekf.x, lm))
                s = h_x @ ekf.P @ h_x.T + r
                if float(y.ravel() @ np.linalg.solve(s, y.ravel())) > thr:
                    status[j] = GATED
                    continue
            ekf.update(
                inp.meas_z[j].reshape(2, 1),
                hjac,
                hx,
                R=r,
                args=(lm,),
                hx_args=(lm,),
                residual=_residual,
            )
        poses[k] = ekf.x.ravel()
        covs[k] = ekf.P
    poses[:, 2] = se2.wrap_angle(poses[:, 2])
    return poses, covs, status
