"""The Delaunay triangle mesh over landmarks, with its degenerate cases handled explicitly.

Triangles are the simplices of ``scipy.spatial.Delaunay`` (made counter-clockwise), edges come
from its neighbour table (each unique edge once, ``(i, j)`` with ``i < j``, taken from the
triangle with the smaller index or the only one on the hull). Degenerate inputs:

* fewer than 3 landmarks: 2 give one edge, 1 or 0 none (no triangles);
* duplicate positions (equal to Qhull's precision, about 1e-12 relative): Qhull drops them
  silently; they are read from its "coplanar" points, reported in :attr:`Mesh.duplicates` as
  ``(kept, dropped)`` pairs and join no edge (which of the two is dropped is Qhull's choice);
* collinear landmarks (Qhull cannot triangulate): the chain of neighbours along the line;
* near-collinear thin triangles: kept, and flagged in :attr:`Mesh.thin` (smallest interior
  angle below ``thin_angle``) since their angles are ill-conditioned.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import Delaunay, QhullError

from relation_metric.trajectory import readonly

__all__ = ["Mesh", "delaunay_mesh", "corner_angles"]


@dataclass(frozen=True)
class Mesh:
    """A triangle mesh over N points.

    Attributes
    ----------
    edges : ndarray of int, shape (E, 2)
        Unique edges ``(i, j)``, ``i < j``, in triangle order (sorted when there are no
        triangles).
    triangles : ndarray of int, shape (T, 3)
        Counter-clockwise vertex triples.
    duplicates : ndarray of int, shape (D, 2)
        ``(kept, dropped)`` pairs of points at the same position, sorted by ``dropped``.
    collinear : bool
        True when the points lie on a line and the mesh is the chain along it.
    thin : ndarray of bool, shape (T,)
        Triangles whose smallest angle is below the threshold.
    """

    edges: NDArray[np.int64]
    triangles: NDArray[np.int64]
    duplicates: NDArray[np.int64]
    collinear: bool
    thin: NDArray[np.bool_]


def corner_angles(xy: ArrayLike, triangles: ArrayLike) -> NDArray[np.float64]:
    """Signed interior angle at each corner, shape (T, 3): at vertex ``a`` of ``(a, b, c)``
    the angle ``atan2(u × v, u · v)`` from ``u = b − a`` to ``v = c − a`` (positive for a
    counter-clockwise triangle; a flipped triangle changes its sign)."""
    cross, dot = _corner_products(
        np.asarray(xy, dtype=np.float64), np.asarray(triangles, dtype=np.int64)
    )
    return np.arctan2(cross, dot)


def delaunay_mesh(xy: ArrayLike, *, thin_angle: float = np.deg2rad(5.0)) -> Mesh:
    """The Delaunay mesh of ``xy`` (shape (N, 2)); see the module docstring for degeneracies.

    Duplicates are the points Qhull leaves out as "coplanar" (``Delaunay.coplanar``), each
    reported with the vertex it coincides with; no extra pass over the points is needed.
    Edges are unique ``(i, j)`` with ``i < j``.
    """
    p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    n = p.shape[0]
    empty_t = np.empty((0, 3), dtype=np.int64)
    tri = None
    if n >= 3:
        try:
            tri = Delaunay(p)
        except QhullError:
            tri = None  # collinear (or all points coincide): the chain below
    if tri is None:
        _, first, inv = np.unique(p, axis=0, return_index=True, return_inverse=True)
        idx = np.sort(first)
        keep = np.zeros(n, dtype=bool)
        keep[idx] = True
        dropped = np.flatnonzero(~keep)
        dup = np.column_stack((first[inv.ravel()[dropped]], dropped)).astype(np.int64)
        q = p[idx]
        order = _along_line(q)
        edges = (
            np.sort(np.column_stack((idx[order[:-1]], idx[order[1:]])), axis=1)
            if order.size > 1
            else np.empty((0, 2), np.int64)
        )
        edges = edges[np.lexsort((edges[:, 1], edges[:, 0]))]
        return Mesh(
            readonly(edges, np.int64),
            readonly(empty_t, np.int64),
            readonly(dup, np.int64),
            q.shape[0] >= 3,
            readonly(np.zeros(0, bool), np.bool_),
        )
    dup = (
        tri.coplanar[:, [2, 0]].astype(np.int64)
        if tri.coplanar.size
        else np.empty((0, 2), np.int64)
    )
    dup = dup[np.argsort(dup[:, 1], kind="stable")]
    simp = tri.simplices.astype(np.int64)
    # each edge once: from the triangle with the smaller index, or from its only triangle on
    # the hull (Qhull's neighbour table: faster than vertex_neighbor_vertices, see
    # benchmarks/README.md)
    nb = tri.neighbors
    keep = (nb > np.arange(simp.shape[0])[:, None]) | (nb < 0)  # edge opposite corner k
    a, b = simp[:, [1, 2, 0]][keep], simp[:, [2, 0, 1]][keep]
    edges = np.column_stack((np.minimum(a, b), np.maximum(a, b)))
    cross, dot = _corner_products(p, simp)
    cw = cross[:, 0] < 0  # reordering a triangle leaves its set of corner angles unchanged
    if cw.any():
        simp[cw] = simp[cw][:, [0, 2, 1]]
    return Mesh(
        edges=readonly(edges, np.int64),
        triangles=readonly(simp, np.int64),
        duplicates=readonly(dup, np.int64),
        collinear=False,
        thin=readonly(_thin(cross, dot, thin_angle), np.bool_),
    )


def _corner_products(
    p: NDArray[np.float64], t: NDArray[np.int64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``u × v`` (T, 1) and ``u · v`` (T, 3) at the corners, ``u = b − a``, ``v = c − a``.

    With the edge vectors ``e_0 = b − a``, ``e_1 = c − b``, ``e_2 = a − c`` the corner ``k``
    has ``u = e_k``, ``v = −e_{k−1}``; the cross product is twice the signed area, the same at
    every corner, so it is computed once.
    """
    x = p[:, 0][t]
    y = p[:, 1][t]
    ex = x[:, [1, 2, 0]] - x
    ey = y[:, [1, 2, 0]] - y
    cross = ex[:, 2:3] * ey[:, 0:1] - ex[:, 0:1] * ey[:, 2:3]
    dot = -(ex * ex[:, [2, 0, 1]] + ey * ey[:, [2, 0, 1]])
    return cross, dot


def _thin(cross: NDArray[np.float64], dot: NDArray[np.float64], angle: float) -> NDArray[np.bool_]:
    """Smallest interior angle below ``angle``, without arctan: a corner's angle
    ``atan2(|u × v|, u · v)`` is below ``angle < π/2`` iff ``u · v > 0`` and
    ``|u × v| < tan(angle) (u · v)``; the smallest angle of a triangle is at most π/3."""
    if angle > np.pi / 3:
        return np.ones(cross.shape[0], dtype=bool)
    return ((dot > 0) & (np.abs(cross) < np.tan(angle) * dot)).any(axis=1)


def _along_line(q: NDArray[np.float64]) -> NDArray[np.int64]:
    if q.shape[0] == 0:
        return np.empty(0, np.int64)
    c = q - q.mean(axis=0)
    _, _, vt = np.linalg.svd(c, full_matrices=False) if q.shape[0] > 1 else (None, None, np.eye(2))
    return np.argsort(c @ vt[0], kind="stable").astype(np.int64)
