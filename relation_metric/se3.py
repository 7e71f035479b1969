"""SE(3) algebra as vectorised free functions over ``(..., 7)`` arrays.

A pose is ``[x, y, z, qx, qy, qz, qw]`` (the TUM column order): the rigid transform
``T(p) = [[R(q), t], [0, 1]]`` with ``t = (x, y, z)`` and the unit quaternion ``q`` (Hamilton
convention, scalar last), mapping points of the pose's (body) frame into the parent frame.
Every function broadcasts over leading axes; nothing loops in Python. The conventions are
those of :mod:`relation_metric.se2`:

* ``compose(a, b) = T(a) T(b)``; ``between(a, b) = a⁻¹ ∘ b``; ``ominus(a, b) = b⁻¹ ∘ a``;
* ``exp``/``log`` map between ``ξ = [ρ, ω]`` (shape ``(..., 6)``: translation part in the
  left-Jacobian coordinates, then the rotation vector) and the group;
* quaternions ``q`` and ``−q`` are the same rotation; functions return either sign, and
  :func:`normalize` makes ``qw ≥ 0`` (what trajectories store).

Euler angles (:func:`euler_zyx`, :func:`from_euler_zyx`) are ``[roll, pitch, yaw]`` with
``R = R_z(yaw) R_y(pitch) R_x(roll)``, the convention of the Freiburg ``.relations`` files and
of the metricEvaluator's parameter vector.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from relation_metric.arrays import Array

__all__ = [
    "identity",
    "normalize",
    "quat_multiply",
    "quat_conjugate",
    "quat_rotate",
    "compose",
    "inverse",
    "between",
    "ominus",
    "rotation_vector",
    "quat_from_rotation_vector",
    "rotation_angle",
    "exp",
    "log",
    "euler_zyx",
    "from_euler_zyx",
    "from_planar",
    "to_planar",
    "to_matrix",
    "from_matrix",
    "transform_points",
]

# Below this angle [rad] the Taylor series of the exp/log coefficients are used.
_SMALL = 1e-4


def _as_poses(p: ArrayLike, name: str = "pose") -> Array:
    arr = np.asarray(p, dtype=np.float64)
    if arr.shape[-1:] != (7,):
        raise ValueError(
            f"{name} must have shape (..., 7) [x, y, z, qx, qy, qz, qw], got {arr.shape}"
        )
    return arr


def identity(shape: tuple[int, ...] = ()) -> Array:
    """Identity poses, shape ``shape + (7,)``."""
    out = np.zeros(shape + (7,))
    out[..., 6] = 1.0
    return out


def normalize(p: ArrayLike) -> Array:
    """Poses with unit quaternions and ``qw ≥ 0`` (a copy), shape ``(..., 7)``."""
    p = np.array(_as_poses(p), dtype=np.float64, copy=True)
    q = p[..., 3:7]
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    q *= np.where(q[..., 3:4] < 0.0, -1.0, 1.0)
    return p


def quat_multiply(a: ArrayLike, b: ArrayLike) -> Array:
    """Hamilton product ``a b`` of quaternions ``[x, y, z, w]``, shape ``(..., 4)``."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    x1, y1, z1, w1 = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    x2, y2, z2, w2 = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2
    out[..., 1] = w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2
    out[..., 2] = w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2
    out[..., 3] = w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2
    return out


def quat_conjugate(q: ArrayLike) -> Array:
    """``[−x, −y, −z, w]``: the inverse rotation of a unit quaternion."""
    out = np.array(q, dtype=np.float64, copy=True)
    out[..., :3] *= -1.0
    return out


def _cross(a0: Array, a1: Array, a2: Array, b0: Array, b1: Array, b2: Array) -> tuple:
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


def quat_rotate(q: ArrayLike, v: ArrayLike) -> Array:
    """Rotate vectors ``v`` (``(..., 3)``) by unit quaternions ``q`` (``(..., 4)``).

    ``v' = v + w τ + u × τ`` with ``τ = 2 u × v`` and ``q = [u, w]``.
    """
    q = np.asarray(q, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    ux, uy, uz, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    vx, vy, vz = v[..., 0], v[..., 1], v[..., 2]
    tx, ty, tz = _cross(ux, uy, uz, vx, vy, vz)
    tx, ty, tz = 2.0 * tx, 2.0 * ty, 2.0 * tz
    cx, cy, cz = _cross(ux, uy, uz, tx, ty, tz)
    out = np.empty(np.broadcast_shapes(q.shape[:-1], v.shape[:-1]) + (3,))
    out[..., 0] = vx + w * tx + cx
    out[..., 1] = vy + w * ty + cy
    out[..., 2] = vz + w * tz + cz
    return out


def compose(a: ArrayLike, b: ArrayLike) -> Array:
    """Composition ``a ∘ b`` (``T(a) T(b)``): ``[t_a + R_a t_b, q_a q_b]``, shape (..., 7)."""
    a = _as_poses(a, "a")
    b = _as_poses(b, "b")
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., :3] = a[..., :3] + quat_rotate(a[..., 3:], b[..., :3])
    out[..., 3:] = quat_multiply(a[..., 3:], b[..., 3:])
    return out


def inverse(a: ArrayLike) -> Array:
    """Inverse ``a⁻¹ = [−Rᵀ t, q*]``, shape (..., 7)."""
    a = _as_poses(a, "a")
    qc = quat_conjugate(a[..., 3:])
    out = np.empty_like(a)
    out[..., :3] = -quat_rotate(qc, a[..., :3])
    out[..., 3:] = qc
    return out


def between(a: ArrayLike, b: ArrayLike) -> Array:
    """Relative motion ``a⁻¹ ∘ b = [R_aᵀ (t_b − t_a), q_a* q_b]`` (``δ_ij`` of the paper)."""
    a = _as_poses(a, "a")
    b = _as_poses(b, "b")
    qc = quat_conjugate(a[..., 3:])
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., :3] = quat_rotate(qc, b[..., :3] - a[..., :3])
    out[..., 3:] = quat_multiply(qc, b[..., 3:])
    return out


def ominus(a: ArrayLike, b: ArrayLike) -> Array:
    """Error of ``a`` with respect to ``b``: ``b⁻¹ ∘ a`` (in the frame of ``b``)."""
    return between(b, a)


def rotation_angle(q: ArrayLike) -> Array:
    """Rotation angle in ``[0, π]`` of quaternions ``(..., 4)``: ``2 atan2(‖u‖, |w|)``.

    Accurate for small and large angles alike (no ``arccos`` of a trace).
    """
    q = np.asarray(q, dtype=np.float64)
    return 2.0 * np.arctan2(np.linalg.norm(q[..., :3], axis=-1), np.abs(q[..., 3]))


def rotation_vector(q: ArrayLike) -> Array:
    """Rotation vectors ``ω = θ n`` (``|ω| ≤ π``) of quaternions ``(..., 4)``, shape (..., 3)."""
    q = np.asarray(q, dtype=np.float64)
    sign = np.where(q[..., 3] < 0.0, -1.0, 1.0)[..., None]
    u, w = q[..., :3] * sign, np.abs(q[..., 3])
    n = np.linalg.norm(u, axis=-1)
    small = n < _SMALL * np.maximum(w, 1e-300)
    safe_n = np.where(small, 1.0, n)
    safe_w = np.where(w > 0, w, 1.0)
    r2 = (n / safe_w) ** 2
    scale = np.where(small, 2.0 / safe_w * (1.0 - r2 / 3.0), 2.0 * np.arctan2(n, w) / safe_n)
    return u * scale[..., None]


def quat_from_rotation_vector(omega: ArrayLike) -> Array:
    """Unit quaternions ``[sin(θ/2) n, cos(θ/2)]`` of rotation vectors ``(..., 3)``."""
    omega = np.asarray(omega, dtype=np.float64)
    theta = np.linalg.norm(omega, axis=-1)
    small = theta < _SMALL
    safe = np.where(small, 1.0, theta)
    s = np.where(small, 0.5 - theta * theta / 48.0, np.sin(0.5 * safe) / safe)
    out = np.empty(omega.shape[:-1] + (4,))
    out[..., :3] = omega * s[..., None]
    out[..., 3] = np.cos(0.5 * theta)
    return out


def _v_apply(omega: Array, v: Array, *, inverse: bool) -> Array:
    """``V(ω) v`` or ``V(ω)⁻¹ v`` (the left Jacobian of SO(3)), series near ``θ = 0``."""
    theta2 = np.sum(omega * omega, axis=-1)
    theta = np.sqrt(theta2)
    small = theta < _SMALL
    t = np.where(small, 1.0, theta)
    t2 = t * t
    wv = np.cross(omega, v)
    wwv = np.cross(omega, wv)
    if not inverse:
        b = np.where(small, 0.5 - theta2 / 24.0, (1.0 - np.cos(t)) / t2)
        c = np.where(small, 1.0 / 6.0 - theta2 / 120.0, (t - np.sin(t)) / (t2 * t))
        return v + b[..., None] * wv + c[..., None] * wwv
    half = 0.5 * t
    # (1 − (θ/2) cot(θ/2)) / θ², stable for θ → 0 by its series
    c = np.where(small, 1.0 / 12.0 + theta2 / 720.0, (1.0 - half / np.tan(half)) / t2)
    return v - 0.5 * wv + c[..., None] * wwv


def exp(xi: ArrayLike) -> Array:
    """Exponential map ``se(3) → SE(3)``: ``[V(ω) ρ, q(ω)]`` for ``ξ = [ρ, ω]`` (..., 6)."""
    xi = np.asarray(xi, dtype=np.float64)
    if xi.shape[-1:] != (6,):
        raise ValueError(f"xi must have shape (..., 6) [rho, omega], got {xi.shape}")
    out = np.empty(xi.shape[:-1] + (7,))
    out[..., :3] = _v_apply(xi[..., 3:], xi[..., :3], inverse=False)
    out[..., 3:] = quat_from_rotation_vector(xi[..., 3:])
    return out


def log(p: ArrayLike) -> Array:
    """Logarithm map ``SE(3) → se(3)``: ``[V(ω)⁻¹ t, ω]``, shape (..., 6); ``|ω| ≤ π``."""
    p = _as_poses(p, "p")
    omega = rotation_vector(p[..., 3:])
    out = np.empty(p.shape[:-1] + (6,))
    out[..., :3] = _v_apply(omega, p[..., :3], inverse=True)
    out[..., 3:] = omega
    return out


def euler_zyx(q: ArrayLike) -> Array:
    """``[roll, pitch, yaw]`` of quaternions ``(..., 4)`` with ``R = R_z R_y R_x``."""
    q = np.asarray(q, dtype=np.float64)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    out = np.empty(q.shape[:-1] + (3,))
    out[..., 0] = np.arctan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    out[..., 1] = np.arcsin(np.clip(2.0 * (w * y - z * x), -1.0, 1.0))
    out[..., 2] = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return out


def from_euler_zyx(rpy: ArrayLike) -> Array:
    """Unit quaternions ``(..., 4)`` of ``[roll, pitch, yaw]`` (``R = R_z R_y R_x``)."""
    rpy = np.asarray(rpy, dtype=np.float64)
    cr, sr = np.cos(rpy[..., 0] / 2), np.sin(rpy[..., 0] / 2)
    cp, sp = np.cos(rpy[..., 1] / 2), np.sin(rpy[..., 1] / 2)
    cy, sy = np.cos(rpy[..., 2] / 2), np.sin(rpy[..., 2] / 2)
    out = np.empty(rpy.shape[:-1] + (4,))
    out[..., 0] = sr * cp * cy - cr * sp * sy
    out[..., 1] = cr * sp * cy + sr * cp * sy
    out[..., 2] = cr * cp * sy - sr * sp * cy
    out[..., 3] = cr * cp * cy + sr * sp * sy
    return out


def from_planar(p: ArrayLike) -> Array:
    """Lift SE(2) poses ``[x, y, θ]`` (..., 3) to SE(3): ``[x, y, 0, 0, 0, sin θ/2, cos θ/2]``."""
    p = np.asarray(p, dtype=np.float64)
    out = np.zeros(p.shape[:-1] + (7,))
    out[..., 0:2] = p[..., 0:2]
    out[..., 5] = np.sin(0.5 * p[..., 2])
    out[..., 6] = np.cos(0.5 * p[..., 2])
    return out


def to_planar(p: ArrayLike) -> Array:
    """Project SE(3) poses onto the plane: ``[x, y, yaw]`` (drops z, roll, pitch)."""
    p = _as_poses(p, "p")
    out = np.empty(p.shape[:-1] + (3,))
    out[..., 0:2] = p[..., 0:2]
    out[..., 2] = euler_zyx(p[..., 3:])[..., 2]
    return out


def to_matrix(p: ArrayLike) -> Array:
    """Homogeneous matrices, shape ``(..., 4, 4)``."""
    p = _as_poses(p, "p")
    x, y, z, w = (p[..., k] for k in (3, 4, 5, 6))
    m = np.zeros(p.shape[:-1] + (4, 4))
    m[..., 0, 0] = 1 - 2 * (y * y + z * z)
    m[..., 0, 1] = 2 * (x * y - z * w)
    m[..., 0, 2] = 2 * (x * z + y * w)
    m[..., 1, 0] = 2 * (x * y + z * w)
    m[..., 1, 1] = 1 - 2 * (x * x + z * z)
    m[..., 1, 2] = 2 * (y * z - x * w)
    m[..., 2, 0] = 2 * (x * z - y * w)
    m[..., 2, 1] = 2 * (y * z + x * w)
    m[..., 2, 2] = 1 - 2 * (x * x + y * y)
    m[..., :3, 3] = p[..., :3]
    m[..., 3, 3] = 1.0
    return m


def from_matrix(m: ArrayLike) -> Array:
    """Poses ``(..., 7)`` from homogeneous ``(..., 4, 4)`` or ``(..., 3, 4)`` matrices.

    scipy's ``Rotation.from_matrix`` written in numpy (scipy.spatial costs start-up: the
    KITTI reader and every alignment call this): a rotation block whose ``R Rᵀ`` is not the
    identity (``isclose``, atol 1e-12) is orthonormalised as ``U Vᵀ`` of its SVD, then the
    quaternion is taken by Markley's rule from the largest of the diagonal and the trace;
    ``qw ≥ 0``. A block with a non-positive determinant is refused (ValueError), as scipy's.
    """
    m = np.asarray(m, dtype=np.float64)
    if m.shape[-2:] not in ((4, 4), (3, 4)):
        raise ValueError(f"matrices must have shape (..., 4, 4) or (..., 3, 4), got {m.shape}")
    lead = m.shape[:-2]
    r = m[..., :3, :3].reshape(-1, 3, 3).copy()
    if r.shape[0] and not (np.linalg.det(r) > 0).all():
        raise ValueError("non-positive determinant (left-handed or null frame) in a rotation")
    if r.shape[0]:
        gram = r @ np.swapaxes(r, 1, 2)
        bent = ~np.isclose(gram, np.eye(3), atol=1e-12).all(axis=(1, 2))
        if bent.any():
            u, _, vt = np.linalg.svd(r[bent], full_matrices=False)
            r[bent] = u @ vt
    out = np.empty(lead + (7,))
    out[..., :3] = m[..., :3, 3]
    out[..., 3:] = _markley(r).reshape(lead + (4,))
    return normalize(out)


def _markley(r: Array) -> Array:
    """Unit quaternions ``(N, 4)`` ``[qx, qy, qz, qw]`` of rotation matrices ``(N, 3, 3)``,
    each from the largest of ``R_00, R_11, R_22, tr R`` (the best-conditioned formula)."""
    tr = r[:, 0, 0] + r[:, 1, 1] + r[:, 2, 2]
    choice = np.argmax(np.stack((r[:, 0, 0], r[:, 1, 1], r[:, 2, 2], tr), axis=1), axis=1)
    q = np.stack(
        (r[:, 2, 1] - r[:, 1, 2], r[:, 0, 2] - r[:, 2, 0], r[:, 1, 0] - r[:, 0, 1], 1 + tr),
        axis=1,
    )
    for i in range(3):  # three cases, each vectorised over its poses
        k = np.flatnonzero(choice == i)
        if k.size:
            j, l = (i + 1) % 3, (i + 2) % 3
            q[k, i] = 1 - tr[k] + 2 * r[k, i, i]
            q[k, j] = r[k, j, i] + r[k, i, j]
            q[k, l] = r[k, l, i] + r[k, i, l]
            q[k, 3] = r[k, l, j] - r[k, j, l]
    return q / np.linalg.norm(q, axis=1)[:, None]


def transform_points(p: ArrayLike, points: ArrayLike) -> Array:
    """Map points ``(..., 3)`` from the frame of ``p`` into the parent frame: ``R q + t``."""
    p = _as_poses(p, "p")
    return p[..., :3] + quat_rotate(p[..., 3:], points)
