"""Motion and sensor models of the SLAM result bundle, with analytic Jacobians.

Every motion model is written as a composition ``x_{k+1} = x_k ∘ u_k`` (``relation_metric.se2``)
with a body-frame increment ``u_k = [dx, dy, dθ]`` and a 3 × 3 covariance ``Σ_k`` of that
increment; the EKF then needs only ``F = ∂(x ∘ u)/∂x`` (a shear) and ``Q = Rot(θ) Σ Rot(θ)ᵀ``.

Velocity model (Thrun, Burgard & Fox, *Probabilistic Robotics*, Sec. 5.3, exact arc)
    ``u(v, ω, Δt) = exp([v Δt, 0, ω Δt]) = [v Δt A(φ), v Δt B(φ), φ]`` with ``φ = ω Δt``,
    ``A = sin φ / φ`` and ``B = (1 − cos φ) / φ`` (straight line ``[v Δt, 0, 0]`` as ω → 0, by
    Taylor series below ``|φ| < 1e-2``: :func:`relation_metric.se2.v_coefficients`). This equals
    the book's Eq. 5.9 arc. Control noise
    ``M = diag(σ_v², σ_ω²)`` or (Table 5.3) ``diag(α1 v² + α2 ω², α3 v² + α4 ω²)``, held over
    Δt, gives ``Σ = J_u M J_uᵀ`` with ``J_u = ∂u/∂(v, ω)`` (rank 2).

Odometry model (Probabilistic Robotics, Sec. 5.4)
    ``u = o_k⁻¹ ∘ o_{k+1}``; ``δrot1 = atan2(u_y, u_x)``, ``δtrans = ‖u_xy‖``,
    ``δrot2 = wrap(u_θ − δrot1)`` (``δrot1 = 0`` when ``δtrans`` is 0). Noise either
    ``diag(σ_x², σ_y², σ_θ²)`` on ``u`` directly, or (Table 5.6) variances
    ``[α1 δrot1² + α2 δtrans², α3 δtrans² + α4 (δrot1² + δrot2²), α1 δrot2² + α2 δtrans²]``
    on ``δ`` mapped to ``u`` with ``J = ∂u/∂δ``.

Range-bearing sensor
    ``h(x, l) = [‖l − p‖, wrap(atan2(l_y − p_y, l_x − p_x) − θ)]`` with Jacobians ``H_x`` (2 × 3)
    and ``H_l`` (2 × 2).

All functions are vectorised over leading axes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from relation_metric import se2
from relation_metric.arrays import Array
from relation_metric.errors import InputError

__all__ = [
    "MotionModel",
    "SensorModel",
    "velocity_increment",
    "velocity_control_covariance",
    "odometry_deltas",
    "odometry_from_deltas",
    "odometry_delta_covariance",
    "increment_covariance",
    "process_noise",
    "range_bearing",
]

MOTION_TYPES = ("velocity", "odometry")
#: The ``sigma`` entries of each motion model, in order (``bundle.json`` keys).
SIGMA_NAMES = {
    "velocity": ("sigma_v", "sigma_omega"),
    "odometry": ("sigma_x", "sigma_y", "sigma_theta"),
}


def _nonnegative_numbers(values: object, size: int, *, what: str) -> tuple[float, ...]:
    """``values`` as ``size`` finite floats ≥ 0, or :class:`InputError` naming ``what``."""
    try:
        out = tuple(float(v) for v in values)  # type: ignore[attr-defined]
    except (TypeError, ValueError):
        raise InputError(f"{what}: expected {size} numbers, got {values!s:.60}") from None
    if len(out) != size:
        raise InputError(f"{what}: expected {size} numbers, got {len(out)}")
    bad = [v for v in out if not (math.isfinite(v) and v >= 0.0)]
    if bad:
        raise InputError(f"{what}: expected finite numbers >= 0, got {bad[0]:g}")
    return out


@dataclass(frozen=True)
class MotionModel:
    """A motion model of the bundle.

    Attributes
    ----------
    type : {"velocity", "odometry"}
    sigma : tuple of float or None
        ``(σ_v, σ_ω)`` for velocity, ``(σ_x, σ_y, σ_θ)`` for odometry.
    alpha : tuple of float or None
        ``(α1, α2, α3, α4)`` of Probabilistic Robotics Table 5.3 / 5.6.

    Exactly one of ``sigma`` and ``alpha`` is set; each is stored as a tuple of float.

    Raises
    ------
    InputError
        When ``type`` is not one of :data:`MOTION_TYPES` (``"Velocity"`` is refused, not run
        as odometry), when neither or both of ``sigma`` and ``alpha`` are given, or when one of
        them has the wrong length or a negative or non-finite entry; the message names the
        field.
    """

    type: str
    sigma: tuple[float, ...] | None = None
    alpha: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        if self.type not in MOTION_TYPES:
            raise InputError(
                f"motion_model.type: unknown type {self.type!r}; expected one of "
                f"{', '.join(MOTION_TYPES)}"
            )
        names = SIGMA_NAMES[self.type]
        if (self.sigma is None) == (self.alpha is None):
            raise InputError(
                f"motion_model ({self.type}): expected either sigma ({', '.join(names)}) or "
                "alpha (alpha1..alpha4), exactly one of them"
            )
        field_name, size = ("sigma", len(names)) if self.alpha is None else ("alpha", 4)
        values = _nonnegative_numbers(
            getattr(self, field_name), size, what=f"motion_model.{field_name} ({self.type})"
        )
        object.__setattr__(self, field_name, values)

    def as_dict(self) -> dict[str, object]:
        out: dict[str, object] = {"type": self.type}
        if self.alpha is not None:
            out["alpha"] = list(self.alpha)
        else:
            out.update(zip(SIGMA_NAMES[self.type], self.sigma or ()))
        return out


@dataclass(frozen=True)
class SensorModel:
    """Range-bearing sensor with independent Gaussian noise (standard deviations).

    Raises
    ------
    InputError
        When ``type`` is not ``"range_bearing"`` or a standard deviation is negative or not
        finite (zero is allowed in memory: a noise-free simulation); the message names the field.
    """

    sigma_range: float
    sigma_bearing: float
    type: str = "range_bearing"

    def __post_init__(self) -> None:
        if self.type != "range_bearing":
            raise InputError(
                f"sensor_model.type: unknown type {self.type!r}; expected range_bearing"
            )
        for name in ("sigma_range", "sigma_bearing"):
            (value,) = _nonnegative_numbers((getattr(self, name),), 1, what=f"sensor_model.{name}")
            object.__setattr__(self, name, value)

    @property
    def covariance(self) -> Array:
        """``diag(σ_r², σ_b²)``, shape (2, 2)."""
        return np.diag([self.sigma_range**2, self.sigma_bearing**2])

    def as_dict(self) -> dict[str, object]:
        return {
            "type": self.type,
            "sigma_range": self.sigma_range,
            "sigma_bearing": self.sigma_bearing,
        }


def velocity_increment(v: ArrayLike, omega: ArrayLike, dt: ArrayLike) -> tuple[Array, Array]:
    """Body-frame increment of the exact-arc velocity model and its Jacobian.

    Parameters
    ----------
    v, omega, dt : array_like, shape (...)
        Velocities held over ``dt`` seconds.

    Returns
    -------
    u : ndarray, shape (..., 3)
        ``[v Δt A(φ), v Δt B(φ), φ]``, ``φ = ω Δt`` (angle not wrapped).
    j_u : ndarray, shape (..., 3, 2)
        ``∂u/∂(v, ω)``.
    """
    v, omega, dt = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (v, omega, dt)))
    phi = omega * dt
    a, b, da, db = se2.v_coefficients(phi, derivatives=True)
    s = v * dt
    u = np.stack((s * a, s * b, phi), axis=-1)
    j = np.zeros(v.shape + (3, 2))
    j[..., 0, 0] = dt * a
    j[..., 1, 0] = dt * b
    j[..., 0, 1] = s * da * dt
    j[..., 1, 1] = s * db * dt
    j[..., 2, 1] = dt
    return u, j


def velocity_control_covariance(
    v: ArrayLike,
    omega: ArrayLike,
    *,
    sigma: tuple[float, ...] | None = None,
    alpha: tuple[float, ...] | None = None,
) -> Array:
    """Control covariance ``M`` (..., 2, 2): ``diag(σ_v², σ_ω²)`` or PR Table 5.3 with α."""
    v, omega = np.broadcast_arrays(np.asarray(v, float), np.asarray(omega, float))
    m = np.zeros(v.shape + (2, 2))
    if alpha is not None:
        a1, a2, a3, a4 = alpha
        m[..., 0, 0] = a1 * v * v + a2 * omega * omega
        m[..., 1, 1] = a3 * v * v + a4 * omega * omega
    else:
        assert sigma is not None
        m[..., 0, 0] = sigma[0] ** 2
        m[..., 1, 1] = sigma[1] ** 2
    return m


def odometry_deltas(u: ArrayLike) -> tuple[Array, Array]:
    """``δ = [δrot1, δtrans, δrot2]`` of relative motions and ``∂u/∂δ``.

    Parameters
    ----------
    u : array_like, shape (..., 3)
        Relative motions in the frame of the earlier pose.

    Returns
    -------
    delta : ndarray, shape (..., 3)
    j : ndarray, shape (..., 3, 3)
        Jacobian of :func:`odometry_from_deltas` at ``delta``.
    """
    u = np.asarray(u, dtype=np.float64)
    trans = np.hypot(u[..., 0], u[..., 1])
    rot1 = np.where(trans > 0.0, np.arctan2(u[..., 1], u[..., 0]), 0.0)
    rot2 = se2.wrap_angle(u[..., 2] - rot1)
    delta = np.stack((rot1, trans, rot2), axis=-1)
    return delta, _odometry_jacobian(delta)


def odometry_from_deltas(delta: ArrayLike) -> Array:
    """``u = [δtrans cos δrot1, δtrans sin δrot1, δrot1 + δrot2]`` (angle not wrapped)."""
    d = np.asarray(delta, dtype=np.float64)
    return np.stack(
        (d[..., 1] * np.cos(d[..., 0]), d[..., 1] * np.sin(d[..., 0]), d[..., 0] + d[..., 2]),
        axis=-1,
    )


def _odometry_jacobian(delta: Array) -> Array:
    c, s = np.cos(delta[..., 0]), np.sin(delta[..., 0])
    t = delta[..., 1]
    j = np.zeros(delta.shape[:-1] + (3, 3))
    j[..., 0, 0] = -t * s
    j[..., 0, 1] = c
    j[..., 1, 0] = t * c
    j[..., 1, 1] = s
    j[..., 2, 0] = 1.0
    j[..., 2, 2] = 1.0
    return j


def odometry_delta_covariance(delta: ArrayLike, alpha: tuple[float, ...]) -> Array:
    """PR Table 5.6 variances of ``δ`` as a diagonal matrix, shape (..., 3, 3)."""
    d = np.asarray(delta, dtype=np.float64)
    a1, a2, a3, a4 = alpha
    r1, t, r2 = d[..., 0] ** 2, d[..., 1] ** 2, d[..., 2] ** 2
    m = np.zeros(d.shape[:-1] + (3, 3))
    m[..., 0, 0] = a1 * r1 + a2 * t
    m[..., 1, 1] = a3 * t + a4 * (r1 + r2)
    m[..., 2, 2] = a1 * r2 + a2 * t
    return m


def increment_covariance(model: MotionModel, u: ArrayLike, aux: ArrayLike) -> Array:
    """Body-frame covariance ``Σ`` (..., 3, 3) of increments ``u``.

    Parameters
    ----------
    model : MotionModel
    u : array_like, shape (..., 3)
        The increments.
    aux : array_like
        Velocity model: the ``(..., 4)`` array ``[v, ω, Δt, scale]`` each increment came from
        (``scale`` multiplies ``M``); odometry model: ``(...,)`` scale on ``Σ``.
    """
    aux = np.asarray(aux, dtype=np.float64)
    if model.type == "velocity":
        v, w, dt, scale = np.moveaxis(aux, -1, 0)
        _, j = velocity_increment(v, w, dt)
        m = velocity_control_covariance(v, w, sigma=model.sigma, alpha=model.alpha)
        m = m * scale[..., None, None]
        return np.einsum("...ia,...ab,...jb->...ij", j, m, j)
    u = np.asarray(u, dtype=np.float64)
    if model.alpha is not None:
        delta, j = odometry_deltas(u)
        m = odometry_delta_covariance(delta, model.alpha)
        sig = np.einsum("...ia,...ab,...jb->...ij", j, m, j)
    else:
        assert model.sigma is not None
        sig = np.broadcast_to(np.diag(np.square(model.sigma)), u.shape[:-1] + (3, 3)).copy()
    return sig * aux[..., None, None]


def process_noise(theta: ArrayLike, sigma_u: ArrayLike) -> Array:
    """World-frame process noise ``Q = Rot(θ) Σ Rot(θ)ᵀ`` (..., 3, 3) of ``x ∘ (u + n)``."""
    th = np.asarray(theta, dtype=np.float64)
    c, s = np.cos(th), np.sin(th)
    rot = np.zeros(th.shape + (3, 3))
    rot[..., 0, 0] = c
    rot[..., 0, 1] = -s
    rot[..., 1, 0] = s
    rot[..., 1, 1] = c
    rot[..., 2, 2] = 1.0
    return np.einsum("...ia,...ab,...jb->...ij", rot, np.asarray(sigma_u, float), rot)


def range_bearing(x: ArrayLike, landmark: ArrayLike) -> tuple[Array, Array, Array]:
    """Expected measurement and Jacobians of the range-bearing sensor.

    Parameters
    ----------
    x : array_like, shape (..., 3)
    landmark : array_like, shape (..., 2)

    Returns
    -------
    z : ndarray, shape (..., 2)
        ``[r, wrap(atan2(dy, dx) − θ)]``.
    h_x : ndarray, shape (..., 2, 3)
        ``[[−dx/r, −dy/r, 0], [dy/q, −dx/q, −1]]``, ``q = r²``.
    h_l : ndarray, shape (..., 2, 2)
        ``[[dx/r, dy/r], [−dy/q, dx/q]]``.
    """
    x = np.asarray(x, dtype=np.float64)
    lm = np.asarray(landmark, dtype=np.float64)
    dx = lm[..., 0] - x[..., 0]
    dy = lm[..., 1] - x[..., 1]
    q = dx * dx + dy * dy
    r = np.sqrt(q)
    z = np.stack((r, se2.wrap_angle(np.arctan2(dy, dx) - x[..., 2])), axis=-1)
    h_l = np.empty(r.shape + (2, 2))
    h_l[..., 0, 0] = dx / r
    h_l[..., 0, 1] = dy / r
    h_l[..., 1, 0] = -dy / q
    h_l[..., 1, 1] = dx / q
    h_x = np.zeros(r.shape + (2, 3))
    h_x[..., :, :2] = -h_l
    h_x[..., 1, 2] = -1.0
    return z, h_x, h_l
