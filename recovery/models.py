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

Velocity model, forward Euler (``integration="euler"``, :func:`euler_increment`)
    What textbook and popular code writes (``x += v cos θ Δt; y += v sin θ Δt; θ += ω Δt``):
    a row's body increment is ``[v Δt, 0, ω Δt]``. A piece of the row starting ``s`` seconds
    after the row's start and lasting ``a`` is ``[v a cos ωs, −v a sin ωs, ω a]`` (the
    pieces compose to the row's Euler step exactly); its control noise maps through
    ``∂u/∂(v, ω)`` of the piece.

Pose noise (``pose_noise``, either model, instead of noise on the controls)
    A 3 × 3 covariance ``C`` per control row or odometry step, in the robot's (``"body"``:
    ``x ∘ (u + n)``, ``Σ = C``) or the map frame (``"world"``: ``x ∘ u + w``; turned into the
    body-frame ``Σ = Rot(θ)ᵀ C Rot(θ)`` with the step's dead-reckoning heading ``θ``, exact
    when :func:`world_noise_is_rotation_invariant`). A fraction ``f`` of a row gets ``f C``.

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

from recovery.constants import MAX_SIGMA, MAX_VARIANCE
from relation_metric import se2
from relation_metric.arrays import Array
from relation_metric.checks import check_covariances
from relation_metric.errors import InputError

__all__ = [
    "MotionModel",
    "MotionModelWarning",
    "MotionPersisting",
    "gauss_markov_window_variance",
    "SensorModel",
    "PersistingError",
    "velocity_increment",
    "euler_increment",
    "world_noise_is_rotation_invariant",
    "velocity_control_covariance",
    "odometry_deltas",
    "odometry_from_deltas",
    "odometry_delta_covariance",
    "increment_covariance",
    "process_noise",
    "range_bearing",
]

MOTION_TYPES = ("velocity", "odometry")
#: ``integration`` of the velocity model: the exact arc, or forward Euler.
INTEGRATIONS = ("arc", "euler")
#: ``control_stamp`` of the velocity model: a control row is stamped at the start of the
#: interval it is held over (row k: ``[t_k, t_{k+1})``) or at its end (``(t_{k−1}, t_k]``).
CONTROL_STAMPS = ("start", "end")
#: ``sensor_model.noise``: the σ are the filter's assumed noise, or the data's true noise.
SENSOR_NOISE_SOURCES = ("assumed", "true")
#: ``pose_noise.frame``: noise on the body-frame increment, or added in the map frame.
POSE_NOISE_FRAMES = ("body", "world")
#: The ``sigma`` entries of each motion model, in order (``bundle.json`` keys).
SIGMA_NAMES = {
    "velocity": ("sigma_v", "sigma_omega"),
    "odometry": ("sigma_x", "sigma_y", "sigma_theta"),
}


class MotionModelWarning(UserWarning):
    """A motion model the recovery can state only approximately (e.g. anisotropic world noise)."""


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
    big = [v for v in out if v > MAX_SIGMA]
    if big:
        raise InputError(
            f"{what}: expected at most {MAX_SIGMA:.0e} (its square must stay far inside "
            f"float64), got {big[0]:g}"
        )
    return out


def _choice(value: object, allowed: tuple[str, ...], *, what: str) -> str:
    """``value`` when it is one of ``allowed``, else :class:`InputError` naming ``what``."""
    if not isinstance(value, str) or value not in allowed:
        shown = repr(value) if isinstance(value, str) else f"{value!s:.60}"
        raise InputError(f"{what}: unknown value {shown}; expected one of {', '.join(allowed)}")
    return value


def _covariance_3x3(values: object, *, what: str) -> tuple[tuple[float, ...], ...]:
    """``values`` as three rows of 3 floats, finite, symmetric and PSD, else :class:`InputError`."""
    try:
        mat = np.array(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{what}: expected a 3 x 3 matrix, got {values!s:.60}") from None
    if mat.shape != (3, 3):
        raise InputError(f"{what}: expected a 3 x 3 matrix, got shape {mat.shape}")
    check_covariances(mat[None], what=what)
    if np.abs(mat).max() > MAX_VARIANCE:
        raise InputError(
            f"{what}: expected entries of at most {MAX_VARIANCE:.0e} (products of covariances "
            f"must stay inside float64), got {np.abs(mat).max():g}"
        )
    return tuple(tuple(float(v) for v in row) for row in mat)


def gauss_markov_window_variance(window: float, tau: float) -> float:
    """``g(W, τ) = ∫₀^W ∫₀^W e^{−|t − t'|/τ} dt dt' = 2 τ² (W/τ − 1 + e^{−W/τ})``: the
    variance of ``∫₀^W x dt`` of a stationary Gauss–Markov ``x`` of unit variance and time
    constant ``τ`` (``W²`` as ``τ → ∞``, ``2 τ W`` as ``τ → 0``). Written with ``expm1`` so
    that a long τ does not lose its digits: ``W/τ − 1 + e^{−W/τ} = expm1(−a) + a``."""
    a = window / tau
    if a < 1e-4:  # the series: 2 τ² (a²/2 − a³/6 + a⁴/24) = W² (1 − a/3 + a²/12)
        return window * window * (1.0 - a / 3.0 + a * a / 12.0)
    return 2.0 * tau * tau * (math.expm1(-a) + a)


@dataclass(frozen=True)
class MotionPersisting:
    """An odometry error that **persists** (docs/bundle.md, ``motion_model.persisting``):
    a speed-scale error ``s`` (unitless, ``v_true = v (1 + s)``) and a turn-per-metre
    error ``κ`` [rad/m] (``ω_true = ω + κ v``), each a stationary first-order Gauss–Markov
    process ``x(t + Δ) = e^{−Δ/τ} x(t) + w``, ``Var w = σ² (1 − e^{−2Δ/τ})``, independent of
    each other and of the white control noise. It is **in addition to** the model's stated
    white noise: the robot moves with the commands ``(v (1 + s), ω + κ v)`` plus that noise.
    Velocity model only. A σ of 0 switches that process off.

    Raises
    ------
    InputError
        A σ that is not a finite number ≥ 0 (at most ``MAX_SIGMA``), a time constant that is
        not a finite number > 0; the message names the field.
    """

    sigma_scale: float
    time_constant_scale: float
    sigma_turn: float
    time_constant_turn: float

    def __post_init__(self) -> None:
        for name in ("sigma_scale", "time_constant_scale", "sigma_turn", "time_constant_turn"):
            (value,) = _nonnegative_numbers(
                (getattr(self, name),), 1, what=f"motion_model.persisting.{name}"
            )
            if name.startswith("time_constant") and not 0.0 < value < 1e30:
                raise InputError(
                    f"motion_model.persisting.{name}: expected a positive number of seconds "
                    f"(below 1e30), got {value:g}"
                )
            object.__setattr__(self, name, value)

    @property
    def sigma(self) -> tuple[float, float]:
        """``(σ_s, σ_κ)``."""
        return (self.sigma_scale, self.sigma_turn)

    @property
    def tau(self) -> tuple[float, float]:
        """``(τ_s, τ_κ)`` [s]."""
        return (self.time_constant_scale, self.time_constant_turn)

    def alpha_share(self, window: float, period: float) -> tuple[float, float]:
        """``(Δα1, Δα3)``: the persisting error as the white speed-proportional velocity
        model (Probabilistic Robotics Table 5.3, ``σ_v² = α1 v² + α2 ω²``,
        ``σ_ω² = α3 v² + α4 ω²`` per control row held over its ``Δt``) that gives the same
        variance of the travelled distance and turn over windows of ``window`` (``W``)
        seconds, with control rows every ``period`` (``h``) seconds, at a constant speed.

        Derivation. At constant ``v`` the distance error over a window from ``s`` is
        ``v ∫₀^W s dt``, of variance ``v² σ_s² g(W, τ_s)`` with
        ``g(W, τ) = ∫₀^W ∫₀^W e^{−|t−t'|/τ} dt dt' = 2 τ² (W/τ − 1 + e^{−W/τ})``
        (:func:`gauss_markov_window_variance`); the turn error from ``κ`` is
        ``v ∫₀^W κ dt``, of variance ``v² σ_κ² g(W, τ_κ)``. The white model's ``W / h`` rows
        each add ``α1 v² h²`` to the distance variance (``α3 v² h²`` to the turn's), together
        ``α1 v² W h``. Equal variances:

        ``Δα1 = σ_s² g(W, τ_s) / (W h)``, ``Δα3 = σ_κ² g(W, τ_κ) / (W h)``.

        Limits: ``τ → ∞`` (a constant error over the window), ``g → W²``: ``σ² W / h``;
        ``τ → 0``, ``g → 2 τ W``: ``2 σ² τ / h`` (white noise of spectral density
        ``2 σ² τ``). The share grows with ``W`` while ``τ`` is not small against it: a
        white model fitted over longer windows states more noise.

        Raises
        ------
        InputError
            When ``window`` or ``period`` is not a finite positive number.
        """
        for name, value in (("window", window), ("period", period)):
            if not (math.isfinite(value) and value > 0):
                raise InputError(f"alpha_share: {name} must be a positive time, got {value!r}")
        return (
            self.sigma_scale**2
            * gauss_markov_window_variance(window, self.time_constant_scale)
            / (window * period),
            self.sigma_turn**2
            * gauss_markov_window_variance(window, self.time_constant_turn)
            / (window * period),
        )

    def as_dict(self) -> dict[str, object]:
        return {
            "sigma_scale": self.sigma_scale,
            "time_constant_scale": self.time_constant_scale,
            "sigma_turn": self.sigma_turn,
            "time_constant_turn": self.time_constant_turn,
        }


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
    integration : {"arc", "euler"}
        Velocity model only: the exact arc (default) or forward Euler (:func:`euler_increment`).
    control_stamp : {"start", "end"}
        Velocity model only: row ``k`` is held over ``[t_k, t_{k+1})`` (``"start"``, default;
        the last row only closes the log) or over ``(t_{k−1}, t_k]`` (``"end"``; the first row
        only opens the log).
    pose_noise_frame : {"body", "world"} or None
        The frame of ``pose_noise``.
    pose_noise : tuple of 3 tuples of 3 floats, or None
        Process noise ``C`` on the pose, once per control row (velocity) or odometry step,
        instead of noise on the controls: ``x ∘ (u + n)`` (``"body"``) or ``x ∘ u + w``
        (``"world"``), ``n, w ~ N(0, C)``.
    step_covariance_frame : {"body", "world"} or None
        A covariance ``C_k`` per control row or odometry step, given with the log
        (``step_covariance.csv``, ``Bundle.step_covariances``), in the frame named, as
        ``pose_noise`` but one per row: e.g. an increment-dependent odometry noise
        ``J C Jᵀ`` as a filter computed it.
    persisting : MotionPersisting or None
        Velocity model with ``sigma`` or ``alpha`` only: a speed-scale and turn-per-metre
        error that persists (:class:`MotionPersisting`), in addition to that white noise.
        None (default): not stated; :meth:`as_dict` then writes no key.

    Exactly one of ``sigma``, ``alpha``, ``pose_noise`` and ``step_covariance_frame`` is
    set; ``sigma`` and ``alpha`` are stored as tuples of float, ``pose_noise`` as a tuple of
    three rows of float.

    Raises
    ------
    InputError
        When ``type`` is not one of :data:`MOTION_TYPES` (``"Velocity"`` is refused, not run
        as odometry), when not exactly one of ``sigma``, ``alpha`` and ``pose_noise`` is given,
        when one of them has the wrong length or a negative or non-finite entry, when
        ``pose_noise`` is not a 3 × 3 symmetric positive semi-definite matrix
        (:func:`relation_metric.checks.check_covariances`) or comes without its frame (or a
        frame without it), when ``integration``, ``control_stamp`` or ``pose_noise_frame`` is
        not one of its allowed values, or when the odometry model is given an ``integration``
        or ``control_stamp`` other than the defaults (they are the velocity model's); the
        message names the field.
    """

    type: str
    sigma: tuple[float, ...] | None = None
    alpha: tuple[float, ...] | None = None
    integration: str = "arc"
    control_stamp: str = "start"
    pose_noise_frame: str | None = None
    pose_noise: tuple[tuple[float, ...], ...] | None = None
    step_covariance_frame: str | None = None
    persisting: MotionPersisting | None = None

    def __post_init__(self) -> None:
        if self.type not in MOTION_TYPES:
            raise InputError(
                f"motion_model.type: unknown type {self.type!r}; expected one of "
                f"{', '.join(MOTION_TYPES)}"
            )
        names = SIGMA_NAMES[self.type]
        forms = ("sigma", "alpha", "pose_noise", "step_covariance_frame")
        given = [f for f in forms if getattr(self, f) is not None]
        if len(given) != 1:
            raise InputError(
                f"motion_model ({self.type}): expected either sigma ({', '.join(names)}), "
                "alpha (alpha1..alpha4), pose_noise or step_covariance, exactly one of them"
                + (f"; got {' and '.join(given)}" if given else "")
            )
        _choice(self.integration, INTEGRATIONS, what="motion_model.integration")
        _choice(self.control_stamp, CONTROL_STAMPS, what="motion_model.control_stamp")
        if self.type == "odometry":
            for name, default in (("integration", "arc"), ("control_stamp", "start")):
                if getattr(self, name) != default:
                    raise InputError(
                        f"motion_model.{name}: applies to the velocity model only; expected "
                        f"no {name} for the odometry model"
                    )
        if self.persisting is not None:
            if not isinstance(self.persisting, MotionPersisting):
                raise InputError(
                    "motion_model.persisting: expected a MotionPersisting, got "
                    f"{self.persisting!s:.60}"
                )
            if self.type != "velocity":
                raise InputError(
                    "motion_model.persisting: applies to the velocity model only (a speed-scale "
                    f"and turn-per-metre error of its commands); expected none for {self.type}"
                )
            if given[0] not in ("sigma", "alpha"):
                raise InputError(
                    "motion_model.persisting: is stated in addition to white control noise; "
                    f"expected sigma (sigma_v, sigma_omega) or alpha, got {given[0]}"
                )
        if given == ["step_covariance_frame"]:
            _choice(
                self.step_covariance_frame,
                POSE_NOISE_FRAMES,
                what="motion_model.step_covariance.frame",
            )
            if self.pose_noise_frame is not None:
                raise InputError("motion_model.pose_noise.frame: given without pose_noise")
            return
        if given == ["pose_noise"]:
            if self.pose_noise_frame is None:
                raise InputError(
                    "motion_model.pose_noise.frame: missing; expected one of "
                    + ", ".join(POSE_NOISE_FRAMES)
                )
            _choice(self.pose_noise_frame, POSE_NOISE_FRAMES, what="motion_model.pose_noise.frame")
            cov = _covariance_3x3(self.pose_noise, what="motion_model.pose_noise.covariance")
            object.__setattr__(self, "pose_noise", cov)
            return
        if self.pose_noise_frame is not None:
            raise InputError("motion_model.pose_noise.frame: given without pose_noise.covariance")
        field_name, size = ("sigma", len(names)) if self.alpha is None else ("alpha", 4)
        values = _nonnegative_numbers(
            getattr(self, field_name), size, what=f"motion_model.{field_name} ({self.type})"
        )
        object.__setattr__(self, field_name, values)

    @property
    def pose_noise_matrix(self) -> Array | None:
        """``pose_noise`` as a (3, 3) array (a new one each call), None without pose noise."""
        return None if self.pose_noise is None else np.array(self.pose_noise, dtype=np.float64)

    def as_dict(self) -> dict[str, object]:
        """The ``bundle.json`` object of the model: every key that applies to its type."""
        out: dict[str, object] = {"type": self.type}
        if self.type == "velocity":
            out["integration"] = self.integration
            out["control_stamp"] = self.control_stamp
        if self.alpha is not None:
            out["alpha"] = list(self.alpha)
        elif self.step_covariance_frame is not None:
            out["step_covariance"] = {"frame": self.step_covariance_frame}
        elif self.pose_noise is not None:
            out["pose_noise"] = {
                "frame": self.pose_noise_frame,
                "covariance": [list(row) for row in self.pose_noise],
            }
        else:
            out.update(zip(SIGMA_NAMES[self.type], self.sigma or ()))
        if self.persisting is not None:  # written when stated (older bundles unchanged)
            out["persisting"] = self.persisting.as_dict()
        return out


@dataclass(frozen=True)
class PersistingError:
    """A measurement error that persists along each landmark's track (docs/bundle.md,
    ``sensor_model.persisting``): per landmark and component a first-order Gauss–Markov bias
    ``b(t + Δ) = e^{−Δ/τ} b(t) + w`` with stationary standard deviation ``sigma_*`` and time
    constant ``time_constant_*`` [s], part of the sensor model's total σ (the rest is white).
    Used by :mod:`recovery.persisting`.

    Raises
    ------
    InputError
        A σ that is not a finite number > 0, a time constant that is not finite and > 0.
    """

    sigma_range: float
    sigma_bearing: float
    time_constant_range: float
    time_constant_bearing: float
    #: The same four numbers for a bias **common to every landmark** (the sensor's own: a
    #: heading or clock offset moves every bearing alike), or None.
    common: PersistingError | None = None

    def __post_init__(self) -> None:
        if self.common is not None and self.common.common is not None:
            raise InputError("sensor_model.persisting.common: expected no common of its own")
        for name in (
            "sigma_range",
            "sigma_bearing",
            "time_constant_range",
            "time_constant_bearing",
        ):
            (value,) = _nonnegative_numbers(
                (getattr(self, name),), 1, what=f"sensor_model.persisting.{name}"
            )
            if not 0.0 < value < 1e30:
                raise InputError(
                    f"sensor_model.persisting.{name}: expected a positive number, got {value:g}"
                )
            object.__setattr__(self, name, value)

    @property
    def sigma(self) -> tuple[float, float]:
        return (self.sigma_range, self.sigma_bearing)

    @property
    def tau(self) -> tuple[float, float]:
        return (self.time_constant_range, self.time_constant_bearing)

    @property
    def variance(self) -> tuple[float, float]:
        """The persisting variance per component, the common bias's included."""
        c = (0.0, 0.0) if self.common is None else self.common.variance
        return (self.sigma_range**2 + c[0], self.sigma_bearing**2 + c[1])

    def as_dict(self) -> dict[str, object]:
        out: dict[str, object] = {
            "sigma_range": self.sigma_range,
            "sigma_bearing": self.sigma_bearing,
            "time_constant_range": self.time_constant_range,
            "time_constant_bearing": self.time_constant_bearing,
        }
        if self.common is not None:
            out["common"] = self.common.as_dict()
        return out


def checked_outlier_share(share: object) -> float:
    """``sensor_model.outlier_share`` as a float in ``[0, 0.5)``, else :class:`InputError`
    (the one home of that rule: :class:`SensorModel` and the bundle reader)."""
    if not (isinstance(share, int | float) and 0.0 <= share < 0.5):
        raise InputError(
            f"sensor_model.outlier_share: expected a share in [0, 0.5) (the measurements that "
            f"are gross errors), got {share!s:.40}"
        )
    return float(share)


@dataclass(frozen=True)
class SensorModel:
    """Range-bearing sensor with independent Gaussian noise (standard deviations).

    ``max_range`` [m] and ``fov`` [rad] (the full opening angle, centred on the heading) are
    the sensor's reach when the bundle declares it (``None``: not declared); only the map
    comparison reads them (which true landmarks the run could have seen). ``mount``
    ``(x, y, θ)``: the sensor's pose in the robot frame (``None``: at the robot's origin,
    facing forward); the measurement is ``h(x ∘ mount, l)``. ``noise``: whether the σ are the
    filter's assumed noise (``"assumed"``, the default) or the data's true noise (``"true"``,
    known for a simulation); the recovery uses them either way and reports which.
    ``outlier_share``: the share of the measurements that are gross errors the Gaussian σ do
    not describe (misread barcodes, multipath), as the writer measured it (``None``: not
    stated); in ``[0, 0.5)``. The recovery is unchanged by it (its robust update down-weights
    such measurements either way); the verdict's map–log lamp judges the innovations' tail
    against it (docs/verdict.md).

    Raises
    ------
    InputError
        When ``type`` is not ``"range_bearing"``, a standard deviation is negative or not
        finite (zero is allowed in memory: a noise-free simulation), ``max_range`` is not
        positive or ``fov`` not in ``(0, 2π]``; the message names the field.
    """

    sigma_range: float
    sigma_bearing: float
    type: str = "range_bearing"
    max_range: float | None = None
    fov: float | None = None
    mount: tuple[float, float, float] | None = None
    noise: str = "assumed"
    persisting: PersistingError | None = None
    outlier_share: float | None = None

    def __post_init__(self) -> None:
        if self.type != "range_bearing":
            raise InputError(
                f"sensor_model.type: unknown type {self.type!r}; expected range_bearing"
            )
        for name in ("sigma_range", "sigma_bearing"):
            (value,) = _nonnegative_numbers((getattr(self, name),), 1, what=f"sensor_model.{name}")
            object.__setattr__(self, name, value)
        for name, high in (("max_range", math.inf), ("fov", 2 * math.pi)):
            v = getattr(self, name)
            if v is None:
                continue
            (value,) = _nonnegative_numbers((v,), 1, what=f"sensor_model.{name}")
            if not 0.0 < value <= high:
                bound = "a positive number" if name == "max_range" else "an angle in (0, 2π]"
                raise InputError(f"sensor_model.{name}: expected {bound}, got {value:g}")
            object.__setattr__(self, name, value)
        _choice(self.noise, SENSOR_NOISE_SOURCES, what="sensor_model.noise")
        if self.mount is not None:
            m = np.asarray(self.mount, dtype=np.float64)
            if m.shape != (3,) or not np.isfinite(m).all() or np.abs(m[:2]).max() > 1e30:
                raise InputError(
                    f"sensor_model.mount: expected [x, y, theta], three finite numbers (the "
                    f"sensor's pose in the robot frame), got {self.mount!s:.60}"
                )
            object.__setattr__(self, "mount", (float(m[0]), float(m[1]), float(m[2])))
        if self.outlier_share is not None:
            object.__setattr__(self, "outlier_share", checked_outlier_share(self.outlier_share))
        pe = self.persisting
        if pe is not None:
            for name, total, var in (
                ("sigma_range", self.sigma_range, pe.variance[0]),
                ("sigma_bearing", self.sigma_bearing, pe.variance[1]),
            ):
                if not var < total * total:
                    raise InputError(
                        f"sensor_model.persisting.{name}: {math.sqrt(var):g} (with the common "
                        f"bias's) is not below the sensor's total {name} {total:g}; expected "
                        "the persisting part of it (the rest is white noise)"
                    )

    @property
    def mounted(self) -> bool:
        """Is the sensor mounted off the robot's origin (a ``mount`` other than zero)?"""
        return self.mount is not None and any(v != 0.0 for v in self.mount)

    @property
    def covariance(self) -> Array:
        """``diag(σ_r², σ_b²)``, shape (2, 2)."""
        return np.diag([self.sigma_range**2, self.sigma_bearing**2])

    def as_dict(self) -> dict[str, object]:
        out: dict[str, object] = {
            "type": self.type,
            "sigma_range": self.sigma_range,
            "sigma_bearing": self.sigma_bearing,
        }
        for name in ("max_range", "fov"):
            if getattr(self, name) is not None:
                out[name] = getattr(self, name)
        if self.mount is not None:
            out["mount"] = list(self.mount)
        if self.noise != "assumed":  # written when stated (older bundles unchanged)
            out["noise"] = self.noise
        if self.persisting is not None:  # written when stated (older bundles unchanged)
            out["persisting"] = self.persisting.as_dict()
        if self.outlier_share is not None:  # written when stated (older bundles unchanged)
            out["outlier_share"] = self.outlier_share
        return out


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


def euler_increment(
    v: ArrayLike, omega: ArrayLike, dt: ArrayLike, offset: ArrayLike = 0.0
) -> tuple[Array, Array]:
    """Body-frame increment of a piece of a forward-Euler velocity row, and its Jacobian.

    The Euler row ``x += v cos θ Δt, y += v sin θ Δt, θ += ω Δt`` is the body increment
    ``[v Δt, 0, ω Δt]``: the robot moves along the heading it had at the row's start. A piece
    starting ``offset`` (``s``) seconds after the row's start, of duration ``dt`` (``a``), keeps
    that: it moves along the row's initial heading, which is ``−ω s`` in the piece's own frame,

    ``u = [v a cos ωs, −v a sin ωs, ω a]``,

    so the pieces of a row compose to its Euler step exactly (in exact arithmetic).

    Parameters
    ----------
    v, omega, dt, offset : array_like, shape (...)

    Returns
    -------
    u : ndarray, shape (..., 3)
    j_u : ndarray, shape (..., 3, 2)
        ``∂u/∂(v, ω)``.
    """
    v, omega, dt, s = np.broadcast_arrays(
        *(np.asarray(a, dtype=np.float64) for a in (v, omega, dt, offset))
    )
    c, n = np.cos(omega * s), np.sin(omega * s)
    d = v * dt
    u = np.stack((d * c, -d * n, omega * dt), axis=-1)
    j = np.zeros(v.shape + (3, 2))
    j[..., 0, 0] = dt * c
    j[..., 1, 0] = -dt * n
    j[..., 0, 1] = -d * s * n
    j[..., 1, 1] = -d * s * c
    j[..., 2, 1] = dt
    return u, j


def world_noise_is_rotation_invariant(cov: ArrayLike) -> bool:
    """Is ``Rot(θ) C Rot(θ)ᵀ = C`` for every ``θ``? (``c_xx = c_yy``, ``c_xy = c_xθ = c_yθ = 0``).

    Then a world-frame pose noise ``C`` is the body-frame ``Σ = C`` exactly, whatever the
    heading; otherwise the recovery's conversion with the dead-reckoning heading is an
    approximation. Within a relative ``1e-9`` of the largest entry (the covariance checks').
    """
    c = np.asarray(cov, dtype=np.float64)
    tol = 1e-9 * float(np.abs(c).max(initial=0.0))
    off = (c[0, 0] - c[1, 1], c[0, 1], c[1, 0], c[0, 2], c[2, 0], c[1, 2], c[2, 1])
    return all(abs(float(x)) <= tol for x in off)


def _rotation(theta: ArrayLike) -> Array:
    """``Rot(θ)`` (..., 3, 3): the x, y block rotated by ``θ``, 1 for the heading."""
    th = np.asarray(theta, dtype=np.float64)
    c, s = np.cos(th), np.sin(th)
    rot = np.zeros(th.shape + (3, 3))
    rot[..., 0, 0] = c
    rot[..., 0, 1] = -s
    rot[..., 1, 0] = s
    rot[..., 1, 1] = c
    rot[..., 2, 2] = 1.0
    return rot


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


def increment_covariance(
    model: MotionModel,
    u: ArrayLike,
    aux: ArrayLike,
    *,
    heading: ArrayLike | None = None,
    step_covariance: ArrayLike | None = None,
) -> Array:
    """Body-frame covariance ``Σ`` (..., 3, 3) of increments ``u``.

    Parameters
    ----------
    model : MotionModel
    u : array_like, shape (..., 3)
        The increments.
    aux : array_like
        Velocity model: the ``(..., 4)`` array ``[v, ω, Δt, scale]`` each increment came from
        (``scale`` multiplies ``M``; a piece of a row of duration ``Δt_row`` has ``scale =
        Δt_row / Δt``), or ``(..., 5)`` with the piece's ``offset`` into its row appended (forward
        Euler; 0 when missing); odometry model: ``(...,)`` scale on ``Σ`` (the fraction of the
        step). With ``pose_noise`` the piece's share of the row is ``1 / scale`` (velocity) or
        the scale (odometry).
    heading : array_like, shape (...), optional
        The heading each increment starts from; needed (only) by world-frame ``pose_noise``,
        which is turned into the body frame with it: ``Σ = Rot(θ)ᵀ f C Rot(θ)``.
    step_covariance : array_like, shape (..., 3, 3), optional
        With ``model.step_covariance_frame``: the covariance ``C`` of the row (or step) each
        increment belongs to; it is used as ``pose_noise`` is (``f C``, rotated when world).
    """
    aux = np.asarray(aux, dtype=np.float64)
    frame = model.pose_noise_frame
    if model.step_covariance_frame is not None:
        if step_covariance is None:
            raise ValueError("a step_covariance motion model needs the rows' covariances")
        frame = model.step_covariance_frame
    if model.pose_noise is not None or model.step_covariance_frame is not None:
        cov = np.asarray(
            model.pose_noise if step_covariance is None else step_covariance, dtype=np.float64
        )
        frac = 1.0 / aux[..., 3] if model.type == "velocity" else aux
        sig = frac[..., None, None] * cov
        if frame == "world":
            if heading is None:
                raise ValueError("world-frame pose noise needs the heading of each increment")
            rot = _rotation(np.broadcast_to(np.asarray(heading, float), frac.shape))
            sig = np.einsum("...ai,...ab,...bj->...ij", rot, sig, rot)
        return sig
    if model.type == "velocity":
        v, w, dt, scale = np.moveaxis(aux[..., :4], -1, 0)
        if model.integration == "euler":
            offset = aux[..., 4] if aux.shape[-1] > 4 else 0.0
            _, j = euler_increment(v, w, dt, offset)
        else:
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
    rot = _rotation(theta)
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
