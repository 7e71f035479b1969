"""Relation-set adjustment: a least-squares pose-graph fit over accepted relations, the
relations re-read from the fitted poses.

Reference relations made by scan alignment form a redundant graph: consecutive keyframe
links plus loop links, whose short cycles (two loop pairs between neighbouring keyframes of
two passes and the two consecutive links that join them) each measure the same motion
twice. Each alignment's error is its own (independent noise of two scans), so fitting poses
``x`` to all of them,

    min_x  Σ_e  r_eᵀ Σ_e⁻¹ r_e,    r_e = x_i⁻¹ ∘ x_j ⊖ z_e

(:func:`slamrel.backends.least_squares.solve_graph`, residual ``[R_iᵀ(t_j − t_i) − z_t,
wrap(θ_j − θ_i − z_θ)]``, each relation weighted by its alignment's covariance ``Σ_e``) and
re-reading every relation as ``x_i⁻¹ ∘ x_j`` averages that noise: in a linear graph with
``E`` relations over ``N`` poses in ``C`` components, the fitted relations' covariance is
the projection ``H Σ`` with trace ``3(N − C)`` out of ``3E`` (the redundancy ``3E − 3(N −
C)`` is the part of the noise removed). A relation on no cycle (a bridge) comes back
unchanged.

Only relations that a review accepted enter (the caller's ``use``): a grossly wrong relation
in the fit would pull its cycles' others toward it. As a second guard the fit is robust by
elimination: while the fit moves some relation farther than ``max_move`` (5 cm) or
``max_move_angle`` (0.02 rad) from its aligned value — the size of a contradiction, not of
alignment noise (the accepted relations' error is a few millimetres, p99 1–3 cm) — the one
moved farthest (in units of these limits) is set aside: it keeps its own aligned value, is
counted, and the fit is redone without it. A gate on ``χ²`` was tried first and dropped: the
aligned relations' covariances are too unevenly calibrated (on the loop world 18–50 of 278
accepted, none of them grossly wrong, lay beyond 50 times the median scale).

Poses start from a spanning tree of the relations themselves (the earliest relations
first: consecutive links before loop links), headings then translations, each a sparse
linear solve; no pose estimate is needed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from relation_metric import se2
from relation_metric.errors import InputError

__all__ = ["MAX_MOVE", "MAX_MOVE_ANGLE", "Adjustment", "adjust_relations"]

#: The fit may move a relation at most this far [m] (and :data:`MAX_MOVE_ANGLE` [rad]);
#: beyond, the relation farthest out is set aside and the fit redone.
MAX_MOVE = 0.05
MAX_MOVE_ANGLE = 0.02
#: The median of χ²₃ (the reported scale's denominator).
_CHI2_3_MEDIAN = 2.366


@dataclass(frozen=True)
class Adjustment:
    """The adjusted relations (``E`` given).

    Attributes
    ----------
    delta : (E, 3) float
        The relations re-read from the fitted poses where ``adjusted``; elsewhere the
        given ones, unchanged.
    adjusted : (E,) bool
        Used and on a cycle of the used relations (a bridge's fit is its own value).
    set_aside : (E,) bool
        Used, but the fit would move it beyond ``max_move`` / ``max_move_angle``: kept as
        given, out of the fit.
    chi2 : (E,) float
        Each used relation's ``r_eᵀ Σ_e⁻¹ r_e`` against the final fit (NaN where not used).
    scale : float
        The variance factor ``s²`` of the final fit, the median ``χ²`` of the relations on
        cycles over the median of χ²₃ (1 where nothing is redundant): below 1, the
        covariances are wider than the cycles' disagreement.
    redundancy : int
        ``3E' − 3(N − C)`` of the final fit (``E'`` relations used and not set aside).
    """

    delta: NDArray[np.float64]
    adjusted: NDArray[np.bool_]
    set_aside: NDArray[np.bool_]
    chi2: NDArray[np.float64]
    scale: float
    redundancy: int


_Ints = NDArray[np.int64]
_Floats = NDArray[np.float64]


def _check(
    i: ArrayLike, j: ArrayLike, delta: ArrayLike, covariance: ArrayLike, use: ArrayLike | None
) -> tuple[
    _Ints,
    _Ints,
    _Floats,
    _Floats,
    NDArray[np.bool_],
]:
    ia = np.asarray(i, dtype=np.int64).ravel()
    ja = np.asarray(j, dtype=np.int64).ravel()
    d = np.asarray(delta, dtype=np.float64)
    c = np.asarray(covariance, dtype=np.float64)
    e = ia.size
    if ja.size != e or d.shape != (e, 3) or c.shape != (e, 3, 3):
        raise InputError(
            f"relations to adjust need i, j (E,), delta (E, 3) and covariance (E, 3, 3); got "
            f"{ia.shape}, {ja.shape}, {d.shape}, {c.shape}"
        )
    u = np.ones(e, dtype=bool) if use is None else np.asarray(use, dtype=bool).ravel()
    if u.shape != (e,):
        raise InputError(f"use must have shape ({e},), got {u.shape}")
    if np.any(ia[u] == ja[u]):
        raise InputError("a relation to adjust joins a scan to itself")
    if not (np.isfinite(d[u]).all() and np.isfinite(c[u]).all()):
        raise InputError("relations to adjust must have finite values and covariances")
    if u.any() and np.linalg.eigvalsh(0.5 * (c[u] + np.swapaxes(c[u], 1, 2))).min() <= 0:
        raise InputError("relations to adjust need positive definite covariances")
    return ia, ja, d, c, u


def _components(a: _Ints, b: _Ints, n: int) -> _Ints:
    from scipy.sparse.csgraph import connected_components

    adj = sp.coo_matrix((np.ones(a.size), (a, b)), shape=(n, n))
    return connected_components(adj, directed=False)[1].astype(np.int64)


def _tree_poses(a: _Ints, b: _Ints, z: _Floats, n: int) -> _Floats:
    """Poses composed along a spanning forest of the relations ``x_a⁻¹ ∘ x_b = z`` (the
    earliest relation of each pair first), each component's first node at the origin:
    headings, then translations, each one sparse linear solve."""
    from scipy.sparse.csgraph import minimum_spanning_tree

    # weights 1, 2, ... in relation order make the forest unique and prefer early relations
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = lo * n + hi
    _, first = np.unique(key, return_index=True)
    w = sp.coo_matrix((first + 1.0, (lo[first], hi[first])), shape=(n, n)).tocsr()
    tree = minimum_spanning_tree(w).tocoo()
    k = np.rint(tree.data).astype(np.int64) - 1  # relation index of each tree edge
    label = _components(a, b, n)
    roots = np.unique(label, return_index=True)[1]
    rows = np.arange(k.size + roots.size)
    # θ_b − θ_a = z_θ on tree edges; θ_root = 0
    cols_a = np.concatenate((a[k], roots))
    cols_b = np.concatenate((b[k], roots))
    va = np.concatenate((-np.ones(k.size), np.zeros(roots.size)))
    vb = np.concatenate((np.ones(k.size), np.ones(roots.size)))
    m = sp.coo_matrix(
        (
            np.concatenate((va, vb)),
            (np.concatenate((rows, rows)), np.concatenate((cols_a, cols_b))),
        ),
        shape=(rows.size, n),
    ).tocsc()
    from scipy.sparse.linalg import splu

    lu = splu(m)
    theta = lu.solve(np.concatenate((z[k, 2], np.zeros(roots.size))))
    ca, sa = np.cos(theta[a[k]]), np.sin(theta[a[k]])
    dx = ca * z[k, 0] - sa * z[k, 1]
    dy = sa * z[k, 0] + ca * z[k, 1]
    rhs = np.zeros((rows.size, 2))
    rhs[: k.size, 0], rhs[: k.size, 1] = dx, dy
    xy = lu.solve(rhs)
    return np.column_stack((xy, theta))


def _fit(
    a: _Ints,
    b: _Ints,
    z: _Floats,
    info: _Floats,
    poses: _Floats,
) -> _Floats:
    """Poses fitted to the relations, component by component (those without a cycle keep
    their tree poses, which meet every relation exactly)."""
    from slamrel.backends.graph import PoseGraph
    from slamrel.backends.least_squares import solve_graph

    n = poses.shape[0]
    label = _components(a, b, n)
    nodes = np.bincount(label, minlength=label.max() + 1)
    edges = np.bincount(label[a], minlength=nodes.size)
    out = poses.copy()
    for comp in np.flatnonzero(edges > nodes - 1):
        ids = np.flatnonzero(label == comp)
        local = np.full(n, -1, dtype=np.int64)
        local[ids] = np.arange(ids.size)
        sel = label[a] == comp
        graph = PoseGraph(
            poses=poses[ids],
            landmarks=np.empty((0, 2)),
            pp_i=local[a[sel]],
            pp_j=local[b[sel]],
            pp_z=z[sel],
            pp_info=info[sel],
        )
        out[ids] = solve_graph(graph).poses
    return out


def _chi2(
    poses: _Floats,
    a: _Ints,
    b: _Ints,
    z: _Floats,
    info: _Floats,
) -> _Floats:
    r = se2.between(poses[a], poses[b]) - z
    r[:, 2] = se2.wrap_angle(r[:, 2])
    return np.einsum("ei,eij,ej->e", r, info, r)


def _moves(
    poses: _Floats,
    a: _Ints,
    b: _Ints,
    z: _Floats,
) -> _Floats:
    """How far the fit moves each relation: ``[‖t‖, |θ|]`` of ``z⁻¹ ∘ (x_a⁻¹ ∘ x_b)``."""
    m = se2.between(z, se2.between(poses[a], poses[b]))
    return np.column_stack((np.hypot(m[:, 0], m[:, 1]), np.abs(se2.wrap_angle(m[:, 2]))))


def adjust_relations(
    i: ArrayLike,
    j: ArrayLike,
    delta: ArrayLike,
    covariance: ArrayLike,
    *,
    use: ArrayLike | None = None,
    max_move: float = MAX_MOVE,
    max_move_angle: float = MAX_MOVE_ANGLE,
) -> Adjustment:
    """Fit poses to the ``use``d relations ``x_i⁻¹ ∘ x_j ≈ delta`` and re-read them.

    Parameters
    ----------
    i, j : (E,) int
        The two scans of each relation (any integer ids).
    delta : (E, 3) float
        ``[x, y, θ]`` of scan ``j`` in scan ``i``'s frame.
    covariance : (E, 3, 3) float
        Each relation's covariance (positive definite where used), in the same coordinates.
    use : (E,) bool, optional
        The relations that enter the fit (default: all): the accepted ones.
    max_move, max_move_angle : float
        Set the relation the fit moves farthest aside while that move exceeds these [m],
        [rad] (:data:`MAX_MOVE`, :data:`MAX_MOVE_ANGLE`; ``inf``: never).

    Raises
    ------
    InputError
        On shapes that do not match, a relation from a scan to itself, non-finite values,
        covariances that are not positive definite (among the used ones), or limits that
        are not positive.
    """
    ia, ja, d, c, u = _check(i, j, delta, covariance, use)
    if not (max_move > 0 and max_move_angle > 0):
        raise InputError(
            f"the adjustment's limits must be positive, got {max_move} m, {max_move_angle} rad"
        )
    e = ia.size
    out = d.copy()
    adjusted = np.zeros(e, dtype=bool)
    aside = np.zeros(e, dtype=bool)
    chi2 = np.full(e, np.nan)
    idx = np.flatnonzero(u)
    if idx.size == 0:
        return Adjustment(out, adjusted, aside, chi2, 1.0, 0)
    ids, inv = np.unique(np.concatenate((ia[idx], ja[idx])), return_inverse=True)
    a_all, b_all = inv[: idx.size], inv[idx.size :]
    inv_c = np.linalg.inv(c[idx])
    info_all = np.asarray(0.5 * (inv_c + np.swapaxes(inv_c, 1, 2)), dtype=np.float64)
    n = ids.size
    keep = np.ones(idx.size, dtype=bool)
    poses = _tree_poses(a_all, b_all, d[idx], n)
    while True:
        a, b = a_all[keep], b_all[keep]
        poses = _fit(a, b, d[idx][keep], info_all[keep], poses)
        x2 = _chi2(poses, a_all, b_all, d[idx], info_all)
        label = _components(a, b, n)
        comps = np.unique(label).size
        redundancy = 3 * int(keep.sum()) - 3 * (n - comps)
        # relations on a cycle: removing them leaves their two ends joined (χ² > 0 where
        # redundant); a bridge fits exactly
        on_cycle = keep & (x2 > 1e-18 * (1 + np.abs(d[idx]).sum(axis=1)))
        scale = float(np.median(x2[on_cycle]) / _CHI2_3_MEDIAN) if on_cycle.any() else 1.0
        scale = scale if scale > 0 else 1.0
        move = _moves(poses, a_all, b_all, d[idx])
        norm = np.where(
            keep, np.maximum(move[:, 0] / max_move, move[:, 1] / max_move_angle), -np.inf
        )
        worst = int(np.argmax(norm))
        if norm[worst] <= 1.0 or redundancy <= 0:
            break
        keep[worst] = False
    fitted = se2.between(poses[a_all], poses[b_all])
    adj_local = on_cycle
    sel = idx[adj_local]
    out[sel] = fitted[adj_local]
    out[sel, 2] = se2.wrap_angle(out[sel, 2])
    adjusted[sel] = True
    aside[idx[~keep]] = True
    chi2[idx] = x2
    return Adjustment(out, adjusted, aside, chi2, scale, redundancy)
