"""Branch-and-bound correlative search over a window sized by the guess's uncertainty.

Olson 2009 ("Real-time correlative scan matching") scores a candidate ``δ = [t, θ]`` of a
current point set ``p_m`` against a reference likelihood grid ``L``:

    s(δ) = 1/M Σ_m L(⌊(R(θ) p_m + t − lo) / r⌋)                 (in [0, 1])

with ``L(c) = max_k exp(−‖c − q_k‖² / (2 σ²))`` over the reference points ``q_k`` (the cell
centre ``c``; built by scattering each point's ``(2w+1)²`` kernel, ``w = ⌈3σ/r⌉``, so the
cost grows with the points, not the grid). Hess et al. 2016 ("Real-time loop closure in
2D LIDAR SLAM", Sect. V) make the search exact and fast with **precomputed grids**
``L_h(c) = max L`` over the ``2^h × 2^h`` cells from ``c``: the score of a node (a rotation and
a ``2^h × 2^h`` block of translations) with ``L_h`` bounds every candidate below it.

The search here is level-synchronous: all nodes of the top level are scored, a greedy
descent from the best gives a first leaf score ``s₀``; then level by level every node whose
bound reaches ``keep · s_best`` is split into its four children. At the leaves (one cell,
one rotation) the best candidate is exact, and every candidate within ``keep`` of it has been
scored too — so the **second hypothesis** (the best candidate farther than ``distinct_xy``
or ``distinct_theta`` from the best) is exact as well: its score ratio says how ambiguous the
match is (a corridor: a second hypothesis along it with nearly the same score). When more
than ``max_nodes`` nodes survive a level only the best are kept, and the result says so
(``truncated``: the window held too many near-equal hypotheses to tell apart).

Rotation step ``Δθ = r / ρ₉₀`` (``ρ₉₀`` the 90th-percentile range of the current points:
it moves about one cell per step).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "SearchOptions",
    "SearchResult",
    "LikelihoodGrid",
    "likelihood_grid",
    "grid_cells",
    "branch_and_bound",
]


@dataclass(frozen=True)
class SearchOptions:
    """Parameters of :func:`branch_and_bound` (metres, radians).

    Attributes
    ----------
    resolution : float
        Cell size ``r`` of the likelihood grid (0.05 m).
    sigma : float
        Blur ``σ`` of the likelihood (0.05 m).
    levels : int
        Precomputed grids ``L_1 … L_H`` (5: top nodes of 32 × 32 cells).
    keep : float
        Nodes whose bound reaches ``keep`` times the best score are split (0.85): every
        candidate within that ratio is scored, so the second hypothesis is exact above it.
    distinct_xy, distinct_theta : float
        A second hypothesis is at least this far from the best (0.3 m or 0.05 rad).
    max_nodes : int
        Nodes kept per level at most (2000).
    max_cells : int
        Largest likelihood grid; a window that would need more is refused (2**25).
    """

    resolution: float = 0.05
    sigma: float = 0.05
    levels: int = 5
    keep: float = 0.85
    distinct_xy: float = 0.3
    distinct_theta: float = 0.05
    max_nodes: int = 2000
    max_cells: int = 2**25


@dataclass(frozen=True)
class SearchResult:
    """The best candidate of the window and the best distinct second one.

    Attributes
    ----------
    delta : (3,) float
        Best ``[x, y, θ]``.
    score : float
        Its score ``s`` in ``[0, 1]``.
    second : (3,) float
        The best candidate at least ``distinct_*`` away (NaN when none reaches ``keep``).
    second_score : float
        Its score (0 when none).
    nodes : int
        Nodes scored.
    truncated : bool
        A level held more than ``max_nodes`` nodes within ``keep`` of the best.
    """

    delta: NDArray[np.float64]
    score: float
    second: NDArray[np.float64]
    second_score: float
    nodes: int
    truncated: bool

    @property
    def ratio(self) -> float:
        """``second_score / score`` (0 when no second hypothesis reaches ``keep``)."""
        return self.second_score / self.score if self.score > 0 else 0.0


@dataclass(frozen=True)
class LikelihoodGrid:
    """The grids ``L_0 … L_H`` over one area (``(X + 1 + 2^H, Y + 1 + 2^H)`` float32 each,
    with a zero border: one cell below, ``2^H`` above).

    Attributes
    ----------
    lo : (2,) float
        Lower corner [m] of cell ``(0, 0)``.
    resolution : float
    pyramid : list of (X', Y') float32
        ``pyramid[h][c] = max L`` over the ``2^h × 2^h`` cells from ``c``.
    """

    lo: NDArray[np.float64]
    resolution: float
    pyramid: list[NDArray[np.float32]]


def grid_cells(lo: NDArray[np.float64], hi: NDArray[np.float64], resolution: float) -> float:
    """Cells of a grid over ``[lo, hi]`` (a float: an absurd extent exceeds every integer)."""
    ext = np.maximum(np.asarray(hi, float) - np.asarray(lo, float), 0.0)
    return float(np.prod(np.ceil(ext / resolution) + 1))


def likelihood_grid(
    points: NDArray[np.float64],
    lo: NDArray[np.float64],
    hi: NDArray[np.float64],
    options: SearchOptions,
) -> LikelihoodGrid:
    """``L`` of ``points`` ``(K, 2)`` over ``[lo, hi]`` and its max pyramid (module docstring).

    The caller checks :func:`grid_cells` against ``options.max_cells`` first.
    """
    r, sig = options.resolution, options.sigma
    shape = (np.ceil((np.asarray(hi) - lo) / r).astype(int) + 1).tolist()
    pad = 2**options.levels
    lo = np.asarray(lo, dtype=np.float64) - r  # a zero border of one cell below
    shape = [shape[0] + 1, shape[1] + 1]
    table = np.zeros((shape[0] + pad, shape[1] + pad), dtype=np.float32)
    w = int(np.ceil(3 * sig / r))
    off = np.arange(-w, w + 1)
    ox, oy = (a.ravel() for a in np.meshgrid(off, off, indexing="ij"))
    cell = np.floor((points - lo) / r).astype(np.int64)  # (K, 2)
    cx = cell[:, 0, None] + ox[None, :]
    cy = cell[:, 1, None] + oy[None, :]
    dx = lo[0] + (cx + 0.5) * r - points[:, 0, None]
    dy = lo[1] + (cy + 0.5) * r - points[:, 1, None]
    val = np.exp(-(dx * dx + dy * dy) / (2 * sig * sig)).astype(np.float32)
    ok = (cx >= 1) & (cx < shape[0]) & (cy >= 1) & (cy < shape[1])
    np.maximum.at(table, (cx[ok], cy[ok]), val[ok])
    pyramid = [table]
    for h in range(1, options.levels + 1):
        s = 2 ** (h - 1)
        prev = pyramid[-1]
        nxt = prev.copy()
        np.maximum(nxt[:-s, :], prev[s:, :], out=nxt[:-s, :])
        nxt2 = nxt.copy()
        np.maximum(nxt2[:, :-s], nxt[:, s:], out=nxt2[:, :-s])
        pyramid.append(nxt2)
    return LikelihoodGrid(lo, r, pyramid)


def _score(
    grid: LikelihoodGrid,
    base: NDArray[np.int64],
    h: int,
    k: NDArray[np.int64],
    u: NDArray[np.int64],
    v: NDArray[np.int64],
) -> NDArray[np.float64]:
    """Mean of ``L_h`` at the points of rotation ``k`` moved by ``(u, v)`` cells, per node."""
    table = grid.pyramid[h]
    nx, ny = table.shape
    # cells outside clip onto the zero border: 0 at level 0, an upper bound above it
    ix = np.clip(base[k, :, 0] + u[:, None], 0, nx - 1)
    iy = np.clip(base[k, :, 1] + v[:, None], 0, ny - 1)
    return table.ravel().take(ix * ny + iy).mean(axis=1, dtype=np.float64)


def _greedy(
    grid: LikelihoodGrid,
    base: NDArray[np.int64],
    top: tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]],
    half: int,
) -> float:
    """Score of the leaf reached by always splitting the best child (a first lower bound)."""
    k, u, v, b = top
    n = int(np.argmax(b))
    kk, uu, vv = k[n : n + 1], u[n : n + 1], v[n : n + 1]
    best = 0.0
    for h in range(len(grid.pyramid) - 1, 0, -1):
        ck, cu, cv = _children(kk, uu, vv, h, half)
        s = _score(grid, base, h - 1, ck, cu, cv)
        if s.size == 0:
            return 0.0
        n = int(np.argmax(s))
        kk, uu, vv, best = ck[n : n + 1], cu[n : n + 1], cv[n : n + 1], float(s[n])
    return best


def _children(
    k: NDArray[np.int64], u: NDArray[np.int64], v: NDArray[np.int64], h: int, half: int
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """The four children (level ``h − 1``) of each node, those inside the window ``±half``."""
    s = 2 ** (h - 1)
    du = np.array([0, s, 0, s])
    dv = np.array([0, 0, s, s])
    ck = np.repeat(k, 4)
    cu = (u[:, None] + du[None, :]).ravel()
    cv = (v[:, None] + dv[None, :]).ravel()
    ok = (cu <= half) & (cv <= half)
    return ck[ok], cu[ok], cv[ok]


def branch_and_bound(
    grid: LikelihoodGrid,
    current: NDArray[np.float64],
    centre: NDArray[np.float64],
    window_xy: float,
    window_theta: float,
    options: SearchOptions,
) -> SearchResult:
    """The best ``δ`` within ``centre ± [window_xy, window_xy, window_theta]`` (docstring).

    Parameters
    ----------
    grid : LikelihoodGrid
        Of the reference points, covering every place the current points reach.
    current : (M, 2) float
        Current points in their own frame.
    centre : (3,) float
    window_xy, window_theta : float
    options : SearchOptions
    """
    r = grid.resolution
    centre = np.asarray(centre, dtype=np.float64)
    rho = float(np.percentile(np.hypot(current[:, 0], current[:, 1]), 90))
    dth = r / max(rho, r)
    nth = int(np.ceil(min(window_theta, np.pi) / dth))
    thetas = centre[2] + dth * np.arange(-nth, nth + 1)
    c, s = np.cos(thetas)[:, None], np.sin(thetas)[:, None]
    px, py = current[None, :, 0], current[None, :, 1]
    rot = np.stack((c * px - s * py, s * px + c * py), axis=-1)  # (T, M, 2)
    base = np.floor((rot + centre[:2] - grid.lo) / r).astype(np.int64)
    half = int(np.ceil(window_xy / r))
    top_h = len(grid.pyramid) - 1
    step = 2**top_h
    starts = np.arange(-half, half + 1, step)
    tk, tu, tv = (
        a.ravel() for a in np.meshgrid(np.arange(thetas.size), starts, starts, indexing="ij")
    )
    bounds = _score(grid, base, top_h, tk, tu, tv)
    nodes = int(bounds.size)
    best = _greedy(grid, base, (tk, tu, tv, bounds), half)
    truncated = False
    k, u, v = tk, tu, tv
    for h in range(top_h, 0, -1):
        alive = bounds >= options.keep * best
        k, u, v, bounds = k[alive], u[alive], v[alive], bounds[alive]
        if bounds.size > options.max_nodes:
            truncated = True
            pick = np.argpartition(-bounds, options.max_nodes)[: options.max_nodes]
            k, u, v = k[pick], u[pick], v[pick]
        k, u, v = _children(k, u, v, h, half)
        bounds = _score(grid, base, h - 1, k, u, v)
        nodes += int(bounds.size)
        if h == 1 and bounds.size:
            best = max(best, float(bounds.max()))
    return _hypotheses(k, u, v, bounds, thetas, centre, r, truncated, nodes, options)


def _hypotheses(
    k: NDArray[np.int64],
    u: NDArray[np.int64],
    v: NDArray[np.int64],
    scores: NDArray[np.float64],
    thetas: NDArray[np.float64],
    centre: NDArray[np.float64],
    r: float,
    truncated: bool,
    nodes: int,
    options: SearchOptions,
) -> SearchResult:
    """Best leaf and the best leaf distinct from it."""
    if scores.size == 0:
        nan3 = np.full(3, np.nan)
        return SearchResult(centre.copy(), 0.0, nan3, 0.0, nodes, truncated)
    pose = np.column_stack((centre[0] + u * r, centre[1] + v * r, thetas[k]))
    b = int(np.argmax(scores))
    far = (np.hypot(pose[:, 0] - pose[b, 0], pose[:, 1] - pose[b, 1]) > options.distinct_xy) | (
        np.abs(pose[:, 2] - pose[b, 2]) > options.distinct_theta
    )
    if far.any():
        idx = np.flatnonzero(far)
        s2 = int(idx[np.argmax(scores[idx])])
        second, second_score = pose[s2].copy(), float(scores[s2])
    else:
        second, second_score = np.full(3, np.nan), 0.0
    return SearchResult(pose[b].copy(), float(scores[b]), second, second_score, nodes, truncated)
