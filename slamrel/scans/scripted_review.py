"""A scripted review of aligned relations: what a person at the review page would decide,
from the flags and the cycle check alone (for benchmarks, tests and notebooks).

Rules, in order:

1. accept every unflagged relation, reject every flagged one;
2. ``cycle_check``: reject the unflagged relations the cycle check contradicts
   (:func:`slamrel.scans.cycles.check_scan_relations` over the unflagged ones);
3. ``confirm``: accept a relation flagged *only* ``large correction`` or *only*
   ``ambiguous`` (:data:`CONFIRMABLE`) when its cycles with the unflagged relations confirm
   it (≥ 2 cycles, none failed) and none contradicts it — a person accepts a flagged
   relation its neighbours agree with. (Confirmation is evidence, not proof: relations
   wrong alike close their cycles with each other, :meth:`CycleCheck.confirmed`.)

A relation a person has **moved by hand** (:func:`hand_realign`) is re-aligned within a
small window around the placement, the rule of the review page's ``i`` key: a grid search
of ±10 cm / ±1° on 2 cm / 0.2° steps (the score: the mean of ``exp(−d²/2σ²)``, ``d`` each
current return's distance to the nearest reference return, ``σ`` = 2 cm), then the
aligner's point-to-line ICP from the best node; an ICP answer that leaves the window (or
fails) is dropped for the grid's. The answer never leaves the window, so a placement near
the truth cannot fall back into the wrong corridor optimum a free ICP finds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from relation_metric.se2 import wrap_angle_float
from slamrel.formats.laser import LaserScans
from slamrel.scans.cycles import check_scan_relations
from slamrel.scans.matching import IcpOptions, PreparedScan, align, prepare_scan
from slamrel.scans.relations import ScanRelations

__all__ = [
    "CONFIRMABLE",
    "HandWindow",
    "ScriptedReview",
    "hand_realign",
    "realign_in_window",
    "scripted_review",
]

#: Flags a relation may carry alone and still be accepted when its cycles confirm it: a
#: correction from a drifting guess, a second hypothesis close in score.
CONFIRMABLE = ("large correction", "ambiguous")


@dataclass(frozen=True)
class ScriptedReview:
    """The decisions on ``P`` relations.

    Attributes
    ----------
    accepted : (P,) bool
    contradicted : int
        Unflagged relations rejected by the cycle check (rule 2).
    confirmed : int
        Flagged relations accepted on their cycles' word (rule 3).
    """

    accepted: NDArray[np.bool_]
    contradicted: int
    confirmed: int


def scripted_review(
    result: ScanRelations, *, cycle_check: bool = True, confirm: bool = True
) -> ScriptedReview:
    """Review ``result`` by the rules of the module docstring."""
    accept = ~result.flagged
    if not (cycle_check or confirm):
        return ScriptedReview(accept, 0, 0)
    soft = np.isin(result.flags, CONFIRMABLE)
    check = check_scan_relations(result, use=accept | soft if confirm else accept)
    contradicted = accept & check.contradicted if cycle_check else np.zeros_like(accept)
    extra = soft & check.confirmed() & ~check.contradicted if confirm else soft & False
    return ScriptedReview(
        (accept & ~contradicted) | extra, int(contradicted.sum()), int(extra.sum())
    )


@dataclass(frozen=True)
class HandWindow:
    """The window of a re-align from a hand placement (the review page's ``i`` key).

    Attributes
    ----------
    half_xy, half_theta : float
        Half widths around the placement [m], [rad] (0.10, 1°).
    step_xy, step_theta : float
        Grid steps [m], [rad] (0.02, 0.2°).
    sigma : float
        Width of the grid search's score [m] (0.02: the page's 2 cm raster).
    """

    half_xy: float = 0.10
    half_theta: float = float(np.radians(1.0))
    step_xy: float = 0.02
    step_theta: float = float(np.radians(0.2))
    sigma: float = 0.02


def _inside(delta: NDArray[np.float64], placed: NDArray[np.float64], w: HandWindow) -> bool:
    d = delta - placed
    d[2] = wrap_angle_float(float(d[2]))
    tol = 1e-9
    return bool(
        abs(d[0]) <= w.half_xy + tol
        and abs(d[1]) <= w.half_xy + tol
        and abs(d[2]) <= w.half_theta + tol
    )


def realign_in_window(
    reference: PreparedScan,
    current: PreparedScan,
    placed: NDArray[np.float64],
    window: HandWindow | None = None,
    icp: IcpOptions | None = None,
) -> NDArray[np.float64]:
    """Re-align ``current`` on ``reference`` within ``window`` around the hand placement
    ``placed`` ``[x, y, θ]`` (module docstring); the answer lies in the window."""
    w = window or HandWindow()
    placed = np.asarray(placed, dtype=np.float64).reshape(3)
    if not (reference.points.shape[0] and current.points.shape[0]):
        return placed.copy()
    nxy = int(round(w.half_xy / w.step_xy))
    nth = int(round(w.half_theta / w.step_theta))
    ths = placed[2] + np.arange(-nth, nth + 1) * w.step_theta
    gx, gy = np.meshgrid(np.arange(-nxy, nxy + 1), np.arange(-nxy, nxy + 1), indexing="ij")
    ox, oy = gx.ravel(), gy.ravel()  # (G,) grid offsets in steps
    c, s = np.cos(ths)[:, None], np.sin(ths)[:, None]
    px, py = current.points[:, 0], current.points[:, 1]
    # the points of each rotation moved to the placement, on cells of one grid step: a
    # translation of k steps moves every point by exactly k cells (the page's raster)
    bx = np.floor((c * px - s * py + placed[0]) / w.step_xy + 0.5).astype(np.int64)  # (T, M)
    by = np.floor((s * px + c * py + placed[1]) / w.step_xy + 0.5).astype(np.int64)
    cx = bx[:, :, None] + ox[None, None, :]  # (T, M, G)
    cy = by[:, :, None] + oy[None, None, :]
    span = int(cy.max() - cy.min()) + 1
    cells, back = np.unique((cx * span + (cy - cy.min())).ravel(), return_inverse=True)
    centres = np.column_stack((cells // span, cells % span + cy.min())) * w.step_xy
    d, _ = cKDTree(reference.points).query(centres, distance_upper_bound=4 * w.sigma)
    like = np.exp(-0.5 * (np.minimum(d, 4 * w.sigma) / w.sigma) ** 2)
    score = like[back].reshape(cx.shape).mean(axis=1)  # (T, G)
    k, g = np.unravel_index(int(np.argmax(score)), score.shape)
    best = np.array([placed[0] + ox[g] * w.step_xy, placed[1] + oy[g] * w.step_xy, ths[k]])
    a = align(reference, current, best, icp)
    if a.failed or not _inside(a.delta.copy(), placed, w):
        return best
    return np.asarray(a.delta, dtype=np.float64)


def hand_realign(
    scans: LaserScans,
    pairs: NDArray[np.int64],
    placed: NDArray[np.float64],
    *,
    window: HandWindow | None = None,
    icp: IcpOptions | None = None,
    min_range: float = 0.05,
    max_range: float | None = None,
) -> NDArray[np.float64]:
    """The scripted person's re-align of relations moved by hand: scan index ``pairs``
    ``(P, 2)`` (reference, current), their hand placements ``(P, 3)``; returns ``(P, 3)``."""
    prepared: dict[int, PreparedScan] = {}

    def scan(k: int) -> PreparedScan:
        if k not in prepared:
            prepared[k] = prepare_scan(scans.points(k, min_range=min_range, max_range=max_range))
        return prepared[k]

    placed = np.asarray(placed, dtype=np.float64).reshape(-1, 3)
    out = np.empty_like(placed)
    for n, (i, j) in enumerate(np.asarray(pairs, dtype=np.int64).reshape(-1, 2).tolist()):
        out[n] = realign_in_window(scan(i), scan(j), placed[n], window, icp)
    return out
