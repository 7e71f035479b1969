"""The Delaunay triangle mesh over landmarks, with its degenerate cases handled explicitly.

Edges come from ``scipy.spatial.Delaunay.vertex_neighbor_vertices`` (each unique edge once,
``i < j``), triangles from its simplices. Degenerate inputs:

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
        Unique edges ``(i, j)``, ``i < j``, grouped by ``i``.
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
    p = np.asarray(xy, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    c = p[t]  # (T, 3, 2) corners
    u = np.roll(c, -1, axis=1) - c  # b − a for every corner a
    v = np.roll(c, -2, axis=1) - c  # c − a
    cross = u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]
    dot = u[..., 0] * v[..., 0] + u[..., 1] * v[..., 1]
    return np.arctan2(cross, dot)


def delaunay_mesh(xy: ArrayLike, *, thin_angle: float = np.deg2rad(5.0)) -> Mesh:
    """The Delaunay mesh of ``xy`` (shape (N, 2)); see the module docstring for degeneracies.

    Duplicates are the points Qhull leaves out as "coplanar" (``Delaunay.coplanar``), each
    reported with the vertex it coincides with; no extra pass over the points is needed.
    Edges are unique ``(i, j)`` with ``i < j``, grouped by ``i``.
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
    indptr, nbr = tri.vertex_neighbor_vertices
    src = np.repeat(np.arange(n), np.diff(indptr))
    sel = src < nbr
    edges = np.column_stack((src[sel], nbr[sel])).astype(np.int64)
    simp = tri.simplices.astype(np.int64)
    ang = corner_angles(p, simp)
    cw = ang[:, 0] < 0
    if cw.any():
        simp[cw] = simp[cw][:, [0, 2, 1]]
    return Mesh(
        edges=readonly(edges, np.int64),
        triangles=readonly(simp, np.int64),
        duplicates=readonly(dup, np.int64),
        collinear=False,
        thin=readonly(np.abs(ang).min(axis=1) < thin_angle, np.bool_),
    )


def _along_line(q: NDArray[np.float64]) -> NDArray[np.int64]:
    if q.shape[0] == 0:
        return np.empty(0, np.int64)
    c = q - q.mean(axis=0)
    _, _, vt = np.linalg.svd(c, full_matrices=False) if q.shape[0] > 1 else (None, None, np.eye(2))
    return np.argsort(c @ vt[0], kind="stable").astype(np.int64)
