"""Full and pose-only least-squares SLAM from a landmark log (Hu, Huang & Dissanayake).

*Full* least squares estimates all poses and landmarks from odometry and every landmark
observation (:mod:`slamrel.backends.graph`).

*Pose-only* least squares first turns the landmark observations into relative-pose
constraints — for a pair of poses ``(i, j)`` that observed common landmarks, a small least
squares over ``δ_ij = x_i⁻¹ ∘ x_j`` and those landmarks (plus the odometry when ``j = i + 1``)
gives ``δ̂_ij`` and its marginal covariance, like scan matching would — and then optimises
the pose graph of these constraints. Because one observation enters several constraints,
the constraints are correlated although the pose graph treats them as independent: the
pose-only solution is less accurate and over-confident, which is what Hu et al. evaluate.

Range-bearing observations are used as relative positions ``z = r [cos b, sin b]`` with the
linearised covariance ``J diag(σ_r², σ_b²) Jᵀ``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from relation_metric import se2
from relation_metric.errors import InputError
from relation_metric.trajectory import Trajectory
from slamrel.backends.graph import (
    GraphSolution,
    PoseGraph,
    initial_landmarks,
    pose_covariances,
    solve_graph,
)

__all__ = [
    "LandmarkLog",
    "cartesian_observations",
    "full_least_squares",
    "pose_only_least_squares",
    "PoseOnlyResult",
]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class LandmarkLog:
    """Odometry poses and range-bearing landmark observations taken at those poses.

    Attributes
    ----------
    odometry : Trajectory
    pose : ndarray of int, shape (K,)
        Index of the observing odometry pose of each measurement.
    range, bearing : ndarray, shape (K,)
    landmark : ndarray of int, shape (K,)
        Known data association.
    sigma_odometry : tuple of 3 floats
        Per-step standard deviations of ``[dx, dy, dθ]``.
    sigma_range, sigma_bearing : float
    """

    odometry: Trajectory
    pose: NDArray[np.int64]
    range: Array
    bearing: Array
    landmark: NDArray[np.int64]
    sigma_odometry: tuple[float, float, float]
    sigma_range: float
    sigma_bearing: float


def cartesian_observations(log: LandmarkLog) -> tuple[Array, Array]:
    """Relative positions ``(K, 2)`` and their information matrices ``(K, 2, 2)``."""
    c, s = np.cos(log.bearing), np.sin(log.bearing)
    z = np.column_stack((log.range * c, log.range * s))
    j = np.empty((z.shape[0], 2, 2))
    j[:, 0, 0], j[:, 0, 1] = c, -log.range * s
    j[:, 1, 0], j[:, 1, 1] = s, log.range * c
    r = np.diag([log.sigma_range**2, log.sigma_bearing**2])
    cov = j @ r @ np.swapaxes(j, 1, 2)
    return z, np.linalg.inv(cov)


def _odometry_factors(log: LandmarkLog) -> tuple[NDArray[np.int64], Array, Array]:
    p = log.odometry.poses
    i = np.arange(p.shape[0] - 1)
    info = np.diag(1.0 / np.square(log.sigma_odometry))
    return i, se2.between(p[:-1], p[1:]), np.broadcast_to(info, (i.size, 3, 3)).copy()


def full_least_squares(log: LandmarkLog) -> tuple[GraphSolution, NDArray[np.int64]]:
    """All poses and landmarks from odometry + observations; returns the solution and ids."""
    z, info = cartesian_observations(log)
    ids, lm_index = np.unique(log.landmark, return_inverse=True)
    i, u, oinfo = _odometry_factors(log)
    poses0 = log.odometry.poses
    graph = PoseGraph(
        poses=poses0,
        landmarks=initial_landmarks(poses0, log.pose, lm_index, z, ids.size),
        pp_i=i,
        pp_j=i + 1,
        pp_z=u,
        pp_info=oinfo,
        pl_k=log.pose,
        pl_l=lm_index,
        pl_z=z,
        pl_info=info,
    )
    return solve_graph(graph), ids


@dataclass(frozen=True)
class PoseOnlyResult:
    """Pose-only least squares: the constraints and the optimised trajectory.

    Attributes
    ----------
    solution : GraphSolution
    pairs : ndarray of int, shape (E, 2)
        The pose pairs that became relative-pose constraints.
    delta, covariance : ndarray, shape (E, 3) and (E, 3, 3)
        The extracted constraints ``δ̂_ij`` and their marginal covariances.
    """

    solution: GraphSolution
    pairs: NDArray[np.int64]
    delta: Array
    covariance: Array

    @property
    def trajectory(self) -> Trajectory:
        return Trajectory.from_poses(self.solution.poses)


def pose_only_least_squares(
    log: LandmarkLog, *, min_common: int = 3, min_gap: int = 5, max_loop_pairs: int = 2000
) -> PoseOnlyResult:
    """Extract relative-pose constraints from shared landmarks, then optimise the pose graph.

    Parameters
    ----------
    log : LandmarkLog
    min_common : int
        Landmarks two non-consecutive poses must share to form a constraint.
    min_gap : int
        Minimum index distance of a non-consecutive pair (loop constraints).
    max_loop_pairs : int
        At most this many loop pairs, those with the most shared landmarks first.
    """
    n = len(log.odometry)
    if n < 2:
        raise InputError("pose-only least squares needs at least 2 poses")
    z, info = cartesian_observations(log)
    ids, lm_index = np.unique(log.landmark, return_inverse=True)
    seen = np.zeros((n, ids.size), dtype=np.int64)
    seen[log.pose, lm_index] = 1
    common = seen @ seen.T
    gi, gj = np.nonzero(np.triu(common >= min_common, k=min_gap))
    if gi.size > max_loop_pairs:
        keep = np.argsort(-common[gi, gj], kind="stable")[:max_loop_pairs]
        gi, gj = gi[keep], gj[keep]
    pairs = np.concatenate(
        (np.column_stack((np.arange(n - 1), np.arange(1, n))), np.column_stack((gi, gj)))
    )
    odo_i, odo_u, odo_info = _odometry_factors(log)
    # observation lookup: for each pose, its measurement rows
    order = np.argsort(log.pose, kind="stable")
    starts = np.searchsorted(log.pose[order], np.arange(n + 1))
    deltas = np.empty((pairs.shape[0], 3))
    covs = np.empty((pairs.shape[0], 3, 3))
    p_odo = log.odometry.poses
    for e, (a, b) in enumerate(pairs):
        ra = order[starts[a] : starts[a + 1]]
        rb = order[starts[b] : starts[b + 1]]
        shared, ia, ib = np.intersect1d(lm_index[ra], lm_index[rb], return_indices=True)
        consecutive = b == a + 1
        guess = se2.between(p_odo[a], p_odo[b])
        if shared.size == 0:
            deltas[e], covs[e] = odo_u[a], np.linalg.inv(odo_info[a])
            continue
        rows_a, rows_b = ra[ia], rb[ib]
        m = shared.size
        local = PoseGraph(
            poses=np.array([[0.0, 0.0, 0.0], guess]),
            landmarks=z[rows_a],
            pp_i=np.array([0] if consecutive else [], dtype=np.int64),
            pp_j=np.array([1] if consecutive else [], dtype=np.int64),
            pp_z=odo_u[a : a + 1] if consecutive else np.empty((0, 3)),
            pp_info=odo_info[a : a + 1] if consecutive else np.empty((0, 3, 3)),
            pl_k=np.concatenate((np.zeros(m, np.int64), np.ones(m, np.int64))),
            pl_l=np.concatenate((np.arange(m), np.arange(m))),
            pl_z=np.concatenate((z[rows_a], z[rows_b])),
            pl_info=np.concatenate((info[rows_a], info[rows_b])),
        )
        sol = solve_graph(local, max_iterations=30)
        deltas[e] = sol.poses[1]
        covs[e] = pose_covariances(local, sol, [1])[0]
    graph = PoseGraph(
        poses=p_odo,
        landmarks=np.empty((0, 2)),
        pp_i=pairs[:, 0],
        pp_j=pairs[:, 1],
        pp_z=deltas,
        pp_info=np.linalg.inv(covs),
    )
    return PoseOnlyResult(solve_graph(graph), pairs, deltas, covs)
