"""The landmark–pose graph: relations between poses and the landmarks they observed.

For a pose ``x_t`` that observed landmark ``l`` (a data association of the SLAM run), the
relation is the landmark in the pose frame, ``x_t⁻¹ · l`` (``relation_metric.se2.
inverse_transform_points``); its error against the same relation from the reference,
``‖x_t⁻¹ · l − x*_t⁻¹ · l*‖``, ties trajectory and map errors together and, like the relation
metric, does not depend on the frame of either solution.

Pose–pose relations through shared landmarks: two poses that observed at least ``k`` common
landmarks form a relation of the relation metric (index-keyed), so a trajectory can be scored
on exactly the pairs the map connects.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from landmark_graph.covisibility import covisible_pairs
from landmark_graph.landmark_association import Association
from landmark_graph.maps import LandmarkMap
from relation_metric import se2
from relation_metric.errors import InputError
from relation_metric.evaluate import error_summaries
from relation_metric.ids import first_missing, rows_of
from relation_metric.relations import RelationSet
from relation_metric.trajectory import Trajectory, readonly

__all__ = [
    "pose_landmark_errors",
    "PoseLandmarkErrors",
    "pose_landmark_relations",
    "shared_landmark_relations",
]


def pose_landmark_errors(
    poses: ArrayLike,
    landmarks: ArrayLike,
    reference_poses: ArrayLike,
    reference_landmarks: ArrayLike,
) -> NDArray[np.float64]:
    """``‖x_t⁻¹ · l − x*_t⁻¹ · l*‖`` for K (pose, landmark) links, shape (K,).

    Parameters
    ----------
    poses, reference_poses : array_like, shape (K, 3)
        The observing pose of each link, estimated and reference.
    landmarks, reference_landmarks : array_like, shape (K, 2)
        The observed landmark of each link, estimated and reference (already associated).
    """
    p, r = np.asarray(poses, float), np.asarray(reference_poses, float)
    lm, lr = np.asarray(landmarks, float), np.asarray(reference_landmarks, float)
    if not (p.shape == r.shape and lm.shape == lr.shape and p.shape[0] == lm.shape[0]):
        raise InputError(
            f"links need matching shapes, got {p.shape}, {lm.shape}, {r.shape}, {lr.shape}"
        )
    d = se2.inverse_transform_points(p, lm) - se2.inverse_transform_points(r, lr)
    return np.hypot(d[:, 0], d[:, 1])


@dataclass(frozen=True)
class PoseLandmarkErrors:
    """Pose–landmark relation errors of the observations whose landmark is associated.

    Attributes
    ----------
    pose : ndarray of int, shape (K,)
        Pose index of each scored observation.
    landmark : ndarray of int, shape (K,)
        Its landmark id in the estimated map.
    error : ndarray, shape (K,)
        ``‖x_t⁻¹ · l − x*_t⁻¹ · l*‖`` [m].
    unassociated : int
        Observations left out because their landmark has no reference counterpart.
    """

    pose: NDArray[np.int64]
    landmark: NDArray[np.int64]
    error: NDArray[np.float64]
    unassociated: int

    def as_dict(self) -> dict[str, Any]:
        """``relations``, ``unassociated`` and ``translation`` → ``abs``/``sqr`` → statistics."""
        return {
            "relations": int(self.error.size),
            "unassociated": self.unassociated,
            "translation": error_summaries(self.error).as_dict(),
        }


def pose_landmark_relations(
    poses: ArrayLike,
    reference_poses: ArrayLike,
    pose: ArrayLike,
    landmark: ArrayLike,
    estimate: LandmarkMap,
    reference: LandmarkMap,
    association: Association,
) -> PoseLandmarkErrors:
    """Pose–landmark relation errors from a SLAM run's data associations.

    Parameters
    ----------
    poses, reference_poses : array_like, shape (N, 3)
        The estimated (e.g. recovered) trajectory and the reference at the same N instants.
    pose : array_like of int, shape (K,)
        The pose index of each observation.
    landmark : array_like of int, shape (K,)
        The estimated-map landmark id the SLAM run associated each observation with.
    estimate, reference : LandmarkMap
    association : Association
        Between ``estimate`` and ``reference`` (``landmark_graph.landmark_association``).

    Returns
    -------
    PoseLandmarkErrors
        Observations of landmarks without a reference counterpart are counted, not scored.

    Raises
    ------
    InputError
        A pose index out of range or a landmark id that is not in ``estimate``.
    """
    x = np.asarray(poses, dtype=np.float64)
    xr = np.asarray(reference_poses, dtype=np.float64)
    k = np.asarray(pose, dtype=np.int64)
    lid = np.asarray(landmark, dtype=np.int64)
    if x.shape != xr.shape or x.ndim != 2 or x.shape[1] != 3 or k.shape != lid.shape:
        raise InputError(
            f"expected (N, 3) poses twice and K observations, got {x.shape}, {xr.shape}, "
            f"{k.shape}, {lid.shape}"
        )
    if k.size and (k.min() < 0 or k.max() >= x.shape[0]):
        bad_k = int(np.flatnonzero((k < 0) | (k >= x.shape[0]))[0])
        raise InputError(
            f"observation {bad_k}: pose index {int(k[bad_k])} outside 0..{x.shape[0] - 1}"
        )
    row = rows_of(estimate.ids, lid)
    bad = first_missing(row)
    if bad is not None:
        raise InputError(f"observation {bad}: landmark id {int(lid[bad])} is not in the map")
    ref_row = np.full(len(estimate), -1, dtype=np.int64)
    ref_row[association.estimate_rows] = association.reference_rows
    r = ref_row[row]
    ok = r >= 0
    err = pose_landmark_errors(x[k[ok]], estimate.xy[row[ok]], xr[k[ok]], reference.xy[r[ok]])
    return PoseLandmarkErrors(
        readonly(k[ok], np.int64), readonly(lid[ok], np.int64), readonly(err), int((~ok).sum())
    )


def shared_landmark_relations(
    reference: Trajectory,
    pose: ArrayLike,
    landmark: ArrayLike,
    *,
    min_common: int = 3,
    min_gap: int = 1,
    max_pairs: float = 2e7,
) -> RelationSet:
    """Index relations between poses that observed ≥ ``min_common`` common landmarks.

    Parameters
    ----------
    reference : Trajectory
        Gives ``δ*`` of each pair.
    pose, landmark : array_like of int, shape (K,)
        The observing pose index and the landmark id of each observation.
    min_gap : int
        Only pairs ``i < j`` with ``j − i ≥ min_gap``.
    max_pairs : float
        Refuse (with :class:`InputError`) when ``Σ_l C(n_l, 2)`` — ``n_l`` the poses that
        observed landmark ``l``, a bound on the pose pairs to examine — exceeds this: the
        sparse product ``S Sᵀ`` of the pose × landmark incidence matrix would not fit
        (:func:`landmark_graph.covisibility.covisible_pairs`).
    """
    i, j, _ = covisible_pairs(
        pose, landmark, len(reference), min_common=min_common, min_gap=min_gap, max_pairs=max_pairs
    )
    return RelationSet.from_trajectory_pairs(reference, i, j, key="index")
