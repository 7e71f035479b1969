"""Landmark relations from the reference mesh, and their errors.

Relations are defined on the Delaunay mesh of the *reference* landmarks and evaluated on the
associated estimated landmarks; each is local, counted once, and independent of a global
rotation or translation of either map:

* per edge ``(i, j)``, the length error ``e_len = | ‖l_j − l_i‖ − ‖l*_j − l*_i‖ |`` (m);
* per triangle corner at ``a`` of ``(a, b, c)``, the angle error
  ``e_ang = |wrap(∠_a − ∠*_a)|`` with ``∠_a = atan2((b − a) × (c − a), (b − a) · (c − a))``
  (rad; a flipped triangle shows as a large error);
* per edge, optionally, the displacement error in the local frame of the triangles that hold
  the edge, ``‖R(ψ_ij) (l_j − l_i) − (l*_j − l*_i)‖`` (m), where ``ψ_ij`` is the
  least-squares rotation (2-D Procrustes) of the edge's neighbourhood — its two ends and the
  opposite corners ``k`` of its one or two triangles — onto the reference,
  ``ψ = atan2(Σ_v (p_v − p̄) × (p*_v − p̄*), Σ_v (p_v − p̄) · (p*_v − p̄*))`` over those 3 or 4
  vertices. The frame depends on no vertex order or triangle numbering; the error changes only
  when an end of the edge or an opposite corner moves. NaN for edges in no triangle;
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
from relation_metric.ids import rows_of

__all__ = ["MeshErrors", "mesh_errors"]


@dataclass(frozen=True)
class MeshErrors:
    """Per-edge and per-corner errors of an estimated map against the reference mesh.

    Attributes
    ----------
    edge_length : ndarray, shape (E,)
    corner_angle : ndarray, shape (T, 3)
    edge_displacement_triangle : ndarray, shape (E,)
        In the local triangle frame; NaN for edges in no triangle (collinear or tiny maps).
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
    disp_tri = np.full(length.shape, np.nan)
    disp_al = np.full(length.shape, np.nan)
    if not displacement:
        return MeshErrors(length, angle, disp_tri, disp_al)
    if mesh.triangles.shape[0]:
        opp1, opp2 = _opposite_corners(mesh, est.shape[0])
        psi = _local_rotation(est, ref, (i, j, opp1, opp2))
        has = opp1 >= 0
        c, s = np.cos(psi[has]), np.sin(psi[has])
        de, dr = d_est[has], d_ref[has]
        disp_tri[has] = np.hypot(
            c * de[:, 0] - s * de[:, 1] - dr[:, 0], s * de[:, 0] + c * de[:, 1] - dr[:, 1]
        )
    if est.shape[0] >= 2:
        al = umeyama(est, ref)
        moved = al.apply(np.column_stack((est, np.zeros(est.shape[0]))))[:, :2]
        disp_al = np.hypot(*((moved[j] - moved[i]) - d_ref).T)
    return MeshErrors(length, angle, disp_tri, disp_al)


def _opposite_corners(mesh: Mesh, n: int) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The corner opposite each edge in its first and second triangle (−1 when none), (E,)."""
    t = mesh.triangles
    pairs = np.sort(np.stack((t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]), axis=1), axis=2)
    opp = t[:, [2, 0, 1]].ravel()
    code = pairs[..., 0].ravel() * n + pairs[..., 1].ravel()
    order = np.argsort(code, kind="stable")
    code, opp = code[order], opp[order]
    start = np.flatnonzero(np.concatenate(([True], code[1:] != code[:-1])))
    stop = np.append(start[1:], code.size)
    edge_code = mesh.edges[:, 0] * n + mesh.edges[:, 1]
    pos = rows_of(code[start], edge_code)
    found = pos >= 0
    pos[~found] = 0
    first = np.where(found, opp[start[pos]], -1)
    second = np.where(
        found & (stop[pos] - start[pos] > 1), opp[np.minimum(start[pos] + 1, code.size - 1)], -1
    )
    return first.astype(np.int64), second.astype(np.int64)


def _local_rotation(
    est: NDArray[np.float64], ref: NDArray[np.float64], vertices: tuple[NDArray[np.int64], ...]
) -> NDArray[np.float64]:
    """Least-squares rotation of each vertex group of ``est`` onto ``ref`` (2-D Procrustes).

    ``vertices`` holds up to four index arrays of shape (E,), −1 meaning "no vertex";
    returns ``ψ`` (E,) with ``atan2(Σ (p − p̄) × (q − q̄), Σ (p − p̄) · (q − q̄))``.
    """
    w = [(v >= 0).astype(np.float64) for v in vertices]
    k = [np.maximum(v, 0) for v in vertices]
    count = sum(w[1:], start=w[0])  # = sum(w), but typed as an array (not array | 0)
    pm = sum(wv[:, None] * est[kv] for wv, kv in zip(w, k)) / count[:, None]
    qm = sum(wv[:, None] * ref[kv] for wv, kv in zip(w, k)) / count[:, None]
    cross = np.zeros(count.shape)
    dot = np.zeros(count.shape)
    for wv, kv in zip(w, k):  # at most four slots, each vectorised over all edges
        p = est[kv] - pm
        q = ref[kv] - qm
        cross += wv * (p[:, 0] * q[:, 1] - p[:, 1] * q[:, 0])
        dot += wv * (p[:, 0] * q[:, 0] + p[:, 1] * q[:, 1])
    return np.arctan2(cross, dot)
