"""The Delaunay triangle mesh over landmarks, with its degenerate cases handled explicitly.

Edges come from ``scipy.spatial.Delaunay.vertex_neighbor_vertices`` (each unique edge once,
``i < j``), triangles from its simplices. Degenerate inputs:

* fewer than 3 landmarks: 2 give one edge, 1 or 0 none (no triangles);
* duplicate positions: Qhull drops them silently, so they are detected first, reported in
  :attr:`Mesh.duplicates` and left out of the mesh (each duplicate joins no edge);
* collinear landmarks (Qhull cannot triangulate): the chain of neighbours along the line;
* near-collinear thin triangles: kept, and flagged in :attr:`Mesh.thin` (smallest interior
  angle below ``thin_angle``) since their angles are ill-conditioned.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import Delaunay

from relation_metric.trajectory import readonly

__all__ = ["Mesh", "delaunay_mesh", "corner_angles"]


@dataclass(frozen=True)
class Mesh:
    """A triangle mesh over N points.

    Attributes
    ----------
    edges : ndarray of int, shape (E, 2)
        Unique edges ``(i, j)``, ``i < j``, sorted.
    triangles : ndarray of int, shape (T, 3)
        Counter-clockwise vertex triples.
    duplicates : ndarray of int, shape (D, 2)
        ``(kept, dropped)`` pairs of points at the same position.
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
    out = np.empty(t.shape)
    for k in range(3):
        a, b, c = p[t[:, k]], p[t[:, (k + 1) % 3]], p[t[:, (k + 2) % 3]]
        u, v = b - a, c - a
        out[:, k] = np.arctan2(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0], np.einsum("ij,ij->i", u, v))
    return out


def delaunay_mesh(xy: ArrayLike, *, thin_angle: float = np.deg2rad(5.0)) -> Mesh:
    """The Delaunay mesh of ``xy`` (shape (N, 2)); see the module docstring for degeneracies."""
    p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    n = p.shape[0]
    # duplicates: identical positions (Qhull would drop them without a word)
    # (lexsort on the coordinates: np.unique(axis=0) is several times slower)
    order = np.lexsort((np.arange(n), p[:, 1], p[:, 0]))
    same = np.zeros(n, dtype=bool)
    same[1:] = np.all(p[order[1:]] == p[order[:-1]], axis=1)
    group_first = order[np.maximum.accumulate(np.where(~same, np.arange(n), 0))] if n else order
    keep = np.ones(n, dtype=bool)
    keep[order[same]] = False
    dup = np.column_stack((group_first[same], order[same])).astype(np.int64)
    dup = dup[np.argsort(dup[:, 1], kind="stable")]
    idx = np.flatnonzero(keep)
    q = p[idx]
    empty_t = np.empty((0, 3), dtype=np.int64)
    if q.shape[0] < 3 or _collinear(q):
        order = _along_line(q)
        edges = (
            np.column_stack((idx[order[:-1]], idx[order[1:]]))
            if order.size > 1
            else np.empty((0, 2), np.int64)
        )
        edges = np.sort(edges, axis=1)
        edges = edges[np.lexsort((edges[:, 1], edges[:, 0]))]
        return Mesh(
            readonly(edges, np.int64),
            readonly(empty_t, np.int64),
            readonly(dup, np.int64),
            q.shape[0] >= 3,
            readonly(np.zeros(0, bool), np.bool_),
        )
    tri = Delaunay(q)
    indptr, nbr = tri.vertex_neighbor_vertices
    src = np.repeat(np.arange(q.shape[0]), np.diff(indptr))
    sel = src < nbr
    edges = np.column_stack((idx[src[sel]], idx[nbr[sel]]))
    edges = np.sort(edges, axis=1)
    edges = edges[np.lexsort((edges[:, 1], edges[:, 0]))]
    simp = tri.simplices.astype(np.int64)
    ang = corner_angles(q, simp)
    ccw = ang[:, 0] > 0
    simp[~ccw] = simp[~ccw][:, [0, 2, 1]]
    ang = np.abs(ang)
    triangles = idx[simp]
    return Mesh(
        edges=readonly(edges, np.int64),
        triangles=readonly(triangles, np.int64),
        duplicates=readonly(dup, np.int64),
        collinear=False,
        thin=readonly(ang.min(axis=1) < thin_angle, np.bool_),
    )


def _collinear(q: NDArray[np.float64]) -> bool:
    c = q - q.mean(axis=0)
    s = np.linalg.svd(c, compute_uv=False)
    return bool(s[-1] <= 1e-12 * max(s[0], 1e-300))


def _along_line(q: NDArray[np.float64]) -> NDArray[np.int64]:
    if q.shape[0] == 0:
        return np.empty(0, np.int64)
    c = q - q.mean(axis=0)
    _, _, vt = np.linalg.svd(c, full_matrices=False) if q.shape[0] > 1 else (None, None, np.eye(2))
    return np.argsort(c @ vt[0], kind="stable").astype(np.int64)
