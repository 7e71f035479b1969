"""Multi-resolution correlative scan matching (Olson 2009), a global initialiser for ICP.

E. Olson, "Real-Time Correlative Scan Matching", ICRA 2009. The reference scan becomes a
lookup table on a grid of cell size ``r``: ``L(c) = exp(−d(c)² / (2 σ²))``, ``d`` the
distance from the cell centre to the nearest reference return (a Euclidean distance
transform). A candidate ``δ = [t, θ]`` scores the mean of ``L`` at the current returns moved
by it, ``s(δ) = 1/M Σ_m L(R(θ) p_m + t)`` (in ``[0, 1]``); the search covers a window
around the guess, ``±search_xy`` in each translation and ``±search_theta``, in steps of
``r`` and ``Δθ = r / ‖p‖₉₀`` (the 90th-percentile return moves about one cell per step; at
most 121 rotations).

Two resolutions (Olson's Sect. III-C): a coarse table ``L_c(c) = max L`` over the
``f × f`` fine cells a coarse step covers is an upper bound of every fine score within the
coarse cell, so the coarse candidates are visited best-first and refined at full
resolution until the best fine score beats the next coarse bound: the answer is the best
fine score in the window, found without evaluating it everywhere.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["CorrelativeOptions", "CorrelativeMatch", "correlative_match", "table_cells"]


@dataclass(frozen=True)
class CorrelativeOptions:
    """Parameters of :func:`correlative_match` (metres, radians).

    Attributes
    ----------
    resolution : float
        Fine cell size ``r`` (0.03 m).
    coarse : int
        Fine cells per coarse step ``f`` (8).
    sigma : float
        Blur of the lookup table (0.05 m).
    search_xy : float
        Half width of the translation window (1.5 m).
    search_theta : float
        Half width of the rotation window (0.5 rad ≈ 29°).
    max_candidates : int
        Coarse candidates refined at most (400).
    """

    resolution: float = 0.03
    coarse: int = 8
    sigma: float = 0.05
    search_xy: float = 1.5
    search_theta: float = 0.5
    max_candidates: int = 400


@dataclass(frozen=True)
class CorrelativeMatch:
    """The best candidate of the window.

    Attributes
    ----------
    delta : (3,) float
        ``[x, y, θ]`` of the current scan in the reference frame.
    score : float
        Its mean lookup value ``s(δ)`` in ``[0, 1]``.
    guess_score : float
        ``s`` at the guess itself (how much the search improved on it).
    candidates : int
        Coarse candidates refined.
    """

    delta: NDArray[np.float64]
    score: float
    guess_score: float
    candidates: int


def _rotated(points: NDArray[np.float64], theta: NDArray[np.float64]) -> NDArray[np.float64]:
    """Points ``(M, 2)`` rotated by each of ``theta`` ``(T,)``: ``(T, M, 2)``."""
    c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]
    x, y = points[None, :, 0], points[None, :, 1]
    return np.stack((c * x - s * y, s * x + c * y), axis=-1)


def _table_extent(
    reference: NDArray[np.float64],
    current: NDArray[np.float64],
    guess: NDArray[np.float64],
    opt: CorrelativeOptions,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Lower corner and size [m] of the lookup table: the reference's returns and every
    place the current scan's returns reach from the window around ``guess``, blurred."""
    f = max(int(opt.coarse), 1)
    reach = float(np.max(np.hypot(current[:, 0], current[:, 1]))) if current.size else 1.0
    margin = reach + opt.search_xy + 4 * opt.sigma + f * opt.resolution
    cx, cy = guess[0], guess[1]
    lo = np.minimum(reference.min(axis=0), [cx - margin, cy - margin]) - 4 * opt.sigma
    hi = np.maximum(reference.max(axis=0), [cx + margin, cy + margin]) + 4 * opt.sigma
    return lo, hi - lo


def table_cells(
    reference: NDArray[np.float64],
    current: NDArray[np.float64],
    guess: NDArray[np.float64],
    options: CorrelativeOptions | None = None,
) -> float:
    """Cells of the lookup table :func:`correlative_match` would build (as a float: a guess
    far off asks for more than any integer type holds)."""
    opt = options or CorrelativeOptions()
    extent = _table_extent(reference, current, np.asarray(guess, dtype=np.float64), opt)[1]
    return float(np.prod(np.ceil(extent / opt.resolution) + 1))


def correlative_match(
    reference: NDArray[np.float64],
    current: NDArray[np.float64],
    guess: NDArray[np.float64],
    options: CorrelativeOptions | None = None,
) -> CorrelativeMatch:
    """Search the window around ``guess`` for the best alignment of two point sets.

    Parameters
    ----------
    reference, current : (K, 2), (M, 2) float
        Returns of the two scans in their own laser frames (no NaN rows).
    guess : (3,) float
        Centre of the search window.
    options : CorrelativeOptions, optional

    Returns
    -------
    CorrelativeMatch
    """
    from scipy import ndimage  # here, not at import: the default global aligner never needs it

    opt = options or CorrelativeOptions()
    guess = np.asarray(guess, dtype=np.float64).reshape(3)
    m = current.shape[0]
    r, f = opt.resolution, max(int(opt.coarse), 1)
    half = int(np.ceil(opt.search_xy / r))
    half = int(np.ceil(half / f)) * f
    lo, extent = _table_extent(reference, current, guess, opt)
    shape = tuple(np.ceil(extent / r).astype(int) + 1)
    occ = np.ones(shape, dtype=bool)
    cells = np.floor((reference - lo) / r + 0.5).astype(int)
    occ[cells[:, 0], cells[:, 1]] = False
    dist = ndimage.distance_transform_edt(occ) * r
    fine = np.exp(-0.5 * (dist / opt.sigma) ** 2)
    # coarse[i, j] = max fine[i : i + f, j : j + f]: an upper bound over a coarse step
    coarse = ndimage.maximum_filter(fine, size=f, origin=-(f // 2), mode="constant", cval=0.0)

    # angular step: the 90th-percentile return moves about one cell; at most 2 · 60 + 1 steps
    typical = float(np.percentile(np.hypot(current[:, 0], current[:, 1]), 90)) if m else 1.0
    dtheta = max(r / max(typical, r), opt.search_theta / 60.0)
    nth = int(np.ceil(opt.search_theta / dtheta))
    thetas = guess[2] + dtheta * np.arange(-nth, nth + 1)
    rot = _rotated(current, thetas)  # (T, M, 2)
    base = np.floor((rot + guess[:2] - lo) / r + 0.5).astype(int)  # (T, M, 2)
    steps = np.arange(-half, half + 1, f)
    gx, gy = np.meshgrid(steps, steps, indexing="ij")
    ox, oy = gx.ravel(), gy.ravel()

    def lookup(table: NDArray[np.float64], ix: NDArray[np.int64], iy: NDArray[np.int64]) -> Any:
        ok = (ix >= 0) & (ix < shape[0]) & (iy >= 0) & (iy < shape[1])
        return np.where(ok, table[np.clip(ix, 0, shape[0] - 1), np.clip(iy, 0, shape[1] - 1)], 0)

    coarse_scores = np.empty((thetas.shape[0], ox.shape[0]))
    for k in range(thetas.shape[0]):  # one vectorised (M × G) lookup per rotation
        ix = base[k, :, 0, None] + ox[None, :]
        iy = base[k, :, 1, None] + oy[None, :]
        coarse_scores[k] = lookup(coarse, ix, iy).sum(axis=0) / m
    order = np.argsort(coarse_scores, axis=None)[::-1]
    hx, hy = np.meshgrid(np.arange(f), np.arange(f), indexing="ij")
    fx, fy = hx.ravel(), hy.ravel()
    best_score, best = -1.0, guess.copy()
    used = 0
    for flat in order[: opt.max_candidates]:
        k, g = np.unravel_index(flat, coarse_scores.shape)
        if coarse_scores[k, g] <= best_score:
            break
        used += 1
        ix = base[k, :, 0, None] + ox[g] + fx[None, :]
        iy = base[k, :, 1, None] + oy[g] + fy[None, :]
        scores = lookup(fine, ix, iy).sum(axis=0) / m
        b = int(np.argmax(scores))
        if scores[b] > best_score:
            best_score = float(scores[b])
            best = np.array(
                [guess[0] + (ox[g] + fx[b]) * r, guess[1] + (oy[g] + fy[b]) * r, thetas[k]]
            )
    g0 = base[nth]
    guess_score = float(lookup(fine, g0[:, 0], g0[:, 1]).sum() / m)
    return CorrelativeMatch(best, best_score, guess_score, used)
