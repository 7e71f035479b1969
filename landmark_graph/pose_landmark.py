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

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relation_metric import se2
from relation_metric.errors import InputError
from relation_metric.relations import RelationSet
from relation_metric.trajectory import Trajectory

__all__ = ["pose_landmark_errors", "shared_landmark_relations"]


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


def shared_landmark_relations(
    reference: Trajectory,
    pose: ArrayLike,
    landmark: ArrayLike,
    *,
    min_common: int = 3,
    min_gap: int = 1,
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
    """
    k = np.asarray(pose, dtype=np.int64)
    ids, lm = np.unique(np.asarray(landmark, dtype=np.int64), return_inverse=True)
    n = len(reference)
    if k.size and (k.min() < 0 or k.max() >= n):
        raise InputError(f"pose index out of range 0..{n - 1}")
    import scipy.sparse as sp

    seen = sp.csr_matrix((np.ones(k.size), (k, lm.ravel())), shape=(n, ids.size))
    seen.data[:] = 1.0  # an observation repeated at one pose counts once
    common = (seen @ seen.T).tocoo()
    keep = (common.col - common.row >= max(min_gap, 1)) & (common.data >= min_common)
    i, j = common.row[keep], common.col[keep]
    order = np.lexsort((j, i))
    return RelationSet.from_trajectory_pairs(reference, i[order], j[order], key="index")
