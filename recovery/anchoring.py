"""The frame a NEES is computed in: a SLAM map's anchoring to the truth frame (no I/O here).

A SLAM run builds its map in its own frame, fixed by the start pose it assumed
(``initial_pose``); a real map sits some decimetres and a degree or so off the frame of the
ground truth. The NEES compares *absolute* poses with their covariances, so that offset is
counted as pose error, at every pose, with the filter's (small) covariance: a consistent
recovery then looks badly inconsistent. The fix is to take the poses into the truth frame
first, by the rigid transform that takes the SLAM map's landmarks onto their true positions.

Convention
----------
The **anchoring** ``A = (dx, dy, dθ)`` is the transform *truth ← map*: a point ``p`` of the
map frame is ``R(dθ) p + [dx, dy]`` in the truth frame (``R`` the counter-clockwise
rotation), i.e. ``A`` is the pose of the map frame's origin and x axis in the truth frame.
It is the SE(2) least-squares fit ``min Σ_k ‖t_k − (R m_k + d)‖²`` over matched landmark
pairs (map position ``m_k``, true position ``t_k``; Umeyama's closed form,
:func:`relation_metric.alignment.umeyama`), at least 2 pairs. A pose ``[x, y, θ]`` and its
covariance ``P`` (rows ``[x, y, θ]``) are taken into the truth frame as

    [x', y'] = R(dθ) [x, y] + [dx, dy],   θ' = wrap(θ + dθ),   P' = J P Jᵀ,
    J = blockdiag(R(dθ), 1)

(only the x-y block rotates; the heading's variance and the rest follow by ``J``). The pose
NEES ``eᵀ P⁻¹ e`` with the world-frame error ``e = truth − pose`` is unchanged by any rigid
transform applied to both pose and truth, so the NEES after anchoring does not depend on the
frame the SLAM run chose, only on how far its map (and trajectory) is from the truth.

The anchoring is estimated from the map, not from the trajectory: aligning the trajectory on
its own ground truth would remove a real error of the recovered poses; the map's offset is
the frame the run chose. It is reported separately (``dx, dy, dθ``, the landmarks used and
the rms residual of the fit, which is the map's own error left after the alignment).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relation_metric import se2
from relation_metric.alignment import Alignment, umeyama
from relation_metric.arrays import Array
from relation_metric.trajectory import Trajectory

__all__ = [
    "ASSOCIATIONS",
    "Anchoring",
    "NeesFrame",
    "RigidSplit",
    "anchor_on_landmarks",
    "anchor_on_start",
    "gauge_jacobian",
    "rigid_split",
    "start_frame",
    "shared_by_id",
    "truth_at_start",
]

#: How the landmark pairs of an anchoring were found: by equal id, by
#: :func:`landmark_graph.landmark_association.associate_auto` (``map-compare --associate auto``)
#: or from an association file; ``"start"``: no landmarks, placed by the run's start pose.
ASSOCIATIONS = ("id", "auto", "file", "start")


@dataclass(frozen=True)
class Anchoring:
    """The truth ← map transform of a SLAM map, fitted on matched landmarks (module docstring).

    Attributes
    ----------
    dx, dy : float
        Position of the map frame's origin in the truth frame [m].
    dtheta : float
        Angle from the truth frame's x axis to the map frame's [rad], in ``[−π, π)``.
    landmarks : int
        Landmark pairs the transform was fitted on (≥ 2).
    association : str
        How the pairs were found (:data:`ASSOCIATIONS`).
    rms_residual : float
        ``√(1/K Σ ‖t_k − (R m_k + d)‖²)`` after the fit [m].
    """

    dx: float
    dy: float
    dtheta: float
    landmarks: int
    association: str
    rms_residual: float

    @property
    def alignment(self) -> Alignment:
        """As a :class:`~relation_metric.alignment.Alignment` (scale 1)."""
        return Alignment(self.dtheta, np.array([self.dx, self.dy]), 1.0)

    def apply(self, poses: ArrayLike, covariances: ArrayLike) -> tuple[Array, Array]:
        """Poses ``(N, 3)`` and their covariances ``(N, 3, 3)`` in the truth frame."""
        c, s = np.cos(self.dtheta), np.sin(self.dtheta)
        j = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        p = np.asarray(covariances, dtype=np.float64)
        return self.alignment.apply(poses), j @ p @ j.T

    def as_dict(self) -> dict[str, object]:
        """The report's ``anchoring`` (``dtheta`` in rad, also in degrees)."""
        return {
            "dx": self.dx,
            "dy": self.dy,
            "dtheta": self.dtheta,
            "dtheta_deg": float(np.degrees(self.dtheta)),
            "landmarks": self.landmarks,
            "association": self.association,
            "rms_residual": self.rms_residual,
        }


def anchor_on_landmarks(
    map_xy: ArrayLike, truth_xy: ArrayLike, *, association: str = "id"
) -> Anchoring:
    """The :class:`Anchoring` of a map: the SE(2) least-squares fit of ``map_xy`` onto
    ``truth_xy``, both ``(K, 2)``, row ``k`` of each the same landmark, ``K ≥ 2``.

    Raises :class:`~relation_metric.errors.InputError` for fewer than 2 pairs or mismatched
    shapes (:func:`~relation_metric.alignment.umeyama`).
    """
    m = np.asarray(map_xy, dtype=np.float64)
    t = np.asarray(truth_xy, dtype=np.float64)
    al = umeyama(m, t)
    res = t - al.apply(np.column_stack((m, np.zeros(m.shape[0]))))[:, :2]
    return Anchoring(
        dx=float(al.translation[0]),
        dy=float(al.translation[1]),
        dtheta=float(se2.wrap_angle(al.angle)),
        landmarks=int(m.shape[0]),
        association=association,
        rms_residual=float(np.sqrt(np.mean(np.sum(res * res, axis=1)))),
    )


def shared_by_id(
    map_ids: ArrayLike, truth_ids: ArrayLike
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Rows ``(map_rows, truth_rows)`` of the landmarks whose ids appear in both, by id."""
    _, a, b = np.intersect1d(np.asarray(map_ids), np.asarray(truth_ids), return_indices=True)
    return a.astype(np.int64), b.astype(np.int64)


@dataclass(frozen=True)
class NeesFrame:
    """The frame a NEES was computed in: the map frame anchored to the truth, or the truth frame.

    Attributes
    ----------
    anchoring : Anchoring or None
        The truth ← map transform applied to the poses and covariances first; ``None``: the
        poses were compared with the ground truth as they are (the truth frame).
    reason : str
        Why there is no anchoring (empty with one).
    """

    anchoring: Anchoring | None
    reason: str = ""
    map_anchoring: Anchoring | None = None

    @property
    def aligned(self) -> bool:
        return self.anchoring is not None

    @property
    def description(self) -> str:
        """E.g. ``"map frame aligned to the truth on 47 landmarks (by id)"``."""
        a = self.anchoring
        if a is None:
            return f"truth frame ({self.reason})" if self.reason else "truth frame"
        if a.association == "start":
            return "map frame placed in the truth frame by the run's start pose"
        how = {"id": "by id", "file": "associated from a file"}.get(
            a.association, "associated automatically"
        )
        return f"map frame aligned to the truth on {a.landmarks} landmarks ({how})"

    def as_dict(self) -> dict[str, object]:
        """The report's ``nees_frame``: ``frame`` (the description), ``aligned``, ``anchoring``."""
        m = self.map_anchoring
        return {
            "frame": self.description,
            "aligned": self.aligned,
            "anchoring": None if self.anchoring is None else self.anchoring.as_dict(),
            "map_anchoring": None if m is None else m.as_dict(),
        }

    @classmethod
    def by_id(
        cls,
        map_ids: ArrayLike,
        map_xy: ArrayLike,
        truth: tuple[ArrayLike, ArrayLike] | None,
    ) -> NeesFrame:
        """Anchored on the landmarks a map shares by id with the landmark ground truth
        ``truth = (ids, xy)``; the truth frame, with the reason, when fewer than 2 are shared."""
        if truth is None:
            return cls(None, "no landmark ground truth to align on")
        rm, rt = shared_by_id(map_ids, truth[0])
        if rm.size < 2:
            return cls(
                None, f"{rm.size} map landmark(s) share an id with the landmark ground truth"
            )
        xy, txy = np.asarray(map_xy), np.asarray(truth[1])
        return cls(anchor_on_landmarks(xy[rm], txy[rt], association="id"))


def anchor_on_start(
    initial_pose: ArrayLike, initial_covariance: ArrayLike, truth_start: ArrayLike
) -> Anchoring | None:
    """The truth ← map transform fixed by the run's start pose, or ``None`` when there is none.

    A filter-based SLAM run defines its map frame by the start pose it assumed
    (``initial_pose``, docs/bundle.md): the transform ``T = g₀ ∘ x₀⁻¹`` takes that pose onto
    the ground truth's pose ``g₀`` at the same time. ``None`` when the two agree within
    ``initial_covariance`` (Mahalanobis distance² ≤ the 99.99 % χ²₃ bound, with a 1 µm /
    1 µrad floor on the covariance): then the map frame *is* the truth frame, and the map's
    own offset from the true landmarks is a map error the covariances account for, not a frame.
    """
    from relation_metric.consistency import OUTLIER_PROBABILITY, chi2_quantile

    x0 = np.asarray(initial_pose, dtype=np.float64)
    g0 = np.asarray(truth_start, dtype=np.float64)
    e = g0 - x0
    e[2] = float(se2.wrap_angle(e[2]))
    p = np.asarray(initial_covariance, dtype=np.float64) + 1e-12 * np.eye(3)
    if float(e @ np.linalg.solve(p, e)) <= chi2_quantile(OUTLIER_PROBABILITY, 3):
        return None
    t = se2.compose(g0, se2.inverse(x0))
    return Anchoring(
        dx=float(t[0]),
        dy=float(t[1]),
        dtheta=float(se2.wrap_angle(t[2])),
        landmarks=0,
        association="start",
        rms_residual=0.0,
    )


def truth_at_start(truth: Trajectory, t0: float, *, tolerance: float = 1e-6) -> Array | None:
    """The ground truth's pose at the log's start time ``t0`` (interpolated), or ``None`` when
    the ground truth does not cover ``t0`` (within ``tolerance`` [s]): then it says nothing
    about the run's start pose (clamping to its first pose would invent one)."""
    lo, hi = truth.span()
    if not lo - tolerance <= t0 <= hi + tolerance:
        return None
    return truth.poses_at(np.array([t0]))[0]


def start_frame(
    initial_pose: ArrayLike,
    initial_covariance: ArrayLike,
    truth_start: ArrayLike | None,
    map_anchoring: Anchoring | None = None,
) -> NeesFrame:
    """The default :class:`NeesFrame`: placed by the start pose (:func:`anchor_on_start`).

    ``map_anchoring`` (the landmark fit of :func:`anchor_on_landmarks`, in the map frame) is
    reported beside it, not applied: it is how far the map sits off the true landmarks.
    ``truth_start`` ``None`` (the ground truth does not cover the log's start,
    :func:`truth_at_start`): the start pose cannot be checked, and the poses are compared as
    they are, which the reason says.
    """
    if truth_start is None:
        return NeesFrame(
            None,
            "the ground truth does not cover the log's start, so the run's start pose cannot "
            "be checked against it; poses compared as they are",
            map_anchoring,
        )
    a = anchor_on_start(initial_pose, initial_covariance, truth_start)
    reason = "" if a is not None else "the run's start pose is the ground truth's"
    return NeesFrame(a, reason, map_anchoring)


@dataclass(frozen=True)
class RigidSplit:
    """A map's error split into a rigid motion of the whole map and what is left (issue 36).

    With ``m`` the estimated landmarks and ``t`` the true ones, both ``(n, 2)``, the rigid part
    is the motion ``T(p) = R(θ) p + d`` of the *true* map that comes closest to the estimate in
    the metric ``W`` of the map's stated covariance ``P`` (``W = P⁻¹``; the identity without
    one) — the gauge of the map, a translation and a rotation no landmark measurement fixes:

        (R1)  T̂ = argmin_T  ρ(T)ᵀ W ρ(T),   ρ(T) = vec(m) − vec(T(t))   (2n,)
        (R2)  rigid part     g = vec(T̂(t)) − vec(t),   residual  r = ρ(T̂),   g + r = vec(m − t)
        (R3)  NEES_rigid = eᵀ W e − rᵀ W r,   NEES_residual = rᵀ W r,   e = vec(m − t)

    ``vec`` stacks ``[x₀, y₀, x₁, y₁, …]``, the order of ``bundle.map_covariance``. (R1) is
    solved by Gauss–Newton from Umeyama's unweighted closed form (exact for ``W = I``). When
    ``e ~ N(0, P)`` and ``T`` is linearised (small angle), (R3) splits the map's NEES
    ``eᵀ P⁻¹ e ~ χ²_{2n}`` into the P⁻¹-orthogonal projection of ``e`` on the 3 gauge
    directions, χ²₃, and its complement, χ²_{2n−3} (Cochran): a map drawn from its stated
    covariance has both about their degrees of freedom; a map whose covariance under-states the
    gauge (a filter's spurious heading information) has the rigid NEES too large only.

    Attributes
    ----------
    dx, dy, dtheta : float
        ``T̂``: the true map moved by ``R(dθ) p + [dx, dy]`` is closest to the estimate
        (``dθ`` in rad, ``[−π, π)``): the estimate ≈ the truth moved by it.
    rigid : ndarray, shape (n, 2)
        ``T̂(t) − t``, the rigid part of the error ``m − t`` [m].
    residual : ndarray, shape (n, 2)
        ``m − T̂(t)``, the rest [m].
    nees_rigid, nees_residual : float or None
        (R3) over 3 and ``2n − 3`` degrees of freedom; ``None`` without a covariance.
    """

    dx: float
    dy: float
    dtheta: float
    rigid: Array
    residual: Array
    nees_rigid: float | None
    nees_residual: float | None

    @property
    def dof_rigid(self) -> int:
        return 3

    @property
    def dof_residual(self) -> int:
        return 2 * int(self.rigid.shape[0]) - 3

    def remove(
        self, map_xy: ArrayLike, map_covariance: ArrayLike | None = None
    ) -> tuple[Array, Array | None]:
        """A map ``(M, 2)`` (and its covariance ``(2M, 2M)``) moved by ``T̂⁻¹``: the estimate's
        rigid part taken away, its shape (every distance between landmarks) kept; the
        covariance rotated by ``blockdiag(R(−dθ), …)``."""
        c, s = np.cos(self.dtheta), np.sin(self.dtheta)
        rinv = np.array([[c, s], [-s, c]])
        xy = (np.asarray(map_xy, dtype=np.float64) - [self.dx, self.dy]) @ rinv.T
        if map_covariance is None:
            return xy, None
        p = np.asarray(map_covariance, dtype=np.float64)
        m = p.shape[0] // 2
        q = p.reshape(m, 2, m, 2)
        q = np.einsum("ab,ibjc,dc->iajd", rinv, q, rinv)
        return xy, q.reshape(2 * m, 2 * m)


def gauge_jacobian(rotated: Array) -> Array:
    """``∂ vec(T(t)) / ∂ [dx, dy, θ]``, ``(2n, 3)``, with ``rotated = R(θ) t``
    (``R'(θ) t = J R(θ) t``, ``J`` the quarter turn)."""
    n = rotated.shape[0]
    g = np.zeros((n, 2, 3))
    g[:, 0, 0] = 1.0
    g[:, 1, 1] = 1.0
    g[:, 0, 2] = -rotated[:, 1]
    g[:, 1, 2] = rotated[:, 0]
    return g.reshape(2 * n, 3)


def rigid_split(
    map_est: ArrayLike, map_true: ArrayLike, cov: ArrayLike | None = None
) -> RigidSplit:
    """The :class:`RigidSplit` of an estimated map ``(n, 2)`` against the true one ``(n, 2)``
    (row ``k`` of each the same landmark, ``n ≥ 2``), in the metric of ``cov`` ``(2n, 2n)``
    (``[x, y]`` per landmark, the estimate's covariance) or unweighted without it.

    Raises :class:`~relation_metric.errors.InputError` for mismatched shapes, fewer than 2
    landmarks, or a covariance that is not symmetric positive definite.
    """
    from relation_metric.errors import InputError

    m = np.asarray(map_est, dtype=np.float64)
    t = np.asarray(map_true, dtype=np.float64)
    if m.ndim != 2 or m.shape[1:] != (2,) or m.shape != t.shape or m.shape[0] < 2:
        raise InputError(
            "rigid split: two maps of the same shape (n ≥ 2, 2) expected, "
            f"got {m.shape} and {t.shape}"
        )
    n = m.shape[0]
    e = (m - t).reshape(-1)
    al = umeyama(t, m)
    d, th = np.array(al.translation[:2], dtype=np.float64), float(al.angle)
    w: Array | None = None
    if cov is not None:
        p = np.asarray(cov, dtype=np.float64)
        if p.shape != (2 * n, 2 * n) or not np.allclose(p, p.T, rtol=1e-9, atol=1e-15):
            raise InputError(
                f"rigid split: a symmetric ({2 * n}, {2 * n}) covariance expected, got {p.shape}"
            )
        try:
            chol = np.linalg.cholesky(p)
        except np.linalg.LinAlgError:
            raise InputError("rigid split: the map covariance is not positive definite") from None
        w = np.linalg.inv(chol)  # whitening: W = wᵀ w
        for _ in range(50):
            moved = _moved(t, d, th)
            a = w @ gauge_jacobian(moved - d)
            b = w @ (m - moved).reshape(-1)
            step = np.linalg.lstsq(a, b, rcond=None)[0]
            d, th = d + step[:2], th + float(step[2])
            if float(np.max(np.abs(step))) < 1e-14:
                break
    moved = _moved(t, d, th)
    residual = m - moved
    nr = nt = None
    if w is not None:
        we, wr = w @ e, w @ residual.reshape(-1)
        nr = float(wr @ wr)
        nt = float(we @ we) - nr
    return RigidSplit(
        dx=float(d[0]),
        dy=float(d[1]),
        dtheta=float(se2.wrap_angle(th)),
        rigid=moved - t,
        residual=residual,
        nees_rigid=nt,
        nees_residual=nr,
    )


def _moved(t: Array, d: Array, theta: float) -> Array:
    """``R(θ) t + d`` for points ``t`` ``(n, 2)``."""
    c, s = np.cos(theta), np.sin(theta)
    return t @ np.array([[c, -s], [s, c]]).T + d
