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

The search here is level-synchronous: all nodes of the top level are scored, greedy
descents from the 16 best of them (always the best child) give a first leaf score ``s₀``
(from the best one alone, ``s₀`` was a median 0.78 of the final best on corridor world 104,
and 2.4 times the nodes survived ``keep · s₀``); then level by level every node whose
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

from dataclasses import dataclass, field
from typing import Any

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
        Precomputed grids ``L_1 … L_H`` (4: top nodes of 16 × 16 cells; windows are a few
        tens of cells wide, and a fifth level cost more to build than it saved).
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
    levels: int = 4
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


#: A margin of padded tables: cells below and above on each axis, ``((a0, a1), (b0, b1))``.
Margin = tuple[tuple[int, int], tuple[int, int]]

#: Cells added to each side of the margin a search needs when the padded tables are built,
#: so that the next searches of the same grid (a neighbouring pair) fit them as well.
_SLACK = 8


@dataclass(frozen=True)
class LikelihoodGrid:
    """The grids ``L_0 … L_H`` over one area (``(X + 1 + 2^H, Y + 1 + 2^H)`` float32 each,
    with a zero border: one cell below, ``2^H`` above).

    Attributes
    ----------
    lo : (2,) float
        Lower corner [m] of cell ``(0, 0)``.
    resolution : float
    table : (X', Y') float32
        ``L_0``.
    levels : int
        ``H``.

    The levels ``L_h`` are made when first asked for: :attr:`pyramid`, or :meth:`padded`
    (each level padded by edge replication, as the search reads them: built once a grid
    and kept while its searches fit them, not once a search).
    """

    lo: NDArray[np.float64]
    resolution: float
    table: NDArray[np.float32]
    levels: int
    _kept: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)

    @property
    def pyramid(self) -> list[NDArray[np.float32]]:
        """``pyramid[h][c] = max L`` over the ``2^h × 2^h`` cells from ``c``, ``h = 0 … H``."""
        got: list[NDArray[np.float32]] | None = self._kept.get("pyramid")
        if got is None:
            got = self._kept["pyramid"] = _pyramid(self.table, self.levels, ((0, 0), (0, 0)))
        return got

    def padded(
        self, first: NDArray[np.int64], last: NDArray[np.int64], limit: int
    ) -> tuple[list[NDArray[np.float32]], Margin] | None:
        """The levels padded by edge replication to hold the cells ``first … last`` (each
        ``(2,)``, of ``L_0``'s indices) and their margin; None when such a level would exceed
        ``limit`` cells. Kept for the next call that they hold."""
        nx, ny = self.table.shape
        kept: tuple[list[NDArray[np.float32]], Margin] | None = self._kept.get("padded")
        if kept is not None:
            (a0, a1), (b0, b1) = kept[1]
            if first[0] >= -a0 and first[1] >= -b0 and last[0] < nx + a1 and last[1] < ny + b1:
                return kept
        need = [
            [max(int(-first[q]), 0), max(int(last[q]) - (n - 1), 0)] for q, n in ((0, nx), (1, ny))
        ]
        if (nx + need[0][0] + need[0][1]) * (ny + need[1][0] + need[1][1]) > limit:
            return None
        grow = [[m + _SLACK if m else 0 for m in side] for side in need]
        margin: Margin = ((grow[0][0], grow[0][1]), (grow[1][0], grow[1][1]))
        if (nx + sum(grow[0])) * (ny + sum(grow[1])) > limit:
            margin = ((need[0][0], need[0][1]), (need[1][0], need[1][1]))
        kept = (_pyramid(self.table, self.levels, margin), margin)
        self._kept["padded"] = kept
        return kept


def _pyramid(table: NDArray[np.float32], levels: int, margin: Margin) -> list[NDArray[np.float32]]:
    """``L_0 … L_H`` of ``table`` (``L_0``), each padded by ``margin`` cells of edge
    replication (``np.pad(L_h, margin, mode="edge")``); no margin: the levels themselves."""
    (a0, a1), (b0, b1) = margin
    nx, ny = table.shape
    shape = (nx + a0 + a1, ny + b0 + b1)
    if margin == ((0, 0), (0, 0)):
        first = table
    else:  # L_0's edges are its zero border: its margin is zero
        first = np.zeros(shape, dtype=np.float32)
        first[a0 : a0 + nx, b0 : b0 + ny] = table
    out = [first]
    prev = table
    rows = np.empty(table.shape, dtype=np.float32)  # max over 2^h rows, then 2^h columns
    for h in range(1, levels + 1):
        s = 2 ** (h - 1)
        np.maximum(prev[:-s, :], prev[s:, :], out=rows[:-s, :])
        rows[-s:, :] = prev[-s:, :]
        whole = np.empty(shape, dtype=np.float32)
        nxt = whole[a0 : a0 + nx, b0 : b0 + ny]
        np.maximum(rows[:, :-s], rows[:, s:], out=nxt[:, :-s])
        nxt[:, -s:] = rows[:, -s:]
        _fill_margin(whole, margin)
        out.append(whole)
        prev = nxt
    return out


def _fill_margin(t: NDArray[np.float32], margin: Margin) -> None:
    """Fill the ``margin`` of ``t`` by edge replication of its inside (``np.pad``'s ``edge``)."""
    (a0, a1), (b0, b1) = margin
    nx, ny = t.shape[0] - a0 - a1, t.shape[1] - b0 - b1
    if a0:
        t[:a0, b0 : b0 + ny] = t[a0, b0 : b0 + ny]
    if a1:
        t[a0 + nx :, b0 : b0 + ny] = t[a0 + nx - 1, b0 : b0 + ny]
    if b0:
        t[:, :b0] = t[:, b0 : b0 + 1]
    if b1:
        t[:, b0 + ny :] = t[:, b0 + ny - 1 : b0 + ny]


def grid_cells(lo: NDArray[np.float64], hi: NDArray[np.float64], resolution: float) -> float:
    """Cells of a grid over ``[lo, hi]`` (a float: an absurd extent exceeds every integer)."""
    ext = np.maximum(np.asarray(hi, float) - np.asarray(lo, float), 0.0)
    return float(np.prod(np.ceil(ext / resolution) + 1))


#: Points per block of :func:`_splat`.
_SPLAT = 1024


def _splat(
    flat: NDArray[np.float32],
    shape: tuple[int, int, int],
    cell: NDArray[np.int64],
    points: NDArray[np.float64],
    kernel: tuple[NDArray[np.float64], float, float, int],
    inside: bool,
) -> None:
    """``flat = max(flat, kernel)`` of ``points`` ``(K, 2)`` in cells ``cell`` ``(K, 2)``
    (``inside``: every kernel cell lies inside the area, none is tested).

    ``flat`` is the table raveled, ``shape = (Y', X, Y)`` its row length and the area whose
    cells ``[1, X) × [1, Y)`` take values (the border stays zero); ``kernel = (lo, r, σ, w)``.
    Kernel cell ``(a, b)`` of point ``k`` is ``cell_k + (o_a, o_b)``, ``o = −w … w``, value
    ``exp(−‖c − p_k‖² / (2σ²))``: the offsets per axis ``(2w+1, K)`` broadcast to
    ``(2w+1, 2w+1, K)``, the points along the last axis (long inner loops; the order of a
    maximum does not change it)."""
    lo, r, sig, w = kernel
    off = np.arange(-w, w + 1)[:, None]  # (2w+1, 1): the points run along the last axis
    cx = off + cell[None, :, 0]
    cy = off + cell[None, :, 1]
    dx = lo[0] + (cx + 0.5) * r - points[None, :, 0]
    dy = lo[1] + (cy + 0.5) * r - points[None, :, 1]
    # separable: exp(−(dx² + dy²)/2σ²) = exp(−dx²/2σ²) · exp(−dy²/2σ²), 2(2w+1) exps a point
    # (the float64 product differs from exp of the sum by float64 roundings, far below the
    # float32 table's: the same tables on corridor worlds 103-105, measured)
    s = -1.0 / (2 * sig * sig)
    ex, ey = np.exp(dx * dx * s), np.exp(dy * dy * s)
    n = off.shape[0]
    val: NDArray[np.float32] = np.empty((n, n, cell.shape[0]), dtype=np.float32)
    np.multiply(ex[:, None, :], ey[None, :, :], out=val, casting="same_kind")
    lin = (off * shape[0] + off.T)[:, :, None] + (cell[:, 0] * shape[0] + cell[:, 1])[None, None]
    if inside:
        lin, val = lin.ravel(), val.ravel()
    else:
        ok = ((cx >= 1) & (cx < shape[1]))[:, None, :] & ((cy >= 1) & (cy < shape[2]))[None, :, :]
        lin, val = lin[ok], val[ok]
    # one flat index: ufunc.at's fast path (a tuple of index arrays is ~6x slower)
    np.maximum.at(flat, lin, val)


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
    cell = np.floor((points - lo) / r).astype(np.int64)  # (K, 2)
    cx, cy = cell[:, 0], cell[:, 1]  # per axis (np.all over a 2-column axis is slow)
    inside = (cx - w >= 1) & (cx + w < shape[0]) & (cy - w >= 1) & (cy + w < shape[1])
    meets = (cx + w >= 1) & (cx - w < shape[0]) & (cy + w >= 1) & (cy - w < shape[1])
    flat = table.ravel()
    dims = (table.shape[1], shape[0], shape[1])
    for part, whole in ((np.flatnonzero(inside), True), (np.flatnonzero(meets & ~inside), False)):
        for a in range(0, part.size, _SPLAT):  # blocks that stay in the cache
            at = part[a : a + _SPLAT]
            _splat(flat, dims, cell[at], points[at], (lo, r, sig, w), whole)
    return LikelihoodGrid(lo, r, table, options.levels)


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


#: Largest padded level [cells] (16 MB of float32); a larger one reads through the clip.
_PAD_LIMIT = 2**22
#: Lookups per block of :meth:`_Lookup.score` (512 KB of indices).
_BLOCK = 65536


def _parked(
    base: NDArray[np.int64], shape: tuple[int, ...], half: int, top: int
) -> NDArray[np.int64]:
    """``base`` with every cell whose lookups all miss the reference parked just above the
    table's far corner.

    A point at cell ``x`` is read, at level ``h``, over the cells ``x + u … x + u + 2^h − 1``
    (``|u| ≤ half``, ``2^h ≤ top``). When ``x < −(half + top − 1)`` or ``x > nx − 1 + half``
    (or the same in ``y``) all of them lie outside the table's cells, where ``L_0`` is 0, so
    0 is its exact value at level 0 and a valid bound above. Parked at ``(nx + half,
    ny + half)``, every lookup reads the edge-replicated zero corner (the table's last
    ``top`` rows and columns are zero, so every level is 0 there). The padded levels then
    need margins of at most ``2 half + top`` cells instead of the current points' extent."""
    nx, ny = shape[0], shape[1]
    bx, by = base[:, :, 0], base[:, :, 1]
    far = (bx < -(half + top - 1)) | (bx > nx - 1 + half) | (by < -(half + top - 1))
    far |= by > ny - 1 + half
    if not far.any():
        return base
    out = base.copy()
    out[far] = (nx + half, ny + half)
    return out


class _Lookup:
    """:func:`_score` without the clip: each level ``L_h`` padded by edge replication so
    that every lookup of the search (rotated points ``base`` moved by ``u, v ∈ ±half``)
    lands inside it — the replicated border is exactly the value the clip reads — and the
    points' cells as flat indices, so a node's score is one ``take`` of ``(N, M)``.
    Falls back to :func:`_score` when the padding would exceed ``limit`` cells a level."""

    def __init__(
        self, grid: LikelihoodGrid, base: NDArray[np.int64], half: int, limit: int
    ) -> None:
        self.grid, self.base = grid, base
        base = _parked(base, grid.table.shape, half, 2**grid.levels)
        bx, by = base[:, :, 0], base[:, :, 1]  # (per axis: numpy's (0, 1) reduction of the
        # last axis's two columns is ~30x slower)
        first = np.array([bx.min(), by.min()]) - half  # (2,) the lookups' extreme cells
        last = np.array([bx.max(), by.max()]) + half
        got = grid.padded(first, last, limit)
        self.padded = got is not None
        if got is None:
            return
        tables, ((a0, _), (b0, _)) = got
        self.stride = int(tables[0].shape[1])
        self.tables = [t.ravel() for t in tables]
        self.flat = (base[:, :, 0] + a0) * self.stride + (base[:, :, 1] + b0)  # (T, M)
        self.ones = np.ones(base.shape[1], dtype=np.float32)

    def score(
        self, h: int, k: NDArray[np.int64], u: NDArray[np.int64], v: NDArray[np.int64]
    ) -> NDArray[np.float64]:
        """``_score(grid, base, h, k, u, v)``, the same values; in blocks of about
        ``_BLOCK`` lookups that stay in the cache (each row's mean is the same sum)."""
        if not self.padded:
            return _score(self.grid, self.base, h, k, u, v)
        table, flat = self.tables[h], self.flat
        n, m = k.shape[0], flat.shape[1]
        rows = max(1, _BLOCK // max(m, 1))
        out = np.empty(n, dtype=np.float64)
        idx = np.empty((min(rows, n), m), dtype=np.int64)
        val = np.empty((min(rows, n), m), dtype=np.float32)
        sums = np.empty(min(rows, n), dtype=np.float32)
        shift = u * self.stride + v
        for a in range(0, n, rows):
            b = min(a + rows, n)
            ib, vb = idx[: b - a], val[: b - a]
            flat.take(k[a:b], axis=0, out=ib, mode="clip")  # the points' cells, then moved
            ib += shift[a:b, None]
            table.take(ib, out=vb, mode="clip")  # in bounds; "raise" would buffer out
            np.matmul(vb, self.ones, out=sums[: b - a])
            out[a:b] = sums[: b - a]
        out /= m  # np.mean's own steps (sum, then divide), without its per-call checks
        return out


#: Top-level nodes (best bounds first) the first descent starts from.
_GREEDY_STARTS = 16


def _greedy(
    look: _Lookup,
    top: tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]],
    half: int,
    starts: int | None = None,
) -> float:
    """Score of the best leaf reached by always splitting the best child, from each of the
    ``starts`` top nodes with the highest bounds (a first lower bound: a leaf's score)."""
    k, u, v, b = top
    n = min(_GREEDY_STARTS if starts is None else starts, b.size)
    if n == 0:
        return 0.0
    pick = np.argpartition(-b, n - 1)[:n] if n < b.size else np.arange(b.size)
    kk, uu, vv = k[pick], u[pick], v[pick]
    best = 0.0
    for h in range(look.grid.levels, 0, -1):
        s = 2 ** (h - 1)
        ck = np.repeat(kk, 4)
        cu = (uu[:, None] + np.array([0, s, 0, s])[None, :]).ravel()
        cv = (vv[:, None] + np.array([0, 0, s, s])[None, :]).ravel()
        ok = (cu <= half) & (cv <= half)  # the first child is always inside the window
        sc = np.full(ck.size, -np.inf)
        sc[ok] = look.score(h - 1, ck[ok], cu[ok], cv[ok])
        first = sc.reshape(-1, 4).argmax(axis=1) + 4 * np.arange(kk.size)  # best child
        kk, uu, vv = ck[first], cu[first], cv[first]
        best = float(sc[first].max())
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


def _percentile_90(x: NDArray[np.float64]) -> float:
    """``np.percentile(x, 90)`` (linear, numpy's own interpolation steps: the same value) by a
    partition, without the ``np.unique`` inside numpy's, which imports ``numpy.ma``."""
    n = x.shape[0]
    v = (n - 1) * 0.9
    lo = int(np.floor(v))
    hi = min(lo + 1, n - 1)
    part = np.partition(x, [lo, hi]) if hi != lo else np.partition(x, lo)
    a, b, g = float(part[lo]), float(part[hi]), v - lo
    d = b - a
    return b - d * (1 - g) if g >= 0.5 else a + d * g


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
    rho = _percentile_90(np.hypot(current[:, 0], current[:, 1]))
    dth = r / max(rho, r)
    nth = int(np.ceil(min(window_theta, np.pi) / dth))
    thetas = centre[2] + dth * np.arange(-nth, nth + 1)
    c, s = np.cos(thetas)[:, None], np.sin(thetas)[:, None]
    px, py = current[None, :, 0], current[None, :, 1]
    rot = np.stack((c * px - s * py, s * px + c * py), axis=-1)  # (T, M, 2)
    base = np.floor((rot + centre[:2] - grid.lo) / r).astype(np.int64)
    half = int(np.ceil(window_xy / r))
    top_h = grid.levels
    step = 2**top_h
    starts = np.arange(-half, half + 1, step)
    tk, tu, tv = (
        a.ravel() for a in np.meshgrid(np.arange(thetas.size), starts, starts, indexing="ij")
    )
    look = _Lookup(grid, base, half, _PAD_LIMIT)
    bounds = look.score(top_h, tk, tu, tv)
    nodes = int(bounds.size)
    best = _greedy(look, (tk, tu, tv, bounds), half)
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
        bounds = look.score(h - 1, k, u, v)
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
