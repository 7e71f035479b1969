"""Landmark relations from the reference mesh, and their errors.

Relations are defined on the Delaunay mesh of the *reference* landmarks and evaluated on the
associated estimated landmarks; each is local, counted once, and independent of a global
rotation or translation of either map:

* per edge ``(i, j)``, the length error ``e_len = | ‖l_j − l_i‖ − ‖l*_j − l*_i‖ |`` (m);
* per triangle corner at ``a`` of ``(a, b, c)``, the angle error
  ``e_ang = |wrap(∠_a − ∠*_a)|`` with ``∠_a = atan2((b − a) × (c − a), (b − a) · (c − a))``
  (rad; a flipped triangle shows as a large error);
* per edge, optionally, the displacement error in the frame of the first triangle that holds
  the edge, ``‖R(φ)ᵀ (l_j − l_i) − R(φ*)ᵀ (l*_j − l*_i)‖`` with ``φ`` the direction of that
  triangle's first edge ``a → b`` — it also moves when ``a`` or ``b`` moves;
* per edge, in a separately labelled mode, the displacement error in the global frame after a
  least-squares rigid alignment of the whole estimate onto the reference (Umeyama):
  ``‖(A l_j − A l_i) − (l*_j − l*_i)‖`` — not local: one misplaced region rotates the rest.

Edge-length and corner-angle errors change only for edges and corners that touch a displaced
landmark. Summaries follow the relation metric: ``translation`` = edge lengths,
``rotation`` = corner angles, each ``abs`` and ``sqr``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from landmark_graph.mesh import Mesh, corner_angles
from relation_metric import se2
from relation_metric.alignment import umeyama

__all__ = ["MeshErrors", "mesh_errors"]


@dataclass(frozen=True)
class MeshErrors:
    """Per-edge and per-corner errors of an estimated map against the reference mesh.

    Attributes
    ----------
    edge_length : ndarray, shape (E,)
    corner_angle : ndarray, shape (T, 3)
    edge_displacement_triangle : ndarray, shape (E,)
        NaN for edges in no triangle (collinear or tiny maps).
    edge_displacement_aligned : ndarray, shape (E,)
    """

    edge_length: NDArray[np.float64]
    corner_angle: NDArray[np.float64]
    edge_displacement_triangle: NDArray[np.float64]
    edge_displacement_aligned: NDArray[np.float64]


def mesh_errors(
    estimate: ArrayLike, reference: ArrayLike, mesh: Mesh, *, displacement: bool = True
) -> MeshErrors:
    """Errors of ``estimate`` (N, 2) against ``reference`` (N, 2), rows associated, on ``mesh``.

    ``displacement=False`` skips the two (optional) displacement errors, which are then NaN.
    """
    est = np.asarray(estimate, dtype=np.float64)
    ref = np.asarray(reference, dtype=np.float64)
    i, j = mesh.edges[:, 0], mesh.edges[:, 1]
    d_est = est[j] - est[i]
    d_ref = ref[j] - ref[i]
    length = np.abs(np.hypot(d_est[:, 0], d_est[:, 1]) - np.hypot(d_ref[:, 0], d_ref[:, 1]))
    angle = np.abs(
        se2.wrap_angle(corner_angles(est, mesh.triangles) - corner_angles(ref, mesh.triangles))
    )
    # frame of the first triangle holding each edge (direction of its edge a -> b)
    disp_tri = np.full(length.shape, np.nan)
    if not displacement:
        return MeshErrors(length, angle, disp_tri, np.full(length.shape, np.nan))
    if mesh.triangles.shape[0]:
        t = mesh.triangles
        tri_edges = np.sort(
            np.stack((t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]), axis=1), axis=2
        )  # (T, 3, 2)
        flat = tri_edges.reshape(-1, 2)
        owner = np.repeat(np.arange(t.shape[0]), 3)
        n = int(max(est.shape[0], 1))
        code = flat[:, 0] * n + flat[:, 1]
        order = np.lexsort((owner, code))
        first = order[np.concatenate(([True], np.diff(code[order]) != 0))]
        edge_code = i * n + j
        pos = np.searchsorted(code[first], edge_code)
        pos = np.clip(pos, 0, first.size - 1)
        has = code[first][pos] == edge_code
        tri = owner[first][pos]
        a, b = t[tri, 0], t[tri, 1]
        phi_e = np.arctan2(*(est[b] - est[a]).T[::-1])
        phi_r = np.arctan2(*(ref[b] - ref[a]).T[::-1])
        in_e = _rotate(d_est, -phi_e)
        in_r = _rotate(d_ref, -phi_r)
        disp_tri[has] = np.hypot(*(in_e - in_r)[has].T)
    if est.shape[0] >= 2:
        al = umeyama(est, ref)
        moved = al.apply(np.column_stack((est, np.zeros(est.shape[0]))))[:, :2]
        disp_al = np.hypot(*((moved[j] - moved[i]) - d_ref).T)
    else:
        disp_al = np.zeros(length.shape)
    return MeshErrors(length, angle, disp_tri, disp_al)


def _rotate(v: NDArray[np.float64], ang: NDArray[np.float64]) -> NDArray[np.float64]:
    c, s = np.cos(ang), np.sin(ang)
    return np.column_stack((c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1]))
