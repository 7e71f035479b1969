"""Reference relations from an optimised pose graph (Cartographer's
``autogenerate_ground_truth``), pure maths on a :class:`~slamrel.backends.graph.PoseGraph`.

The graph's vertices are taken as its optimum ``x`` (poses in increasing id order). Its
pose–pose edges ``z_ij ≈ x_i⁻¹ ∘ x_j`` are

* **sequential** when ``i`` and ``j`` are consecutive poses (``|i − j| = 1`` in id order:
  the odometry or scan-matching chain; Cartographer's ``INTRA_SUBMAP``), and
* **loop closures** otherwise.

A loop closure becomes a relation ``(i, j, z_ij)`` — the constraint itself, as Cartographer
writes its ``expected`` — when

1. the distance travelled between its poses along the optimum,
   ``|s_j − s_i|`` with ``s_k = Σ_{m<k} ‖t(x_m⁻¹ ∘ x_{m+1})‖``, is at least ``min_travel``
   (``min_covered_distance``, 100 m by default), and
2. it agrees with the optimum: the error ``E = (x_i⁻¹ ∘ x_j) ∘ z_ij⁻¹`` has
   ``‖t(E)‖ ≤ max_error_xy`` (``outlier_threshold_meters``, 0.15 m) and
   ``|θ(E)| ≤ max_error_theta`` (``outlier_threshold_radians``, 0.02 rad).

The defaults are those of Cartographer's ``autogenerate_ground_truth_main.cc`` flags.
Every loop closure is counted as kept or dropped with its reason.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from relation_metric.se2 import between, compose, inverse
from slamrel.backends.graph import PoseGraph
from slamrel.constants import GRAPH_MAX_ERROR_THETA, GRAPH_MAX_ERROR_XY, GRAPH_MIN_TRAVEL

__all__ = ["GraphRelations", "graph_relations", "MIN_TRAVEL", "MAX_ERROR_XY", "MAX_ERROR_THETA"]

#: Cartographer's defaults (``autogenerate_ground_truth_main.cc``; :mod:`slamrel.constants`).
MIN_TRAVEL, MAX_ERROR_XY, MAX_ERROR_THETA = (
    GRAPH_MIN_TRAVEL,
    GRAPH_MAX_ERROR_XY,
    GRAPH_MAX_ERROR_THETA,
)

#: Reasons a loop closure is dropped.
SHORT, OUTLIER = "short travel", "outlier"


@dataclass(frozen=True)
class GraphRelations:
    """The loop closures of a graph and the verdict on each (``L`` loop closures).

    Attributes
    ----------
    edge : (L,) int
        Index of each loop closure among the graph's pose–pose edges.
    first, second : (L,) int
        Pose indices (increasing id order) of its ends.
    delta : (L, 3) float
        The constraint ``z_ij``.
    travel : (L,) float
        Distance travelled between its poses along the optimum [m].
    error_xy, error_theta : (L,) float
        ``‖t(E)‖`` [m] and ``|θ(E)|`` [rad] of ``E = (x_i⁻¹ ∘ x_j) ∘ z_ij⁻¹``.
    reason : (L,) str
        Why it was dropped: ``"short travel"`` (checked first), ``"outlier"``; ``""`` kept.
    sequential : int
        Pose–pose edges between consecutive poses (not candidates).
    """

    edge: NDArray[np.int64]
    first: NDArray[np.int64]
    second: NDArray[np.int64]
    delta: NDArray[np.float64]
    travel: NDArray[np.float64]
    error_xy: NDArray[np.float64]
    error_theta: NDArray[np.float64]
    reason: NDArray[np.str_]
    sequential: int

    @property
    def kept(self) -> NDArray[np.bool_]:
        return self.reason == ""

    def counts(self) -> dict[str, int]:
        """Loop closures kept and dropped by reason."""
        return {
            "kept": int(np.count_nonzero(self.kept)),
            SHORT: int(np.count_nonzero(self.reason == SHORT)),
            OUTLIER: int(np.count_nonzero(self.reason == OUTLIER)),
        }


def graph_relations(
    graph: PoseGraph,
    *,
    min_travel: float = MIN_TRAVEL,
    max_error_xy: float = MAX_ERROR_XY,
    max_error_theta: float = MAX_ERROR_THETA,
) -> GraphRelations:
    """The loop closures of ``graph`` judged against its vertices (module docstring).

    ``graph.poses`` (N, 3) are the optimum, in the order of increasing vertex id.
    """
    x = graph.poses
    i, j = graph.pp_i, graph.pp_j
    loop = np.abs(i - j) != 1
    steps = between(x[:-1], x[1:])
    s = np.concatenate(([0.0], np.cumsum(np.hypot(steps[:, 0], steps[:, 1]))))
    li, lj, z = i[loop], j[loop], graph.pp_z[loop]
    travel = np.abs(s[lj] - s[li])
    err = compose(between(x[li], x[lj]), inverse(z))
    exy, eth = np.hypot(err[:, 0], err[:, 1]), np.abs(err[:, 2])
    reason = np.where(
        travel < min_travel,
        SHORT,
        np.where((exy > max_error_xy) | (eth > max_error_theta), OUTLIER, ""),
    )
    return GraphRelations(
        edge=np.flatnonzero(loop),
        first=li,
        second=lj,
        delta=z.copy(),
        travel=travel,
        error_xy=exy,
        error_theta=eth,
        reason=reason.astype(str),
        sequential=int(np.count_nonzero(~loop)),
    )
