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

__all__ = ["Alignment", "umeyama", "ATEResult", "absolute_trajectory_error"]


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
    x = np.asarray(source, dtype=np.float64)
    y = np.asarray(target, dtype=np.float64)
    if x.shape != y.shape or x.ndim != 2 or x.shape[1] not in (2, 3):
        raise InputError(
            f"alignment needs two (N, 2) or (N, 3) point sets, got {x.shape} and {y.shape}"
        )
    dim = x.shape[1]
    n = x.shape[0]
    if n < 2:
        raise InputError(f"alignment needs at least 2 corresponding points, got {n}")
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
class ATEResult:
    """Absolute trajectory error after alignment.

    Attributes
    ----------
    alignment : Alignment
    translation, rotation : ndarray, shape (K,)
        Per matched pose: ``‖p_ref − A(p_est)‖`` (m) and ``|wrap(θ_ref − θ_est − angle)|``.
    translation_stats, rotation_stats : Summary
    matched : int
        Poses matched in time (within the tolerance).
    timestamps : ndarray, shape (K,), or None
        The matched estimate poses' times (the rows of ``translation`` and ``rotation``).
    """

    alignment: Alignment
    translation: NDArray[np.float64]
    rotation: NDArray[np.float64]
    translation_stats: Summary
    rotation_stats: Summary
    matched: int
    timestamps: NDArray[np.float64] | None = None


def absolute_trajectory_error(
    estimate: Trajectory,
    reference: Trajectory,
    *,
    align: str = "se2",
    max_time_diff: float = 0.1,
) -> ATEResult:
    """ATE of ``estimate`` against ``reference`` after ``align``.

    ``align`` ∈ {"none", "se2", "sim2", "se3", "sim3"}: a rigid or similarity alignment of
    the positions (``se2``/``sim2`` and ``se3``/``sim3`` are the same request; the group of
    the trajectories decides 2-D or 3-D). On SE(3) (either trajectory 3-D; the other is
    lifted) the errors are evo's APE ``translation_part`` and ``rotation_angle``:
    ``‖t_ref − t_est'‖`` and the angle of ``R_refᵀ R_est'``.

    Estimate poses are matched to the reference pose nearest in time (within
    ``max_time_diff``); unmatched estimate poses are left out and the count is reported.
    """
    if align not in ("none", "se2", "sim2", "se3", "sim3"):
        raise InputError(f"align must be 'none', 'se2', 'sim2', 'se3' or 'sim3', got {align!r}")
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
    dim = group.position_dim
    if align == "none":
        al = Alignment(0.0, np.zeros(dim), 1.0)
    else:
        al = umeyama(
            group.positions(est), group.positions(ref), with_scale=align in ("sim2", "sim3")
        )
    moved = al.apply(est)
    if group is SE3:
        err = se3.between(moved, ref)  # evo's APE: E = P_est⁻¹ P_ref
        trans = np.linalg.norm(ref[:, :3] - moved[:, :3], axis=1)
        rot = se3.rotation_angle(err[:, 3:])
    else:
        trans = np.hypot(*(ref[:, :2] - moved[:, :2]).T)
        rot = np.abs(se2.wrap_angle(ref[:, 2] - moved[:, 2]))
    stamps = estimate.timestamps[ok]
    return ATEResult(al, trans, rot, summarize(trans), summarize(rot), int(ok.sum()), stamps)
