"""Pose pairs that observed common landmarks (covisibility), computed sparse.

A SLAM log's observations are ``(pose, landmark)`` pairs. Two consumers need "which poses
share which landmarks": the landmark–pose graph scores trajectories on pose pairs that share
landmarks (:func:`landmark_graph.pose_landmark.shared_landmark_relations`), and pose-only
least squares builds a relative-pose constraint from the landmarks a pair shares
(:mod:`slamrel.backends.pose_only`). Both go through this module; nothing here is
quadratic in the number of poses or dense in poses × landmarks:

* :func:`covisible_pairs` — all pairs ``i < j`` sharing at least ``min_common`` landmarks,
  from the sparse product ``S Sᵀ`` of the pose × landmark incidence matrix ``S``;
* :func:`shared_observations` — for given pairs, the shared landmarks and the observation
  of each at both poses, by a sorted join on ``(pose, landmark)`` keys.

An observation repeated at one pose (the same landmark twice) counts once; the last one in
the input is the one reported.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relation_metric.errors import InputError

__all__ = ["covisible_pairs", "shared_observations", "SharedObservations"]


def _observations(
    pose: ArrayLike, landmark: ArrayLike, n_poses: int
) -> tuple[NDArray[np.int64], NDArray[np.int64], int]:
    """Pose indices (K,), dense landmark indices (K,) (``np.unique`` order) and their count."""
    k = np.asarray(pose, dtype=np.int64).ravel()
    lid = np.asarray(landmark, dtype=np.int64).ravel()
    if k.shape != lid.shape:
        raise InputError(
            f"pose and landmark need one entry per observation, got {k.size}, {lid.size}"
        )
    if k.size and (k.min() < 0 or k.max() >= n_poses):
        raise InputError(f"pose index out of range 0..{n_poses - 1}")
    ids, lm = np.unique(lid, return_inverse=True)
    return k, lm.ravel(), int(ids.size)


def covisible_pairs(
    pose: ArrayLike,
    landmark: ArrayLike,
    n_poses: int,
    *,
    min_common: int = 1,
    min_gap: int = 1,
    max_pairs: float = float("inf"),
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """Pose pairs ``i < j`` (``j − i ≥ min_gap``) that observed ``≥ min_common`` common landmarks.

    Parameters
    ----------
    pose, landmark : array_like of int, shape (K,)
        The observing pose index (``0 .. n_poses − 1``) and the landmark id of each
        observation.
    n_poses : int
    min_common : int
        Fewest distinct shared landmarks.
    min_gap : int
        Smallest ``j − i`` (at least 1).
    max_pairs : float
        Refuse (:class:`InputError`) when ``Σ_l C(n_l, 2)`` — ``n_l`` the poses that
        observed landmark ``l``, a bound on the pairs ``S Sᵀ`` holds — exceeds this.

    Returns
    -------
    i, j : ndarray of int, shape (E,)
        Sorted by ``i``, then ``j``.
    common : ndarray of int, shape (E,)
        Distinct landmarks each pair shares.
    """
    import scipy.sparse as sp  # lazily: relation_metric imports no scipy at import time

    k, lm, n_lm = _observations(pose, landmark, n_poses)
    seen = sp.csr_matrix((np.ones(k.size), (k, lm)), shape=(n_poses, n_lm))
    seen.data[:] = 1.0  # an observation repeated at one pose counts once
    per_landmark = np.diff(seen.tocsc().indptr).astype(np.float64)
    bound = float((per_landmark * (per_landmark - 1) / 2).sum())  # ≥ candidate pairs
    if bound > max_pairs:
        raise InputError(
            f"up to {bound:.3g} pose pairs share a landmark (limit max_pairs = {max_pairs:.3g}); "
            "pass fewer poses (e.g. every k-th) or raise max_pairs"
        )
    common = sp.triu(seen @ seen.T, k=max(min_gap, 1)).tocoo()
    keep = common.data >= min_common
    i, j = common.row[keep].astype(np.int64), common.col[keep].astype(np.int64)
    order = np.lexsort((j, i))
    return i[order], j[order], np.rint(common.data[keep][order]).astype(np.int64)


class SharedObservations(NamedTuple):
    """The landmarks each pose pair shares, one row per (pair, landmark).

    Attributes
    ----------
    pair : ndarray of int, shape (R,)
        Index into the pairs; rows sorted by pair, then by landmark.
    landmark : ndarray of int, shape (R,)
        Dense landmark index (position in ``np.unique(landmark)``).
    first, second : ndarray of int, shape (R,)
        The observation (index into the K observations) of the landmark at the pair's first
        and second pose.
    """

    pair: NDArray[np.int64]
    landmark: NDArray[np.int64]
    first: NDArray[np.int64]
    second: NDArray[np.int64]


def shared_observations(
    pose: ArrayLike, landmark: ArrayLike, n_poses: int, pairs: ArrayLike
) -> SharedObservations:
    """The landmarks both poses of each pair observed, and the two observations of each.

    A sorted join: the observations are sorted by the key ``pose · L + landmark``; each
    observation of a pair's first pose looks its landmark up at the second pose by binary
    search. Work and memory O(Σ_pairs observations at the first pose · log K).

    Parameters
    ----------
    pose, landmark : array_like of int, shape (K,)
        As :func:`covisible_pairs`.
    n_poses : int
    pairs : array_like of int, shape (E, 2)

    Returns
    -------
    SharedObservations
    """
    k, lm, n_lm = _observations(pose, landmark, n_poses)
    pr = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    if pr.size and (pr.min() < 0 or pr.max() >= n_poses):
        raise InputError(f"pair pose index out of range 0..{n_poses - 1}")
    if k.size == 0:
        empty = np.empty(0, dtype=np.int64)
        return SharedObservations(empty, empty, empty, empty)
    key = k * n_lm + lm
    order = np.argsort(key, kind="stable")
    skey = key[order]
    last = np.ones(skey.size, dtype=bool)  # the last of each repeated observation
    last[:-1] = skey[1:] != skey[:-1]
    skey, obs = skey[last], order[last]
    spose = skey // n_lm
    start = np.searchsorted(spose, np.arange(n_poses + 1))
    count = start[pr[:, 0] + 1] - start[pr[:, 0]]  # observations at each pair's first pose
    pair = np.repeat(np.arange(pr.shape[0]), count)
    offset = np.arange(pair.size) - np.repeat(np.cumsum(count) - count, count)
    a = start[pr[pair, 0]] + offset  # positions in the sorted observations
    want = pr[pair, 1] * n_lm + skey[a] % n_lm
    b = np.minimum(np.searchsorted(skey, want), skey.size - 1)
    hit = skey[b] == want
    a, b, pair = a[hit], b[hit], pair[hit]
    return SharedObservations(pair, skey[a] % n_lm, obs[a], obs[b])
