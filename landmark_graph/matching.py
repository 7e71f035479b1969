"""Optimal matching of two point sets on the pairs within a cut-off, in sparse form.

One home for the min-weight bipartite matching that both the automatic landmark
association (:mod:`landmark_graph.landmark_association`) and the OSPA/GOSPA distances of
large maps (:mod:`landmark_graph.set_distances`) solve: only pairs closer than the cut-off
are candidates, so the problem takes ``O(m + n + pairs)`` memory instead of a dense
``m × n`` matrix.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

__all__ = ["sparse_matching"]


def sparse_matching(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    cutoff: float,
    *,
    power: float,
    cost_x: float,
    cost_y: float,
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
    """Min-weight matching on the pairs closer than ``cutoff``: ``d^power`` per pair,
    ``cost_x`` per unmatched ``x``, ``cost_y`` per unmatched ``y``; the matched rows and
    their distances. The square augmentation ``[[D^p, cost_x I], [cost_y I, (D^p)ᵀ-pattern at
    ~0]]`` always has a full matching (the two identities); the pair weights get a tiny
    ``eps`` (and a zero cost is ``eps``) so that none is an implicit zero of the sparse
    matrix.

    Parameters
    ----------
    x, y : ndarray, shape (m, 2) and (n, 2)
        The two point sets [m].
    cutoff : float
        Pairs at this distance or farther are never matched.
    power : float
        The exponent ``p`` of a matched pair's cost ``d^p``.
    cost_x, cost_y : float
        The cost of leaving one point of ``x`` (of ``y``) unmatched.

    Returns
    -------
    rows_x, rows_y : ndarray of int, shape (K,)
        The matched rows of ``x`` and ``y``.
    distances : ndarray, shape (K,)
        The distance of each matched pair.
    """
    import scipy.sparse as sp
    from scipy.sparse.csgraph import min_weight_full_bipartite_matching

    m, n = x.shape[0], y.shape[0]
    d = cKDTree(x).sparse_distance_matrix(cKDTree(y), cutoff, output_type="coo_matrix")
    keep = d.data < cutoff
    i, j, dist = d.row[keep], d.col[keep], d.data[keep]
    w = dist**power
    eps = 1e-9 * max(cutoff**power, 1e-300)
    rows = np.concatenate((i, np.arange(m), m + np.arange(n), m + j))
    cols = np.concatenate((j, n + np.arange(m), np.arange(n), n + i))
    cx, cy = (cost if cost > 0 else eps for cost in (cost_x, cost_y))
    vals = np.concatenate((w + eps, np.full(m, cx), np.full(n, cy), np.full(i.size, eps)))
    g = sp.csr_matrix((vals, (rows, cols)), shape=(m + n, m + n))
    left, right = min_weight_full_bipartite_matching(g)
    real = (left < m) & (right < n)
    er, rr = left[real].astype(np.int64), right[real].astype(np.int64)
    return er, rr, np.hypot(*(x[er] - y[rr]).T)
