"""SE(2) algebra as vectorised free functions over ``(..., 3)`` arrays.

A pose is ``[x, y, θ]``: the rigid transform ``T(p) = [[R(θ), t], [0, 1]]`` with
``t = (x, y)``, mapping points of the pose's (body) frame into the parent frame.
Every function broadcasts over leading axes, so one call handles one pose, ``(N, 3)``
trajectories or any ``(..., 3)`` stack; nothing loops in Python.

Conventions (used throughout slamrel):

* composition ``a ∘ b`` (``compose``) is the matrix product ``T(a) T(b)``;
* ``between(a, b) = a⁻¹ ∘ b`` is the motion from ``a`` to ``b`` expressed in the frame of ``a``
  (Kümmerle et al. 2009 write it ``δ_ij = x_j ⊖ x_i``);
* ``ominus(a, b) = b⁻¹ ∘ a`` is the error of ``a`` with respect to ``b`` in the frame of ``b``;
  ``minus(a, b)`` is the plain vector difference ``a − b`` with the heading wrapped (not ⊖);
* ``exp``/``log`` map between the tangent vector ``ξ = [ρ_x, ρ_y, φ]`` (translation part in
  the left-Jacobian coordinates) and the group, so ``exp(log(p)) == p`` for ``θ ∈ [−π, π)``;
* all angles are wrapped to ``[−π, π)`` by :func:`wrap_angle`, the only place that does so.

The derivatives live here too, next to the operations they differentiate: ``between(a, b,
jacobians=True)``, :func:`compose_jacobian` (and :func:`shear`, the same matrix written with
the world-frame step), and :func:`v_coefficients` (``sin φ/φ``, ``(1 − cos φ)/φ`` and their
derivatives, with one small-angle cut-off).
"""

from __future__ import annotations

import math
from typing import Literal, overload

import numpy as np
from numpy.typing import ArrayLike

from relation_metric.arrays import Array

__all__ = [
    "wrap_angle_float",
    "wrap_angle",
    "compose",
    "inverse",
    "between",
    "compose_jacobian",
    "shear",
    "v_coefficients",
    "ominus",
    "minus",
    "exp",
    "log",
    "transform_points",
    "inverse_transform_points",
    "to_matrix",
    "from_matrix",
    "cumulative_compose",
]

_TWO_PI = 2.0 * np.pi
# Below this |φ| the Taylor series (up to φ⁴) of sin φ/φ, (1 − cos φ)/φ and their derivatives
# are used. Measured against 40-digit mpmath over |φ| in [1e-7, 0.5]: the largest relative
# error of the four is 4.1e-12 (of d/dφ sin φ/φ, cancellation in φ cos φ − sin φ just above
# the cut-off; 9.8e-13 for (1 − cos φ)/φ); a cut-off of 1e-4 gave 9.9e-9 for (1 − cos φ)/φ
# and 4.2e-8 for its derivative, 3e-2 gives 7.7e-13, 5e-2 1e-12 (series truncation grows).
_SMALL_ANGLE = 1e-2


def wrap_angle(angle: ArrayLike) -> Array:
    """Wrap angles to ``[−π, π)``.

    ``wrap(a) = a − 2π ⌊(a + π) / 2π⌋``; angles already in ``[−π, π)`` are returned bit for
    bit, others are reduced stably even for large multiples of 2π.

    Parameters
    ----------
    angle : array_like, shape (...)
        Angles in radians.

    Returns
    -------
    ndarray, shape (...)
        The wrapped angles, float64.
    """
    a = np.asarray(angle, dtype=np.float64)
    # Angles already in range are returned unchanged (a + π would round π − 1 ulp to 2π);
    # only the others go through the reduction (one pass over the rest on the hot path).
    out = np.array(a, dtype=np.float64, copy=True)
    far = ~((a >= -np.pi) & (a < np.pi))
    if out.ndim == 0:
        return _reduce_angle(out) if far else out
    if far.any():
        out[far] = _reduce_angle(a[far])
    return out


def wrap_angle_float(angle: float) -> float:
    """:func:`wrap_angle` of one Python float, bit for bit, without numpy.

    For scalar loops (the EKF's per-measurement code), where numpy's per-call overhead is
    many times the arithmetic (benchmarks/README.md). Same formula: Python's ``%`` on
    floats folds C's ``fmod`` onto the divisor's sign like ``np.mod``; non-finite angles go
    to :func:`wrap_angle`.

    Parameters
    ----------
    angle : float

    Returns
    -------
    float
        In ``[−π, π)`` (NaN for a non-finite angle).
    """
    if -math.pi <= angle < math.pi:
        return angle
    if not math.isfinite(angle):
        return float(wrap_angle(angle))
    r = (angle + math.pi) % _TWO_PI - math.pi
    return r - _TWO_PI if r >= math.pi else r  # % can round to exactly 2π: fold it back


def _reduce_angle(a: Array) -> Array:
    wrapped = np.mod(a + np.pi, _TWO_PI) - np.pi
    # np.mod can return exactly 2π for tiny negative inputs through rounding; fold it back.
    return np.where(wrapped >= np.pi, wrapped - _TWO_PI, wrapped)


def _as_poses(p: ArrayLike, name: str = "pose") -> Array:
    arr = np.asarray(p, dtype=np.float64)
    if arr.shape[-1:] != (3,):
        raise ValueError(f"{name} must have shape (..., 3) [x, y, theta], got {arr.shape}")
    return arr


def compose(a: ArrayLike, b: ArrayLike) -> Array:
    """Composition ``a ∘ b`` (``T(a) T(b)``).

    ``[x_a + c_a x_b − s_a y_b, y_a + s_a x_b + c_a y_b, wrap(θ_a + θ_b)]``.

    Parameters
    ----------
    a, b : array_like, shape (..., 3)
        Poses; leading axes broadcast.

    Returns
    -------
    ndarray, shape (..., 3)
    """
    a = _as_poses(a, "a")
    b = _as_poses(b, "b")
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 0] + c * b[..., 0] - s * b[..., 1]
    out[..., 1] = a[..., 1] + s * b[..., 0] + c * b[..., 1]
    out[..., 2] = wrap_angle(a[..., 2] + b[..., 2])
    return out


def inverse(a: ArrayLike) -> Array:
    """Inverse ``a⁻¹``: ``[−c x − s y, s x − c y, wrap(−θ)]``.

    Parameters
    ----------
    a : array_like, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 3)
    """
    a = _as_poses(a, "a")
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    out = np.empty_like(a)
    out[..., 0] = -c * a[..., 0] - s * a[..., 1]
    out[..., 1] = s * a[..., 0] - c * a[..., 1]
    out[..., 2] = wrap_angle(-a[..., 2])
    return out


@overload
def between(a: ArrayLike, b: ArrayLike, *, jacobians: Literal[False] = ...) -> Array: ...


@overload
def between(
    a: ArrayLike, b: ArrayLike, *, jacobians: Literal[True]
) -> tuple[Array, Array, Array]: ...


def between(
    a: ArrayLike, b: ArrayLike, *, jacobians: bool = False
) -> Array | tuple[Array, Array, Array]:
    """Relative motion ``a⁻¹ ∘ b``: pose ``b`` expressed in the frame of pose ``a``.

    This is the relation ``δ_ij = x_i⁻¹ ∘ x_j`` of Kümmerle et al. 2009 (their Eq. 1 writes
    it ``x_j ⊖ x_i``). Computed directly as
    ``[c Δx + s Δy, −s Δx + c Δy, wrap(θ_b − θ_a)]`` with ``Δ = t_b − t_a``, ``c, s`` of ``θ_a``.

    Parameters
    ----------
    a, b : array_like, shape (..., 3)
    jacobians : bool, keyword-only
        Also return the derivatives (of the unwrapped angle difference, i.e. the ones a
        least-squares residual ``between(a, b) − z`` needs).

    Returns
    -------
    d : ndarray, shape (..., 3)
    j_a : ndarray, shape (..., 3, 3), only with ``jacobians=True``
        ``∂d/∂a = [[−c, −s, −s Δx + c Δy], [s, −c, −c Δx − s Δy], [0, 0, −1]]``.
    j_b : ndarray, shape (..., 3, 3), only with ``jacobians=True``
        ``∂d/∂b = [[c, s, 0], [−s, c, 0], [0, 0, 1]]``.
    """
    a = _as_poses(a, "a")
    b = _as_poses(b, "b")
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    dx = b[..., 0] - a[..., 0]
    dy = b[..., 1] - a[..., 1]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = c * dx + s * dy
    out[..., 1] = -s * dx + c * dy
    out[..., 2] = wrap_angle(b[..., 2] - a[..., 2])
    if not jacobians:
        return out
    shape = out.shape[:-1] + (3, 3)
    c, s = np.broadcast_to(c, shape[:-2]), np.broadcast_to(s, shape[:-2])
    j_a = np.zeros(shape)
    j_a[..., 0, 0], j_a[..., 0, 1], j_a[..., 0, 2] = -c, -s, -s * dx + c * dy
    j_a[..., 1, 0], j_a[..., 1, 1], j_a[..., 1, 2] = s, -c, -c * dx - s * dy
    j_a[..., 2, 2] = -1.0
    j_b = np.zeros(shape)
    j_b[..., 0, 0], j_b[..., 0, 1] = c, s
    j_b[..., 1, 0], j_b[..., 1, 1] = -s, c
    j_b[..., 2, 2] = 1.0
    return out, j_a, j_b


def compose_jacobian(a: ArrayLike, b: ArrayLike) -> Array:
    """``∂(a ∘ b)/∂a = [[1, 0, −Δy], [0, 1, Δx], [0, 0, 1]]`` with ``Δ = R(θ_a) t_b``.

    (``∂(a ∘ b)/∂b`` is ``blockdiag(R(θ_a), 1)``.)

    Parameters
    ----------
    a, b : array_like, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    d = np.stack((c * b[..., 0] - s * b[..., 1], s * b[..., 0] + c * b[..., 1]), axis=-1)
    return shear(d)


def shear(d: ArrayLike) -> Array:
    """``S(d) = [[1, 0, −d_y], [0, 1, d_x], [0, 0, 1]]``: :func:`compose_jacobian` from the step.

    ``d`` is the world-frame translation ``t(a ∘ b) − t(a)`` of the composition.

    Parameters
    ----------
    d : array_like, shape (..., 2) (or (..., 3); the angle is not used)

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    d = np.asarray(d, dtype=np.float64)
    out = np.broadcast_to(np.eye(3), d.shape[:-1] + (3, 3)).copy()
    out[..., 0, 2] = -d[..., 1]
    out[..., 1, 2] = d[..., 0]
    return out


def ominus(a: ArrayLike, b: ArrayLike) -> Array:
    """Error of ``a`` with respect to ``b``: ``b⁻¹ ∘ a`` (in the frame of ``b``).

    Kümmerle et al. 2009, Eq. 2 uses ``δ_ij ⊖ δ*_ij``; with this function the error of an
    estimated relation ``d`` against its reference ``d*`` is ``ominus(d, d_ref)``.

    Parameters
    ----------
    a, b : array_like, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 3)
    """
    return between(b, a)


def minus(a: ArrayLike, b: ArrayLike) -> Array:
    """The vector difference of poses with the heading wrapped: ``a − b``, shape (..., 3).

    ``[x_a − x_b, y_a − y_b, wrap(θ_a − θ_b)]`` (:func:`wrap_angle`), a difference of
    parameter vectors in the parent frame — an error against a truth, a residual taken in the
    global frame, a tree parameter. It is **not** the group's ⊖: :func:`ominus` is
    ``b⁻¹ ∘ a``, whose translation is expressed in the frame of ``b``; the two agree on the
    heading and on the translation only when ``θ_b = 0``. Broadcasts like ``a − b``.

    Parameters
    ----------
    a, b : array_like, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 3)
        A new float64 array.
    """
    d = np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)
    d[..., 2] = wrap_angle(d[..., 2])
    return d


def exp(xi: ArrayLike) -> Array:
    """Exponential map ``se(2) → SE(2)``.

    ``exp([ρ, φ]) = [V(φ) ρ, φ]`` with ``V(φ) = [[sin φ/φ, −(1 − cos φ)/φ],
    [(1 − cos φ)/φ, sin φ/φ]]`` (the left Jacobian of SO(2)); ``V → I`` as ``φ → 0``.

    Parameters
    ----------
    xi : array_like, shape (..., 3)
        Tangent vectors ``[ρ_x, ρ_y, φ]``.

    Returns
    -------
    ndarray, shape (..., 3)
        Poses; the angle is wrapped to ``[−π, π)``.
    """
    xi = _as_poses(xi, "xi")
    phi = xi[..., 2]
    a, b = v_coefficients(phi)
    out = np.empty_like(xi)
    out[..., 0] = a * xi[..., 0] - b * xi[..., 1]
    out[..., 1] = b * xi[..., 0] + a * xi[..., 1]
    out[..., 2] = wrap_angle(phi)
    return out


def log(p: ArrayLike) -> Array:
    """Logarithm map ``SE(2) → se(2)``, the inverse of :func:`exp` for ``θ ∈ [−π, π)``.

    ``log([t, θ]) = [V(θ)⁻¹ t, θ]``; ``V⁻¹ = 1/(A² + B²) [[A, B], [−B, A]]`` with
    ``A = sin θ/θ`` and ``B = (1 − cos θ)/θ``.

    Parameters
    ----------
    p : array_like, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 3)
    """
    p = _as_poses(p, "p")
    phi = wrap_angle(p[..., 2])
    a, b = v_coefficients(phi)
    det = a * a + b * b
    out = np.empty_like(p)
    out[..., 0] = (a * p[..., 0] + b * p[..., 1]) / det
    out[..., 1] = (-b * p[..., 0] + a * p[..., 1]) / det
    out[..., 2] = phi
    return out


@overload
def v_coefficients(phi: ArrayLike, *, derivatives: Literal[False] = ...) -> tuple[Array, Array]: ...


@overload
def v_coefficients(
    phi: ArrayLike, *, derivatives: Literal[True]
) -> tuple[Array, Array, Array, Array]: ...


def v_coefficients(
    phi: ArrayLike, *, derivatives: bool = False
) -> tuple[Array, Array] | tuple[Array, Array, Array, Array]:
    """``A = sin φ/φ``, ``B = (1 − cos φ)/φ`` (the entries of ``V(φ)``) and their derivatives.

    Below ``|φ| < 1e-2`` their Taylor series up to ``φ⁴`` are used; the largest relative error
    (against 40-digit arithmetic, ``|φ| ∈ [1e-7, 0.5]``) is 4.1e-12 (``dA/dφ``), 9.8e-13 (``B``).

    Parameters
    ----------
    phi : array_like, shape (...)
    derivatives : bool, keyword-only
        Also return ``dA/dφ`` and ``dB/dφ``.

    Returns
    -------
    a, b : ndarray, shape (...)
    da, db : ndarray, shape (...), only with ``derivatives=True``
    """
    phi = np.asarray(phi, dtype=np.float64)
    small = np.abs(phi) < _SMALL_ANGLE
    p = np.where(small, 1.0, phi)
    s, c = np.sin(p), np.cos(p)
    phi2 = phi * phi
    phi4 = phi2 * phi2
    a = np.where(small, 1.0 - phi2 / 6.0 + phi4 / 120.0, s / p)
    b = np.where(small, phi * (0.5 - phi2 / 24.0 + phi4 / 720.0), (1.0 - c) / p)
    if not derivatives:
        return a, b
    da = np.where(small, phi * (-1.0 / 3.0 + phi2 / 30.0 - phi4 / 840.0), (p * c - s) / (p * p))
    db = np.where(small, 0.5 - phi2 / 8.0 + phi4 / 144.0, (p * s - (1.0 - c)) / (p * p))
    return a, b, da, db


def transform_points(p: ArrayLike, points: ArrayLike) -> Array:
    """Map points from the frame of pose ``p`` into the parent frame: ``R(θ) q + t``.

    Parameters
    ----------
    p : array_like, shape (..., 3)
    points : array_like, shape (..., 2)
        Leading axes broadcast against those of ``p``.

    Returns
    -------
    ndarray, shape (..., 2)
    """
    p = _as_poses(p, "p")
    q = np.asarray(points, dtype=np.float64)
    if q.shape[-1:] != (2,):
        raise ValueError(f"points must have shape (..., 2), got {q.shape}")
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    out = np.empty(np.broadcast_shapes(p.shape[:-1], q.shape[:-1]) + (2,))
    out[..., 0] = p[..., 0] + c * q[..., 0] - s * q[..., 1]
    out[..., 1] = p[..., 1] + s * q[..., 0] + c * q[..., 1]
    return out


def inverse_transform_points(p: ArrayLike, points: ArrayLike) -> Array:
    """Express parent-frame points in the frame of pose ``p``: ``R(θ)ᵀ (q − t)``.

    This is ``p⁻¹ · l``, the landmark-in-pose-frame relation of the landmark graph.

    Parameters
    ----------
    p : array_like, shape (..., 3)
    points : array_like, shape (..., 2)

    Returns
    -------
    ndarray, shape (..., 2)
    """
    p = _as_poses(p, "p")
    q = np.asarray(points, dtype=np.float64)
    if q.shape[-1:] != (2,):
        raise ValueError(f"points must have shape (..., 2), got {q.shape}")
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    dx = q[..., 0] - p[..., 0]
    dy = q[..., 1] - p[..., 1]
    out = np.empty(np.broadcast_shapes(p.shape[:-1], q.shape[:-1]) + (2,))
    out[..., 0] = c * dx + s * dy
    out[..., 1] = -s * dx + c * dy
    return out


def to_matrix(p: ArrayLike) -> Array:
    """Homogeneous matrices ``[[c, −s, x], [s, c, y], [0, 0, 1]]``, shape ``(..., 3, 3)``."""
    p = _as_poses(p, "p")
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    m = np.zeros(p.shape[:-1] + (3, 3))
    m[..., 0, 0] = c
    m[..., 0, 1] = -s
    m[..., 1, 0] = s
    m[..., 1, 1] = c
    m[..., 0, 2] = p[..., 0]
    m[..., 1, 2] = p[..., 1]
    m[..., 2, 2] = 1.0
    return m


def from_matrix(m: ArrayLike) -> Array:
    """Poses from homogeneous matrices ``(..., 3, 3)``; the angle is ``atan2(m10, m00)``."""
    m = np.asarray(m, dtype=np.float64)
    if m.shape[-2:] != (3, 3):
        raise ValueError(f"matrices must have shape (..., 3, 3), got {m.shape}")
    out = np.empty(m.shape[:-2] + (3,))
    out[..., 0] = m[..., 0, 2]
    out[..., 1] = m[..., 1, 2]
    out[..., 2] = np.arctan2(m[..., 1, 0], m[..., 0, 0])
    return wrap_last(out)


def wrap_last(p: Array) -> Array:
    """Return ``p`` with its angle column wrapped (helper for readers and constructors)."""
    out = np.array(p, dtype=np.float64, copy=True)
    out[..., 2] = wrap_angle(out[..., 2])
    return out


def cumulative_compose(increments: ArrayLike, start: ArrayLike | None = None) -> Array:
    """Chain relative motions: ``x_0 = start``, ``x_{k+1} = x_k ∘ u_k``, vectorised.

    The heading is a cumulative sum; each translation increment is rotated by the heading
    before it and the results are cumulatively summed, so no Python loop runs over steps.

    Parameters
    ----------
    increments : array_like, shape (K, 3)
        Relative motions ``u_k`` in the frame of ``x_k``.
    start : array_like, shape (3,), optional
        The first pose; the origin when omitted.

    Returns
    -------
    ndarray, shape (K + 1, 3)
    """
    u = _as_poses(increments, "increments")
    if u.ndim != 2:
        raise ValueError(f"increments must have shape (K, 3), got {u.shape}")
    x0 = np.zeros(3) if start is None else _as_poses(start, "start").reshape(3)
    heading = x0[2] + np.concatenate(([0.0], np.cumsum(u[:, 2])))
    c, s = np.cos(heading[:-1]), np.sin(heading[:-1])
    out = np.empty((u.shape[0] + 1, 3))
    out[0] = x0
    out[1:, 0] = x0[0] + np.cumsum(c * u[:, 0] - s * u[:, 1])
    out[1:, 1] = x0[1] + np.cumsum(s * u[:, 0] + c * u[:, 1])
    out[:, 2] = wrap_angle(heading)
    return out
