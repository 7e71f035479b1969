"""Absolute trajectory error after a least-squares alignment (Umeyama 1991).

The naive absolute error — the sum of squared distances between estimate and reference
poses — depends on the frame the estimate happens to be in. Its rescue is to minimise it over
all rigid transforms (SE(2)/SE(3)) or similarities (Sim(2)/Sim(3)) first; this module does that with
Umeyama's closed form, tagged with the paper's equation numbers. Even aligned, the ATE weighs
an early rotation error over the whole remaining trajectory while a late one barely counts —
the reason for the relation metric (see the tests for the worked example).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relation_metric import se2, se3
from relation_metric.errors import AssociationError, InputError
from relation_metric.groups import SE3
from relation_metric.stats import Summary, summarize
from relation_metric.time_association import nearest_index
from relation_metric.trajectory import Trajectory

__all__ = [
    "Alignment",
    "umeyama",
    "AffineAlignment",
    "affine_fit",
    "ATEResult",
    "AxisErrors",
    "ALIGNMENTS",
    "umeyama_yaw",
    "absolute_trajectory_error",
]


@dataclass(frozen=True)
class Alignment:
    """A similarity ``y ≈ scale · R x + translation`` in 2-D or 3-D.

    ``angle`` is the rotation angle of ``R`` (2-D: signed, about z; 3-D: in ``[0, π]``);
    ``rotation`` is ``R`` itself, ``(2, 2)`` or ``(3, 3)`` (``None``: ``R(angle)`` in 2-D).
    """

    angle: float
    translation: NDArray[np.float64]
    scale: float
    rotation: NDArray[np.float64] | None = None

    def apply(self, poses: ArrayLike) -> NDArray[np.float64]:
        """Apply to poses ``(..., 3)`` or ``(..., 7)``: positions mapped, orientations rotated."""
        p = np.asarray(poses, dtype=np.float64)
        if p.shape[-1] == 7:
            r = np.eye(3) if self.rotation is None else self.rotation
            q_r = se3.from_matrix(np.vstack((np.column_stack((r, np.zeros(3))), [0, 0, 0, 1])))
            out = np.empty_like(p)
            out[..., :3] = self.scale * p[..., :3] @ r.T + self.translation
            out[..., 3:] = se3.quat_multiply(q_r[3:], p[..., 3:])
            return out
        c, s = np.cos(self.angle), np.sin(self.angle)
        out = np.empty_like(p)
        out[..., 0] = self.scale * (c * p[..., 0] - s * p[..., 1]) + self.translation[0]
        out[..., 1] = self.scale * (s * p[..., 0] + c * p[..., 1]) + self.translation[1]
        out[..., 2] = se2.wrap_angle(p[..., 2] + self.angle)
        return out


def _point_sets(
    source: ArrayLike, target: ArrayLike, dims: tuple[int, ...]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Two corresponding ``(N, d)`` point sets, ``d`` in ``dims`` and N ≥ 2, as float arrays."""
    x = np.asarray(source, dtype=np.float64)
    y = np.asarray(target, dtype=np.float64)
    if x.shape != y.shape or x.ndim != 2 or x.shape[1] not in dims:
        shapes = " or ".join(f"(N, {d})" for d in dims)
        raise InputError(f"alignment needs two {shapes} point sets, got {x.shape} and {y.shape}")
    if x.shape[0] < 2:
        raise InputError(f"alignment needs at least 2 corresponding points, got {x.shape[0]}")
    return x, y


def umeyama(source: ArrayLike, target: ArrayLike, *, with_scale: bool = False) -> Alignment:
    """Least-squares similarity taking ``source`` points onto ``target`` points.

    Minimises ``1/n Σ ‖y_i − (c R x_i + t)‖²`` (Umeyama 1991, Eq. 1) in closed form.

    Parameters
    ----------
    source, target : array_like, shape (N, 2) or (N, 3)
        Corresponding points ``x_i`` (estimate) and ``y_i`` (reference); N ≥ 2.
    with_scale : bool
        Estimate the scale ``c`` (Sim(2)/Sim(3)); otherwise ``c = 1`` (SE(2)/SE(3)).

    Returns
    -------
    Alignment
    """
    x, y = _point_sets(source, target, (2, 3))
    dim = x.shape[1]
    n = x.shape[0]
    mu_x = x.mean(axis=0)  # Eq. 34
    mu_y = y.mean(axis=0)  # Eq. 35
    xc = x - mu_x
    yc = y - mu_y
    sigma_x2 = float(np.mean(np.sum(xc * xc, axis=1)))  # Eq. 36
    cov = yc.T @ xc / n  # Σ_xy, Eq. 38
    u, d, vt = np.linalg.svd(cov)
    s = np.eye(dim)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:  # Eq. 39 / 43: avoid a reflection
        s[-1, -1] = -1.0
    r = u @ s @ vt  # Eq. 40
    c = float(np.trace(np.diag(d) @ s) / sigma_x2) if with_scale and sigma_x2 > 0 else 1.0  # Eq. 42
    t = mu_y - c * r @ mu_x  # Eq. 41
    if dim == 2:
        return Alignment(angle=float(np.arctan2(r[1, 0], r[0, 0])), translation=t, scale=c)
    angle = float(np.arccos(np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0)))
    return Alignment(angle=angle, translation=t, scale=c, rotation=r)


@dataclass(frozen=True)
class AffineAlignment:
    """An affine map ``y ≈ A x + b`` in 2-D or 3-D: ``matrix`` ``A`` (d, d), ``translation`` ``b``.

    ``rank`` is the rank of the centred source points' scatter matrix: below ``d`` (a planar
    3-D path, a straight line) ``A`` is not unique and the minimum-norm one is returned; the
    minimum of the sum of squared distances is unique either way.
    """

    matrix: NDArray[np.float64]
    translation: NDArray[np.float64]
    rank: int

    def apply_points(self, points: ArrayLike) -> NDArray[np.float64]:
        """``A x + b`` for points ``(..., d)``."""
        return np.asarray(points, dtype=np.float64) @ self.matrix.T + self.translation


def affine_fit(source: ArrayLike, target: ArrayLike) -> AffineAlignment:
    """The affine map minimising the sum of squared distances ``Σ ‖y_i − (A x_i + b)‖²``.

    The "rescue" of the naive absolute error over the largest family of maps that keep
    straight lines straight (rigid ⊂ similarity ⊂ affine): the minimum over affine maps is a
    lower bound of the SE/Sim-aligned errors. Closed form (linear least squares): with the
    centroids ``μ_x, μ_y`` and centred points ``x̃, ỹ``,
    ``A = (Σ ỹ x̃ᵀ)(Σ x̃ x̃ᵀ)⁺`` and ``b = μ_y − A μ_x`` (``⁺`` the pseudo-inverse).

    Parameters
    ----------
    source, target : array_like, shape (N, d), d ∈ {2, 3}
        Corresponding points (estimate, reference); N ≥ 2.
    """
    x, y = _point_sets(source, target, (2, 3))
    mu_x, mu_y = x.mean(axis=0), y.mean(axis=0)
    xc, yc = x - mu_x, y - mu_y
    scatter = xc.T @ xc
    a = (yc.T @ xc) @ np.linalg.pinv(scatter)
    rank = int(np.linalg.matrix_rank(scatter))
    return AffineAlignment(matrix=a, translation=mu_y - a @ mu_x, rank=rank)


def umeyama_yaw(source: ArrayLike, target: ArrayLike) -> Alignment:
    """Least-squares 4-DoF alignment: a rotation about z (yaw) and a translation, in 3-D.

    Minimises ``Σ ‖y_i − (R_z(ψ) x_i + t)‖²`` over ``ψ`` and ``t`` (visual-inertial odometry:
    roll and pitch are observable through gravity, yaw and position are not). Closed form:
    with centred points ``x̃, ỹ``, the z terms do not depend on ``ψ``, so
    ``ψ = atan2(Σ (x̃_x ỹ_y − x̃_y ỹ_x), Σ (x̃_x ỹ_x + x̃_y ỹ_y))`` (2-D Procrustes of the
    horizontal parts) and ``t = μ_y − R_z(ψ) μ_x``. Points ``(N, 3)``, N ≥ 2.
    """
    x, y = _point_sets(source, target, (3,))
    mu_x, mu_y = x.mean(axis=0), y.mean(axis=0)
    xc, yc = x - mu_x, y - mu_y
    psi = float(
        np.arctan2(
            np.sum(xc[:, 0] * yc[:, 1] - xc[:, 1] * yc[:, 0]),
            np.sum(xc[:, 0] * yc[:, 0] + xc[:, 1] * yc[:, 1]),
        )
    )
    c, s = np.cos(psi), np.sin(psi)
    r = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return Alignment(angle=abs(psi), translation=mu_y - r @ mu_x, scale=1.0, rotation=r)


@dataclass(frozen=True)
class AxisErrors:
    """Per-axis position errors of the matched poses after alignment.

    ``residual`` is ``p_ref − A(p_est)``, ``(K, d)`` (world axes of the reference);
    ``x``, ``y``, ``z`` summarise ``|residual|`` per axis (``z`` only in 3-D);
    ``in_plane`` summarises ``‖residual_xy‖``, ``height`` ``|residual_z|`` (3-D; the same as
    ``z``: the vertical axis is the reference's z).
    """

    residual: NDArray[np.float64]

    def summaries(self) -> dict[str, Summary]:
        """``{"x", "y"[, "z"], "in_plane"[, "height"]}`` → statistics."""
        r = self.residual
        out = {"x": summarize(np.abs(r[:, 0])), "y": summarize(np.abs(r[:, 1]))}
        if r.shape[1] == 3:
            out["z"] = summarize(np.abs(r[:, 2]))
        out["in_plane"] = summarize(np.hypot(r[:, 0], r[:, 1]))
        if r.shape[1] == 3:
            out["height"] = summarize(np.abs(r[:, 2]))
        return out


#: The alignments of :func:`absolute_trajectory_error` (``align``).
ALIGNMENTS = ("none", "se2", "sim2", "se3", "sim3", "4dof", "origin", "affine", "scale")


@dataclass(frozen=True)
class ATEResult:
    """Absolute trajectory error after alignment.

    Attributes
    ----------
    alignment : Alignment or AffineAlignment
        The map applied to the estimate (an :class:`AffineAlignment` for ``align="affine"``).
    translation, rotation : ndarray, shape (K,)
        Per matched pose: ``‖p_ref − A(p_est)‖`` (m) and ``|wrap(θ_ref − θ_est − angle)|``
        (SE(3): the angle of ``R_refᵀ R_est'``). Empty for ``align="affine"``: an affine map
        does not map orientations.
    translation_stats, rotation_stats : Summary
    matched : int
        Poses matched in time (within the tolerance).
    axes : AxisErrors
        The per-axis, in-plane and height position errors.
    aligned_on : int
        How many of the matched poses the alignment was fitted on (the first ones).
    timestamps : ndarray, shape (K,), or None
        The matched estimate poses' times (the rows of ``translation`` and ``rotation``).
    """

    alignment: Alignment | AffineAlignment
    translation: NDArray[np.float64]
    rotation: NDArray[np.float64]
    translation_stats: Summary
    rotation_stats: Summary
    matched: int
    axes: AxisErrors
    aligned_on: int
    timestamps: NDArray[np.float64] | None = None


def absolute_trajectory_error(
    estimate: Trajectory,
    reference: Trajectory,
    *,
    align: str = "se2",
    max_time_diff: float = 0.1,
    n_to_align: int | None = None,
) -> ATEResult:
    """ATE of ``estimate`` against ``reference`` after ``align``.

    ``align`` (one of :data:`ALIGNMENTS`) is the map ``A`` applied to the estimate:

    - ``"none"``: the identity;
    - ``"se2"``/``"se3"`` and ``"sim2"``/``"sim3"``: the rigid or similarity transform
      minimising ``Σ ‖p_ref − A(p_est)‖²`` (Umeyama; the two spellings are one request, the
      group of the trajectories decides 2-D or 3-D);
    - ``"4dof"``: a rotation about z and a translation minimising the same sum
      (:func:`umeyama_yaw`; visual-inertial odometry, gravity along z); on SE(2) it is SE(2);
    - ``"origin"``: ``A = X_ref,0 ∘ X_est,0⁻¹``, which puts the first matched estimate pose
      (position and orientation) on the first matched reference pose (evo's
      ``--align_origin``);
    - ``"affine"``: the affine map minimising the sum (:func:`affine_fit`), the lower bound
      of the others; positions only, so no rotation errors;
    - ``"scale"``: the scale ``c`` of the similarity (Umeyama) alone, ``A(p) = c p``, no
      rotation or translation (evo's ``--correct_scale`` without ``--align``).

    ``n_to_align`` fits the alignment on the first ``n_to_align`` matched poses only (≥ 2;
    evo's ``--n_to_align``) and applies it to all; None: on all.

    On SE(3) (either trajectory 3-D; the other is lifted) the errors are evo's APE
    ``translation_part`` and ``rotation_angle``: ``‖t_ref − t_est'‖`` and the angle of
    ``R_refᵀ R_est'``.

    Estimate poses are matched to the reference pose nearest in time (within
    ``max_time_diff``); unmatched estimate poses are left out and the count is reported.
    """
    if align not in ALIGNMENTS:
        raise InputError(f"align must be one of {', '.join(ALIGNMENTS)}, got {align!r}")
    if n_to_align is not None and (int(n_to_align) != n_to_align or n_to_align < 2):
        raise InputError(f"n_to_align must be an integer >= 2, got {n_to_align!r}")
    if estimate.group is SE3 or reference.group is SE3:
        estimate, reference = estimate.lifted(), reference.lifted()
    k = nearest_index(reference.timestamps, estimate.timestamps)
    ok = np.abs(reference.timestamps[k] - estimate.timestamps) <= max_time_diff
    if ok.sum() < 2:
        raise AssociationError(
            f"fewer than 2 estimate poses lie within {max_time_diff} s of a reference pose "
            f"(estimate spans {estimate.span()}, reference spans {reference.span()})"
        )
    est = estimate.poses[ok]
    ref = reference.poses[k[ok]]
    group = estimate.group
    m = est.shape[0] if n_to_align is None else min(int(n_to_align), est.shape[0])
    p_est, p_ref = group.positions(est), group.positions(ref)
    fitted: Alignment | AffineAlignment
    if align == "affine":
        fitted = affine_fit(p_est[:m], p_ref[:m])
        residual = p_ref - fitted.apply_points(p_est)
        rot = np.empty(0)  # an affine map does not map orientations
    else:
        fitted = _rigid_alignment(align, group, est, ref, m)
        moved = fitted.apply(est)
        if group is SE3:
            err = se3.between(moved, ref)  # evo's APE: E = P_est⁻¹ P_ref
            residual = ref[:, :3] - moved[:, :3]
            rot = se3.rotation_angle(err[:, 3:])
        else:
            residual = ref[:, :2] - moved[:, :2]
            rot = np.abs(se2.wrap_angle(ref[:, 2] - moved[:, 2]))
    trans = np.linalg.norm(residual, axis=1)
    return ATEResult(
        fitted,
        trans,
        rot,
        summarize(trans),
        summarize(rot),
        int(ok.sum()),
        AxisErrors(residual),
        m,
        estimate.timestamps[ok],
    )


def _rigid_alignment(
    align: str, group: object, est: NDArray[np.float64], ref: NDArray[np.float64], m: int
) -> Alignment:
    """The map of ``align`` (not affine), fitted on the first ``m`` matched poses."""
    three_d = group is SE3
    dim = 3 if three_d else 2
    if align == "none":
        return Alignment(0.0, np.zeros(dim), 1.0)
    if align == "origin":
        if three_d:
            t = se3.compose(ref[0], se3.inverse(est[0]))  # X_ref,0 ∘ X_est,0⁻¹
            r = se3.to_matrix(t)[:3, :3]
            angle = float(se3.rotation_angle(t[3:]))
            return Alignment(angle=angle, translation=t[:3].copy(), scale=1.0, rotation=r)
        t2 = se2.compose(ref[0], se2.inverse(est[0]))
        return Alignment(angle=float(t2[2]), translation=t2[:2].copy(), scale=1.0)
    if align == "4dof" and three_d:
        return umeyama_yaw(est[:m, :3], ref[:m, :3])
    pos = slice(0, dim)
    if align == "scale":
        c = umeyama(est[:m, pos], ref[:m, pos], with_scale=True).scale
        return Alignment(0.0, np.zeros(dim), c, np.eye(3) if three_d else None)
    return umeyama(est[:m, pos], ref[:m, pos], with_scale=align in ("sim2", "sim3"))
