"""A sensor mounted off the robot's origin: the recovery runs in the sensor's frame.

With the sensor at pose ``m = (m_x, m_y, m_θ)`` in the robot frame, a measurement is
``h(x ∘ m, l)`` (``recovery.models.range_bearing`` of the sensor pose). The sensor pose
``s = x ∘ m`` moves by the conjugated increment

    s_{k+1} = s_k ∘ u_s,   u_s = m⁻¹ ∘ u ∘ m,
    Σ_s = J Σ Jᵀ,   J = ∂u_s/∂u = blockdiag(R(−m_θ), 1) · S(R(u_θ) t_m)

(``S`` the shear of :func:`relation_metric.se2.compose_jacobian`), exact for the means and
to first order for the covariances, the order of the EKF's own linearisation. So the filter,
the smoother and the batch run unchanged on the sensor's poses (start ``x₀ ∘ m``, covariance
``A P₀ Aᵀ``, ``A = ∂(x ∘ m)/∂x``), and the result is taken back to the robot:
``x = s ∘ m⁻¹``, ``P = B P_s Bᵀ``, ``B = ∂(s ∘ m⁻¹)/∂s``. The map, the measurements and the
NIS do not change.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from recovery.ekf import FilterInput
from relation_metric import se2
from relation_metric.arrays import Array

__all__ = ["to_sensor_frame", "to_robot_frame", "loadings_to_robot_frame", "conjugation_jacobian"]


def _sandwich(j: Array, c: Array) -> Array:
    """``J C Jᵀ`` over leading axes."""
    return np.einsum("...ia,...ab,...jb->...ij", j, c, j)


def conjugation_jacobian(u: Array, mount: Array) -> Array:
    """``∂(m⁻¹ ∘ u ∘ m)/∂u`` (..., 3, 3) for increments ``u`` (..., 3)."""
    rot = np.eye(3)
    c, s = np.cos(mount[2]), np.sin(mount[2])
    rot[:2, :2] = [[c, s], [-s, c]]  # R(−m_θ)
    return rot @ se2.compose_jacobian(u, np.broadcast_to(mount, np.shape(u)))


def to_sensor_frame(inp: FilterInput, mount: Array) -> FilterInput:
    """The filter's input for the sensor's poses ``s = x ∘ m`` (see the module doc)."""
    m = np.asarray(mount, dtype=np.float64)
    u = se2.compose(se2.inverse(m), se2.compose(inp.u, np.broadcast_to(m, inp.u.shape)))
    a = se2.compose_jacobian(inp.x0, m)
    return replace(
        inp,
        u=u,
        sigma=_sandwich(conjugation_jacobian(inp.u, m), inp.sigma),
        x0=se2.compose(inp.x0, m),
        p0=a @ inp.p0 @ a.T,
    )


def to_robot_frame(poses: Array, covariances: Array, mount: Array) -> tuple[Array, Array]:
    """Sensor poses (N, 3) and covariances (N, 3, 3) back to the robot: ``x = s ∘ m⁻¹``."""
    mi = np.broadcast_to(se2.inverse(np.asarray(mount, dtype=np.float64)), poses.shape)
    b = se2.compose_jacobian(poses, mi)
    return se2.compose(poses, mi), _sandwich(b, covariances)


def loadings_to_robot_frame(poses: Array, loadings: Array, mount: Array) -> Array:
    """The sensor poses' (N, 3) map loadings ``V`` (N, 3, r) for the robot's poses: ``B V``
    with ``B`` the Jacobian of :func:`to_robot_frame` (so ``B V Vᵀ Bᵀ`` is its covariance
    term)."""
    mi = np.broadcast_to(se2.inverse(np.asarray(mount, dtype=np.float64)), poses.shape)
    return se2.compose_jacobian(poses, mi) @ loadings
