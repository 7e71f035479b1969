"""evo's absolute and relative pose errors (APE, RPE) on synchronised trajectories.

``evo_ape`` and ``evo_rpe`` (evo 1.x, ``evo.core.metrics``) compare two trajectories pose by
pose after the time association (:func:`relation_metric.time_association.synchronize`),
optionally aligned (Umeyama) and projected to a plane. Their definitions, built here on
slamrel's own pieces:

- **APE** at pose k: ``E_k = P_k⁻¹ Q_k`` (estimate ``P``, reference ``Q``); the error is the
  translation ``‖t_Q − t_P‖`` (the positions' distance, which is ``‖t(E_k)‖``) or the
  rotation angle of ``E_k`` — :func:`relation_metric.alignment.absolute_trajectory_error`
  with the alignment ``A`` applied to ``P`` first.
- **RPE** of a pose pair (i, j): ``E = (Q_i⁻¹ Q_j)⁻¹ (P_i⁻¹ P_j)``, the ``paper`` error of the
  relation metric (:func:`relation_metric.metric.relation_errors`); the pairs are chosen on
  the estimate's poses (on the reference's with ``pairs_from_reference``) by
  :func:`pose_pairs`.

``pose_relation`` turns ``E`` into one number: ``trans_part`` ``‖t(E)‖``, ``angle_rad`` and
``angle_deg`` the rotation angle θ of ``E``, ``rot_part`` ``‖R(E) − I‖_F = 2√2 sin(θ/2)``,
``full`` ``‖E − I‖_F = sqrt(‖R(E) − I‖_F² + ‖t(E)‖²)`` (Frobenius norms of evo's 4×4
matrices, written through θ: the same numbers to rounding), ``point_distance`` the
difference of the two trajectories' point distances ``|‖Q_i Q_j‖ − ‖P_i P_j‖|`` (RPE; for
APE evo uses the translation part).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from relation_metric import se3
from relation_metric.alignment import Alignment, absolute_trajectory_error
from relation_metric.constants import DELTA_UNITS, PLANES, POSE_RELATIONS
from relation_metric.errors import InputError
from relation_metric.metric import relation_errors
from relation_metric.relations import chain_from_zero, generate_relations
from relation_metric.trajectory import Trajectory

__all__ = [
    "POSE_RELATIONS",
    "DELTA_UNITS",
    "PLANE_NORMALS",
    "EVO_ALIGNMENTS",
    "PoseErrors",
    "absolute_pose_errors",
    "relative_pose_errors",
    "pose_pairs",
    "project_to_plane",
]

#: The axis each of evo's ``--project_to_plane`` planes drops.
PLANE_NORMALS = {"xy": 2, "xz": 1, "yz": 0}
#: The alignments evo applies before APE and RPE: none, ``-a`` (se3), ``-as`` (sim3),
#: ``-s`` alone (scale), ``--align_origin`` (origin).
EVO_ALIGNMENTS = ("none", "se3", "sim3", "scale", "origin")


@dataclass(frozen=True)
class PoseErrors:
    """The errors of an APE or RPE, one per pose (APE) or pose pair (RPE).

    ``errors`` (K,) in the relation's unit; ``first``/``second`` (K,) the indices of the pose
    pairs in the synchronised trajectories (APE: ``first == second``, the pose itself);
    ``alignment`` the map applied to the estimate (None: none).
    """

    errors: NDArray[np.float64]
    first: NDArray[np.int64]
    second: NDArray[np.int64]
    alignment: Alignment | None


def _by_index(t: Trajectory) -> Trajectory:
    """``t`` lifted to SE(3) with its pose index as the time: pose k pairs with pose k."""
    return Trajectory(np.arange(len(t), dtype=np.float64), t.lifted().poses)


def _check_pair(reference: Trajectory, estimate: Trajectory) -> None:
    if len(reference) != len(estimate):
        raise InputError(
            f"the synchronised trajectories must have as many poses: {len(reference)} "
            f"reference and {len(estimate)} estimate poses"
        )
    if len(reference) < 2:
        raise InputError(f"needs at least 2 synchronised poses, got {len(reference)}")


def _aligned(
    reference: Trajectory, estimate: Trajectory, align: str, n_to_align: int | None
) -> tuple[Trajectory, Alignment | None]:
    """The estimate (by index, SE(3)) after evo's alignment ``align`` (:data:`EVO_ALIGNMENTS`)."""
    if align not in EVO_ALIGNMENTS:
        raise InputError(f"align must be one of {', '.join(EVO_ALIGNMENTS)}, got {align!r}")
    est = _by_index(estimate)
    if align == "none":
        return est, None
    ref = _by_index(reference)
    fit = absolute_trajectory_error(est, ref, align=align, max_time_diff=0.0, n_to_align=n_to_align)
    assert isinstance(fit.alignment, Alignment)  # not affine
    return Trajectory(est.timestamps, fit.alignment.apply(est.poses)), fit.alignment


def _relation_values(trans: NDArray, angle: NDArray, relation: str) -> NDArray[np.float64]:
    """One number per error pose ``E`` from ``‖t(E)‖`` and its rotation angle (module doc)."""
    if relation in ("trans_part", "point_distance"):
        return trans
    if relation == "angle_rad":
        return angle
    if relation == "angle_deg":
        return np.rad2deg(angle)
    rot = 2.0 * math.sqrt(2.0) * np.sin(angle / 2.0)  # ‖R − I‖_F
    if relation == "rot_part":
        return rot
    if relation == "full":
        return np.sqrt(rot * rot + trans * trans)
    raise InputError(f"pose_relation must be one of {', '.join(POSE_RELATIONS)}, got {relation!r}")


def absolute_pose_errors(
    reference: Trajectory,
    estimate: Trajectory,
    relation: str = "trans_part",
    *,
    align: str = "none",
    n_to_align: int | None = None,
    plane: str | None = None,
    rotations: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None,
) -> PoseErrors:
    """evo's APE of synchronised trajectories (pose k of both is one pair).

    ``align`` (:data:`EVO_ALIGNMENTS`) is fitted on the first ``n_to_align`` poses (None: all)
    and applied to the estimate; then both are projected to ``plane`` (``"xy"``, ``"xz"``,
    ``"yz"``; :func:`project_to_plane`), as evo does after aligning. ``rotations``: the
    rotation blocks as a file gave them, as in :func:`relative_pose_errors` (``rot_part``
    and ``full`` of ``E_k = P_k⁻¹ Q_k`` on them, and the projection's angles).
    """
    _check_pair(reference, estimate)
    est, fit = _aligned(reference, estimate, align, n_to_align)
    ref = _by_index(reference)
    est, ref, raw = _projected(reference, estimate, est, ref, rotations, align, fit, plane)
    r = absolute_trajectory_error(est, ref, align="none", max_time_diff=0.0)
    k = np.arange(len(ref), dtype=np.int64)
    values = _relation_values(r.translation, r.rotation, relation)
    if raw is not None and relation in ("rot_part", "full"):
        values = _matrix_errors(raw[1], raw[0], k, k, relation, first_identity=True)
    return PoseErrors(values, k, k, fit)


def _projected(
    reference: Trajectory,
    estimate: Trajectory,
    est: Trajectory,
    ref: Trajectory,
    rotations: tuple[NDArray[np.float64], NDArray[np.float64]] | None,
    align: str,
    fit: Alignment | None,
    plane: str | None,
) -> tuple[Trajectory, Trajectory, Any]:
    """``est`` and ``ref`` projected to ``plane`` (when given), and the rotation blocks as
    given after the alignment (:func:`_raw_aligned`; None without ``rotations`` or after a
    projection, whose rotations are built exactly, as evo's)."""
    raw = None
    if rotations is not None:
        raw = _raw_aligned(reference, estimate, est, rotations, align, fit)
    if plane is None:
        return est, ref, raw
    r_ref, r_est = (None, None) if raw is None else (raw[0][0], raw[1][0])
    if raw is not None:
        est = Trajectory(est.timestamps, np.column_stack((raw[1][1], est.poses[:, 3:])))
    est = project_to_plane(est, plane, rotations=r_est)
    ref = project_to_plane(ref, plane, rotations=r_ref)
    return est, ref, None


def relative_pose_errors(
    reference: Trajectory,
    estimate: Trajectory,
    relation: str = "trans_part",
    *,
    delta: float = 1.0,
    delta_unit: str = "f",
    rel_delta_tol: float = 0.1,
    all_pairs: bool = False,
    pairs_from_reference: bool = False,
    align: str = "none",
    n_to_align: int | None = None,
    plane: str | None = None,
    rotations: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None,
) -> PoseErrors:
    """evo's RPE of synchronised trajectories (pose k of both is one pair).

    The estimate is aligned and both projected as in :func:`absolute_pose_errors` (a rigid
    alignment leaves every ``P_i⁻¹ P_j`` unchanged; a scale does not); the pose pairs are
    :func:`pose_pairs` on the estimate (the reference with ``pairs_from_reference``).

    ``rotations`` (reference, estimate), each ``(N, 3, 3)``: the rotation blocks as a file
    gave them (KITTI's 3×4 matrices, written with 6–9 digits, are orthonormal to ~1e-7
    only). Without a projection, ``trans_part``, ``rot_part`` and ``full`` are then computed
    on them as evo does (:func:`_matrix_errors`: inverses by transposition), not on the
    re-orthonormalised quaternions of the trajectories; on long relations the two readings
    differ in the 6th digit (module doc of :mod:`slamrel.evo_metrics`).
    """
    _check_pair(reference, estimate)
    est, fit = _aligned(reference, estimate, align, n_to_align)
    ref = _by_index(reference)
    est, ref, raw = _projected(reference, estimate, est, ref, rotations, align, fit, plane)
    i, j = pose_pairs(
        ref if pairs_from_reference else est, delta, delta_unit, rel_delta_tol, all_pairs
    )
    if relation == "point_distance":
        d_ref = np.linalg.norm(ref.poses[i, :3] - ref.poses[j, :3], axis=1)
        d_est = np.linalg.norm(est.poses[i, :3] - est.poses[j, :3], axis=1)
        return PoseErrors(np.abs(d_ref - d_est), i, j, fit)
    e = relation_errors(
        se3.between(est.poses[i], est.poses[j]), se3.between(ref.poses[i], ref.poses[j])
    )
    values = _relation_values(e.translation, e.rotation, relation)
    if raw is not None and relation in ("trans_part", "rot_part", "full"):
        values = _matrix_errors(raw[0], raw[1], i, j, relation)
    return PoseErrors(values, i, j, fit)


def _raw_aligned(
    reference: Trajectory,
    estimate: Trajectory,
    aligned: Trajectory,
    rotations: tuple[NDArray[np.float64], NDArray[np.float64]],
    align: str,
    fit: Alignment | None,
) -> tuple[tuple[NDArray, NDArray], tuple[NDArray, NDArray]]:
    """(rotations, positions) of reference and aligned estimate on the rotation blocks as
    given, with evo's arithmetic: Umeyama's ``R_a`` multiplies them (its positions are those
    of ``aligned``: Umeyama reads positions only); ``--align_origin``'s map is evo's
    ``Q_0 · se3_inverse(P_0)`` on the blocks as given."""
    r_ref, r_est = rotations
    t_ref = reference.lifted().poses[:, :3]
    t_est = aligned.poses[:, :3]
    if align == "origin":
        t0 = estimate.lifted().poses[0, :3]
        r_t = r_ref[0] @ r_est[0].T
        t_t = t_ref[0] - r_t @ t0
        t_est = estimate.lifted().poses[:, :3] @ r_t.T + t_t
        r_est = r_t @ r_est
    elif fit is not None and fit.rotation is not None:
        r_est = fit.rotation @ r_est
    return (r_ref, t_ref), (r_est, t_est)


def _matrix_errors(
    ref: tuple[NDArray, NDArray],
    est: tuple[NDArray, NDArray],
    i: NDArray,
    j: NDArray,
    rel: str,
    *,
    first_identity: bool = False,
) -> NDArray[np.float64]:
    """evo's RPE on matrices as given: ``E = A⁻¹ B``, ``A = Q_i⁻¹ Q_j``, ``B = P_i⁻¹ P_j``.

    ``ref`` and ``est`` are (rotations ``(N, 3, 3)``, positions ``(N, 3)``); every inverse
    is evo's ``se3_inverse`` ``[Rᵀ | −Rᵀ t]``, exact only for an orthonormal ``R``. Returns
    ``‖t(E)‖`` (``trans_part``), ``‖R(E) − I‖_F`` (``rot_part``) or ``‖E − I‖_F`` (``full``).
    ``first_identity``: ``A = I`` and ``B = ref_k⁻¹ est_k`` (``i == j``): the APE's
    ``E_k = P_k⁻¹ Q_k`` when called with (estimate, reference).
    """

    def between(r: NDArray, t: NDArray) -> tuple[NDArray, NDArray]:
        ri_t = np.swapaxes(r[i], 1, 2)
        return ri_t @ r[j], np.einsum("nab,nb->na", ri_t, t[j] - t[i])

    if first_identity:
        ri_t = np.swapaxes(ref[0], 1, 2)
        ra, ta = np.broadcast_to(np.eye(3), ref[0].shape), np.zeros_like(ref[1])
        rb, tb = ri_t @ est[0], np.einsum("nab,nb->na", ri_t, est[1] - ref[1])
    else:
        ra, ta = between(*ref)
        rb, tb = between(*est)
    ra_t = np.swapaxes(ra, 1, 2)
    trans = np.linalg.norm(np.einsum("nab,nb->na", ra_t, tb - ta), axis=1)
    if rel == "trans_part":
        return trans
    rot = np.linalg.norm(ra_t @ rb - np.eye(3), axis=(1, 2))
    return rot if rel == "rot_part" else np.sqrt(rot * rot + trans * trans)


def pose_pairs(
    trajectory: Trajectory,
    delta: float,
    unit: str = "f",
    rel_tol: float = 0.1,
    all_pairs: bool = False,
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """evo's RPE pose pairs (``evo.core.metrics.id_pairs_from_delta``), vectorised.

    ``unit`` ``"f"`` (frames), ``"m"`` (metres of travelled path), ``"d"``/``"r"`` (degrees,
    radians of rotation). Consecutive pairs (``all_pairs=False``): a chain from pose 0, each
    pair starting where the last ended and ending at the first pose ``delta`` or more further
    on (frames: exactly ``delta`` further; angles: the rotation angles between neighbouring
    poses summed). ``all_pairs``: frames, every pose with the one ``delta`` later; metres, every
    pose i with the later pose whose path distance from i is nearest to ``delta`` (the first
    such), kept when within ``delta · rel_tol``; angles, every later pose whose direct rotation
    angle from i lies within ``delta ± delta · rel_tol``.

    Raises
    ------
    InputError
        For a negative or (frames) fractional ``delta``, an angle beyond [0°, 180°], or when
        no pair is found (evo's "empty index list").
    """
    if not delta >= 0:
        raise InputError(f"delta must be a positive number, got {delta}")
    if unit == "f":
        if delta != int(delta) or delta < 1:
            raise InputError(
                f"delta must be an integer >= 1 for delta unit f (frames), got {delta}"
            )
        rel = generate_relations(
            trajectory, "consecutive", step=int(delta), chained=not all_pairs, key="index"
        )
        i, j = rel.first.astype(np.int64), rel.second.astype(np.int64)
    elif unit == "m":
        i, j = _pairs_by_path(trajectory, delta, delta * rel_tol, all_pairs)
    elif unit in ("d", "r"):
        i, j = _pairs_by_angle(trajectory, delta, rel_tol, unit == "d", all_pairs)
    else:
        raise InputError(f"delta unit must be one of {', '.join(DELTA_UNITS)}, got {unit!r}")
    if i.size == 0:
        names = {"f": "frames", "m": "m", "d": "deg", "r": "rad"}
        raise InputError(
            f"delta = {delta} ({names[unit]}) produced an empty index list - try lower values "
            "or a less strict tolerance"
        )
    return i, j


def _pairs_by_path(
    trajectory: Trajectory, delta: float, tol: float, all_pairs: bool
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Pairs by travelled distance (``evo.core.filters.filter_pairs_by_path``)."""
    if not all_pairs:
        if delta == 0:  # every pose is "delta further on" than its predecessor
            n = len(trajectory)
            return np.arange(n - 1, dtype=np.int64), np.arange(1, n, dtype=np.int64)
        rel = generate_relations(trajectory, "distance", distance=delta, chained=True, key="index")
        return rel.first.astype(np.int64), rel.second.astype(np.int64)
    s = trajectory.path_length()
    n = s.size
    i = np.arange(n - 1, dtype=np.int64)
    # x_j = (s_j − s_i) − delta rises with j; |x_j| is least next to its first j with x_j ≥ 0
    # (u): at u or at the last j below it (l), ties to the earlier, as evo's argmin.
    u = np.searchsorted(s, s[i] + delta, side="left").astype(np.int64)
    u = np.maximum(u, i + 1)
    for _ in range(4):  # the exact test on evo's arithmetic moves u by a step at most
        below = (u < n) & ((s[np.minimum(u, n - 1)] - s[i]) - delta < 0)
        u = np.where(below, u + 1, u)
        back = (u - 1 > i) & ((s[u - 1] - s[i]) - delta >= 0)
        u = np.where(back, u - 1, u)
    lo = np.maximum(u - 1, i + 1)
    x_lo = np.abs((s[lo] - s[i]) - delta)
    x_up = np.where(u < n, np.abs((s[np.minimum(u, n - 1)] - s[i]) - delta), np.inf)
    use_lo = (u - 1 > i) & (x_lo <= x_up) | (u >= n)
    # among equal path distances (standing still) argmin takes the first pose
    first_lo = np.maximum(np.searchsorted(s, s[lo], side="left"), i + 1)
    j = np.where(use_lo, first_lo, u)
    best = np.where(use_lo, x_lo, x_up)
    keep = best <= tol
    return i[keep], j[keep].astype(np.int64)


def _pairs_by_angle(
    trajectory: Trajectory, delta: float, rel_tol: float, degrees: bool, all_pairs: bool
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Pairs by rotation angle (``evo.core.filters.filter_pairs_by_angle``)."""
    bound = 180.0 if degrees else math.pi
    if not 0.0 <= delta <= bound:
        raise InputError(f"delta angle must be within [0, {bound:g}], got {delta}")
    d = math.radians(delta) if degrees else float(delta)
    tol = math.radians(delta * rel_tol) if degrees else delta * rel_tol
    q = trajectory.poses[:, 3:]
    n = q.shape[0]
    if not all_pairs:
        steps = se3.rotation_angle(se3.quat_multiply(se3.quat_conjugate(q[:-1]), q[1:]))
        cum = np.concatenate(([0.0], np.cumsum(steps)))
        succ = np.maximum(np.searchsorted(cum, cum + d, side="left"), np.arange(1, n + 1))
        ids = chain_from_zero(succ.astype(np.int64), n)
        return ids[:-1], ids[1:]
    firsts, seconds = [], []
    for k in range(n - 1):  # all pairs are quadratic in the poses, as in evo
        angle = se3.rotation_angle(se3.quat_multiply(se3.quat_conjugate(q[k]), q[k + 1 :]))
        hit = np.flatnonzero((d - tol <= angle) & (angle <= d + tol)) + k + 1
        firsts.append(np.full(hit.size, k, dtype=np.int64))
        seconds.append(hit.astype(np.int64))
    if not firsts:
        return np.empty(0, np.int64), np.empty(0, np.int64)
    return np.concatenate(firsts), np.concatenate(seconds)


def project_to_plane(
    trajectory: Trajectory, plane: str, *, rotations: NDArray[np.float64] | None = None
) -> Trajectory:
    """Poses projected to ``plane`` as evo's ``PosePath3D.project`` does.

    The dropped axis (``xy``: z, ``xz``: y, ``yz``: x) is zeroed in the positions, and each
    rotation becomes the rotation about that axis by its static-xyz Euler angle about it
    (``transformations.euler_from_matrix(R, "sxyz")``). A KITTI drive (camera frame, y down)
    lies in ``xz``. ``rotations`` ``(N, 3, 3)``: the blocks the angles are read from (as a
    file gave them), instead of the trajectory's quaternions.
    """
    if plane not in PLANES:
        raise InputError(f"plane must be one of {', '.join(PLANES)}, got {plane!r}")
    axis = PLANE_NORMALS[plane]
    p = trajectory.lifted().poses
    r = se3.to_matrix(p)[:, :3, :3] if rotations is None else rotations
    cy = np.hypot(r[:, 0, 0], r[:, 1, 0])
    regular = cy > 4.0 * np.finfo(float).eps
    if axis == 0:
        angle = np.where(
            regular,
            np.arctan2(r[:, 2, 1], r[:, 2, 2]),
            np.arctan2(-r[:, 1, 2], r[:, 1, 1]),
        )
    elif axis == 1:
        angle = np.arctan2(-r[:, 2, 0], cy)
    else:
        angle = np.where(regular, np.arctan2(r[:, 1, 0], r[:, 0, 0]), 0.0)
    out = np.zeros_like(p)
    out[:, :3] = p[:, :3]
    out[:, axis] = 0.0
    out[:, 3 + axis] = np.sin(angle / 2.0)
    out[:, 6] = np.cos(angle / 2.0)
    return Trajectory(trajectory.timestamps, out)
