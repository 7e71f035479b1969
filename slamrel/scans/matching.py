"""Point-to-line ICP for 2-D laser scans, with the quality measures a reviewer needs.

Convention
----------
The relation of two scans is ``δ = [x, y, θ]``, the pose of the *current* scan's laser frame
in the *reference* scan's laser frame (``δ_ij = x_i⁻¹ ∘ x_j`` of Kümmerle et al. 2009 with
``i`` the reference, ``j`` the current scan): a current point ``p`` is ``R(θ) p + t`` in the
reference frame.

Metric (Censi 2008, "An ICP variant using a point-to-line metric", ICRA)
-------------------------------------------------------------------------
Each reference return ``a_k`` gets a line: the least-squares line through the returns of
the neighbouring beams ``k−w … k+w`` that lie within ``radius`` and within ``max_gap · |j|``
of it (at least three; a window whose scatter is not line-like,
``λ_min/λ_max > max_curvature``, gets no line: corners and clutter). The line is stored as
its centroid ``c_k`` and unit normal ``n_k``. (Censi builds the line from the two nearest
reference points at every iteration; fitting it once per scan over a few neighbours is the
same metric with less noise and no per-iteration work.) A current point ``q = R p + t`` is
associated with the reference line whose centroid is nearest (exactly by :class:`NearestGrid`
or scipy's cKDTree, or approximately by a raster lookup: ``IcpOptions.nearest``), if nearer
than the gate; its residual is

    e = n_kᵀ (R p + t − c_k)

and the step solves the weighted Gauss–Newton system ``(Jᵀ W J) Δ = −Jᵀ W e`` with
``J = [n_x, n_y, n_kᵀ R' p]`` (``R' p = [−(Rp)_y, (Rp)_x]``), updating ``t += Δ_t``,
``θ += Δ_θ``.

Robustness: the largest ``1 − trim`` share of ``|e|`` is dropped (trimmed ICP,
Chetverikov et al. 2002) and the rest weighted by Cauchy's ``w = 1 / (1 + (e / (c σ))²)``,
``σ = 1.4826 · median |e|`` (never below ``min_sigma``), ``c = 2.385``. The gate starts at
``max_distance`` and shrinks to ``gate_sigmas · σ`` (never below ``min_distance``).

Results (:class:`Alignment`)
----------------------------
``covariance``
    The Gauss–Newton (Hessian) covariance ``Σ = s² (Jᵀ W J)⁻¹``, ``s² = Σ w e² / (Σ w − 3)``,
    at the solution. It is *not* Censi's closed form (which adds the sensitivity of the
    correspondences) and, as every such estimate from correlated laser residuals, it is
    optimistic; use it to compare relations with each other and for the degeneracy test.
``matched_fraction``
    Share of the current scan's returns that end with a reference line within the final
    gate and ``|e| ≤ 3 σ``.
``residual``
    RMS of ``e`` over the matched points [m].
``condition``, ``weak_direction``, ``degenerate``
    The translational information with the rotation marginalised out,
    ``S = H_tt − H_tθ H_θθ⁻¹ H_θt`` (2 × 2, ``H = Jᵀ W J``); ``condition = λ_min / λ_max`` of
    ``S`` and ``weak_direction`` its eigenvector of ``λ_min`` in the reference frame. A
    corridor constrains only the direction across it: ``condition`` near 0, and the weak
    direction is along the corridor. ``degenerate`` when ``condition < degenerate_ratio``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from relation_metric.se2 import wrap_angle_float

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

__all__ = [
    "IcpOptions",
    "PreparedScan",
    "Alignment",
    "prepare_scan",
    "align",
    "transform",
]

_MAD = 1.4826
_CAUCHY = 2.385


@dataclass(frozen=True)
class IcpOptions:
    """Parameters of :func:`align` (lengths in metres, angles in radians).

    Attributes
    ----------
    max_distance : float
        Initial association gate (0.5 m).
    min_distance : float
        Smallest gate the adaptive gate may shrink to (0.05 m).
    gate_sigmas : float
        The gate shrinks to this many robust residual scales (4).
    trim : float
        Share of the associated points kept, the smallest residuals (0.9).
    min_sigma : float
        Floor of the robust residual scale (0.005 m: the order of a laser's range noise).
    max_iterations : int
        Gauss–Newton iterations at most (60).
    tolerance : float
        Convergence: a step below this in translation [m] and in rotation [rad] (1e-6).
    min_matches : int
        Fewer associated points than this is a failure (20).
    degenerate_ratio : float
        ``condition`` below this flags degenerate geometry (0.02).
    stall_tolerance, stall_iterations : float, int
        Also converged: steps below ``stall_tolerance`` (1e-4 m and rad) for
        ``stall_iterations`` (4) iterations in a row at a settled gate. Trimming and the
        gate switch a few correspondences back and forth, and the estimate then circles
        within that tolerance instead of settling below ``tolerance``. When it circles
        exactly (the same iterates again, period 2–4, twice in a row) it stops at the mean
        of the cycle.
    coarse_stride : int
        Above 1: iterate on every ``coarse_stride``-th current return until converged, then
        go on from there, at the gate reached, with every return for at most
        ``polish_iterations`` steps (the many early iterations at a fraction of the cost;
        1: every return throughout). Only when the current scan has at least
        ``4 · coarse_stride · min_matches`` returns; a coarse step that matches fewer than
        ``2 · min_matches`` goes on with every return until converged (a small overlap).
    polish_iterations : int
        Steps with every return after the coarse phase (2).
    shrink_after : int
        The gate may shrink (towards ``gate_sigmas · σ``) after this many steps, or at the
        first step below ``tolerance`` (5).
    nearest : {"grid", "tree", "raster"}
        How a point finds its nearest anchor: ``"grid"`` exactly by :class:`NearestGrid`
        (numpy; the same anchors as ``"tree"``, without ``scipy.spatial`` to import, 0.4 CPU-s
        of a ``relations align`` command); ``"tree"`` exactly by ``scipy``'s cKDTree;
        ``"raster"`` by :class:`NearestRaster` (the anchor nearest its cell's centre, then
        the nearest of that anchor and its two neighbours on each side in scan order: no
        tree to build, no ``scipy.spatial`` to import, a third of the time a query).
    raster_cell, raster_reach : float
        Cell of the ``"raster"`` lookup [m] (0.1), and how far from an anchor its cells reach
        (0.5; never beyond ``max_distance``: farther points find no anchor).
    """

    max_distance: float = 0.5
    min_distance: float = 0.05
    gate_sigmas: float = 4.0
    trim: float = 0.9
    min_sigma: float = 0.005
    max_iterations: int = 60
    tolerance: float = 1e-6
    min_matches: int = 20
    degenerate_ratio: float = 0.02
    stall_tolerance: float = 1e-4
    stall_iterations: int = 4
    coarse_stride: int = 1
    polish_iterations: int = 2
    shrink_after: int = 5
    nearest: str = "grid"
    raster_cell: float = 0.1
    raster_reach: float = 0.5


@dataclass(frozen=True)
class PreparedScan:
    """A scan ready to be matched: its returns, and the lines fitted to it.

    Attributes
    ----------
    points : (K, 2) float
        The returns in the laser frame (the role of the *current* scan).
    anchors, normals : (L, 2) float
        Centroid and unit normal of each fitted line (the role of the *reference* scan),
        in scan order.

    The nearest-anchor lookups (:attr:`grid`, :attr:`tree`, :meth:`raster`) are made when
    first asked for.
    """

    points: NDArray[np.float64]
    anchors: NDArray[np.float64]
    normals: NDArray[np.float64]
    _kept: dict[Any, Any] = field(default_factory=dict, repr=False, compare=False)

    @property
    def tree(self) -> cKDTree:
        """A cKDTree over ``anchors``."""
        got = self._kept.get("tree")
        if got is None:
            from scipy.spatial import cKDTree

            got = self._kept["tree"] = cKDTree(self.anchors)
        return got

    @property
    def grid(self) -> NearestGrid:
        """:class:`NearestGrid` of ``anchors``, kept."""
        got = self._kept.get("grid")
        if got is None:
            got = self._kept["grid"] = NearestGrid(self.anchors)
        return got

    def raster(self, cell: float, reach: float) -> NearestRaster:
        """:class:`NearestRaster` of ``anchors`` (``cell``, ``reach``), kept."""
        key = ("raster", cell, reach)
        got = self._kept.get(key)
        if got is None:
            got = self._kept[key] = NearestRaster(self.anchors, cell, reach)
        return got

    def nearest(
        self, q: NDArray[np.float64], gate: float, opt: IcpOptions
    ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """Distance to and index of the nearest anchor of each ``q`` (``(K, 2)``) within
        ``gate`` (``inf`` and ``L`` beyond it), by ``opt.nearest``."""
        if opt.nearest == "grid":
            return self.grid.query(q, gate)
        if opt.nearest == "raster":
            return self.raster(opt.raster_cell, min(opt.raster_reach, opt.max_distance)).query(
                q, gate
            )
        dist, k = self.tree.query(q, distance_upper_bound=gate)
        return dist, k

    def matches(
        self, q: NDArray[np.float64], gate: float, opt: IcpOptions
    ) -> tuple[NDArray[np.bool_], NDArray[np.int64]]:
        """Whether each ``q`` has an anchor within ``gate``, and the anchor's index where it
        has (:meth:`nearest` without the distances ICP does not read)."""
        if opt.nearest == "grid":
            return self.grid.match(q, gate)[:2]
        if opt.nearest == "raster":
            reach = min(opt.raster_reach, opt.max_distance)
            return self.raster(opt.raster_cell, reach).match(q, gate)[:2]
        dist, k = self.nearest(q, gate, opt)
        return np.isfinite(dist), k


def _least(points: NDArray[np.float64]) -> NDArray[np.float64]:
    """``points.min(axis=0)`` of ``(K, 2)`` points, column by column (the same values; numpy's
    reduction over the first axis of a two-column array is several times slower)."""
    return np.array([points[:, 0].min(), points[:, 1].min()])


def _greatest(points: NDArray[np.float64]) -> NDArray[np.float64]:
    """``points.max(axis=0)`` of ``(K, 2)`` points, column by column."""
    return np.array([points[:, 0].max(), points[:, 1].max()])


#: Empty cells of :class:`NearestGrid`'s table (no anchor within its reach).
_NONE = np.iinfo(np.int64).max


class NearestGrid:
    """The exact nearest anchor, in numpy: a raster proposes, a bound certifies, the rest is
    searched by brute force.

    Every cell (``cell`` wide) within ``cell + reach`` of an anchor holds the anchor nearest
    its centre ``m`` (``a_C``) and a lower bound ``s_C`` on the distance from ``m`` to every
    anchor outside ``S_C``, the :data:`_GRID_SIDE` anchors on each side of ``a_C`` in scan
    order (the same wall). A query ``q`` in that cell (``|q − m| ≤ h``, half the cell's
    diagonal) takes the nearest of ``S_C``, at ``d``. Any anchor ``b`` outside ``S_C`` is at
    least ``s_C − h`` from ``q``; so when ``min(d, gate) ≤ s_C − h`` the answer is exact (the
    nearest, or none within ``gate``). A cell no anchor reaches has every anchor farther than
    ``cell + reach − h`` from its queries: none within a gate up to that. Every other query
    (a point far from every wall under a wide gate, or between two walls) is compared with
    every anchor. The answers are cKDTree's (``query(q, distance_upper_bound=gate)``: the
    nearest anchor strictly within ``gate``), but for which of two anchors at exactly the same
    distance is taken.

    Corridor world 104 (3,480 lookups of the chain's links): 8 % of the queries compared with
    every anchor; lookups as fast as cKDTree's, the tables ~0.4 ms a scan to build.
    """

    def __init__(
        self, anchors: NDArray[np.float64], cell: float = 0.05, reach: float = 0.05
    ) -> None:
        n_a = anchors.shape[0]
        self.n = n_a
        self.ax, self.ay = anchors[:, 0].copy(), anchors[:, 1].copy()
        self.cell = cell
        self._side = np.arange(-_GRID_SIDE, _GRID_SIDE + 1)[None, :]
        self._by_x: NDArray[np.int64] | None = None
        self._sx = self.ax
        self.h = cell * np.sqrt(0.5) * (1.0 + 1e-9) + 1e-9  # the margin: rounding of the cell
        self.lim = cell + reach
        lim2 = self.lim * self.lim
        w = int(np.ceil(self.lim / cell))  # every cell whose centre is within lim of an anchor
        self.cells: NDArray[np.int64] | None = None  # None: a dense table
        if n_a == 0:
            self.lo, self.shape = np.zeros(2), (1, 1)
            self.table, self.s2 = np.full(1, _NONE), np.full(1, lim2)
            return
        self.lo = _least(anchors) - (w + 1) * cell  # outermost cells: no anchor reaches
        ext = np.ceil((_greatest(anchors) + (w + 1) * cell - self.lo) / cell).astype(np.int64)
        self.shape = (int(ext[0]) + 1, int(ext[1]) + 1)
        c = np.floor((anchors - self.lo) * (1.0 / cell)).astype(np.int64)  # (L, 2)
        off = np.arange(-w, w + 1)
        cx = c[:, 0, None] + off[None, :]  # (L, n)
        cy = c[:, 1, None] + off[None, :]
        dx = self.lo[0] + (cx + 0.5) * cell - anchors[:, 0, None]
        dy = self.lo[1] + (cy + 0.5) * cell - anchors[:, 1, None]
        dx *= dx
        dy *= dy
        d2 = (dx[:, :, None] + dy[:, None, :]).ravel()  # (L n n,) anchor to cell centre
        lin = (cx[:, :, None] * self.shape[1] + cy[:, None, :]).ravel()
        n_cells = self.shape[0] * self.shape[1]
        if n_cells > _GRID_DENSE:  # a wide scan (80 m returns): only the cells anchors reach
            self.cells, lin = np.unique(lin, return_inverse=True)
            n_cells = self.cells.shape[0]
        aid = np.repeat(np.arange(n_a, dtype=np.int64), off.size * off.size)
        # the anchor nearest a cell's centre: the least (distance, anchor) packed in one integer
        # (d2 ≤ 2 (w + 1)² cell² < 8 lim2 here: below 2³¹ after scaling, no overflow)
        packed = (d2 * (2**28 / lim2)).astype(np.int64) << 32 | aid
        table = np.full(n_cells, _NONE)
        np.minimum.at(table, lin, packed)
        first = table[lin] & 0xFFFFFFFF
        d2[np.abs(aid - first) <= _GRID_SIDE] = np.inf  # members of S_C: not in the bound
        s2 = np.full(n_cells, lim2)  # anchors not in the pairs lie farther than lim
        np.minimum.at(s2, lin, d2)
        self.table, self.s2 = table, s2

    def query(
        self, q: NDArray[np.float64], gate: float
    ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """Distance and index of the nearest anchor of each ``q`` (``inf`` and ``L`` when none
        lies strictly within ``gate``), as ``cKDTree.query(q, distance_upper_bound=gate)``."""
        ok, k, d2 = self.match(q, gate)
        return np.where(ok, np.sqrt(d2), np.inf), np.where(ok, k, self.n)

    def match(
        self, q: NDArray[np.float64], gate: float
    ) -> tuple[NDArray[np.bool_], NDArray[np.int64], NDArray[np.float64]]:
        """Whether the nearest anchor of each ``q`` lies strictly within ``gate``, its index
        and squared distance (:meth:`query` without the distances ICP does not read)."""
        n_a = self.n
        g2 = gate * gate
        if n_a == 0:
            none = np.zeros(q.shape[0], dtype=bool)
            return none, np.zeros(q.shape[0], dtype=np.int64), np.full(q.shape[0], np.inf)
        # a point outside the raster is clipped onto its outermost cells: no anchor reaches them
        cx = np.maximum((q[:, 0] - self.lo[0]) * (1.0 / self.cell), 0.0)
        cy = np.maximum((q[:, 1] - self.lo[1]) * (1.0 / self.cell), 0.0)
        lin = np.minimum(cx, self.shape[0] - 1.0, out=cx).astype(np.int64) * self.shape[1]
        lin += np.minimum(cy, self.shape[1] - 1.0, out=cy).astype(np.int64)
        if self.cells is not None:
            at = np.searchsorted(self.cells, lin).clip(0, self.cells.shape[0] - 1)
            got = self.table.take(at)
            got[self.cells.take(at) != lin] = _NONE
            s2 = self.s2.take(at)
        else:
            got = self.table.take(lin, mode="clip")  # (NaN queries: any cell, no answer)
            s2 = self.s2.take(lin, mode="clip")
        found = got != _NONE
        cand = (got & 0xFFFFFFFF)[:, None] + self._side  # (K, 2s+1)
        np.maximum(cand, 0, out=cand)
        np.minimum(cand, n_a - 1, out=cand)
        dx = self.ax.take(cand) - q[:, 0, None]
        dy = self.ay.take(cand) - q[:, 1, None]
        d2 = dx * dx + dy * dy
        j = d2.argmin(axis=1)
        rows = np.arange(q.shape[0])
        best2 = d2[rows, j]
        k = cand[rows, j]
        bound = np.sqrt(s2) - self.h
        sure = np.where(
            found,
            (np.minimum(best2, g2) <= bound * bound) & (bound > 0),
            gate <= self.lim - self.h,
        )
        unsure = np.flatnonzero(~sure)
        if unsure.size:
            best2[unsure], k[unsure] = self._sweep(q[unsure], gate)
        return best2 < g2, k, best2

    def _sweep(
        self, q: NDArray[np.float64], gate: float
    ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """Squared distance and index of the nearest anchor of each ``q`` among those within
        ``gate`` of it in ``x`` (a run of the anchors sorted by ``x``; all of them when the
        longest run is not shorter), or any anchor when none is."""
        if self._by_x is None:
            self._by_x = np.argsort(self.ax, kind="stable")
            self._sx = self.ax[self._by_x]
        reach = gate * (1.0 + 1e-9) + 1e-12  # an anchor strictly within gate: inside the run
        lo = np.searchsorted(self._sx, q[:, 0] - reach, side="left")
        hi = np.searchsorted(self._sx, q[:, 0] + reach, side="right")
        width = int((hi - lo).max())
        if width == 0:
            return np.full(q.shape[0], np.inf), np.zeros(q.shape[0], dtype=np.int64)
        if 2 * width >= self.n:  # compared with every anchor
            dx = self.ax[None, :] - q[:, 0, None]
            dy = self.ay[None, :] - q[:, 1, None]
            dd = dx * dx + dy * dy
            jj = dd.argmin(axis=1)
            return dd[np.arange(q.shape[0]), jj], jj
        at = lo[:, None] + np.arange(width)[None, :]
        outside = at >= hi[:, None]
        np.minimum(at, self.n - 1, out=at)
        cand = self._by_x.take(at)
        dx = self.ax.take(cand) - q[:, 0, None]
        dy = self.ay.take(cand) - q[:, 1, None]
        dd = dx * dx + dy * dy
        dd[outside] = np.inf
        jj = dd.argmin(axis=1)
        rows = np.arange(q.shape[0])
        return dd[rows, jj], cand[rows, jj]


#: Anchors on each side of the cell's, in scan order, that :class:`NearestGrid` tries first.
_GRID_SIDE = 4

#: Cells above which :class:`NearestGrid` keeps only the cells anchors reach (sorted).
_GRID_DENSE = 1 << 20


#: Neighbours on each side, in scan order, that :meth:`NearestRaster.query` also tries.
_RASTER_SIDE = 2


class NearestRaster:
    """Nearest anchor by a raster: every cell within ``reach`` of an anchor holds the anchor
    nearest its centre; a query takes its cell's anchor and the :data:`_RASTER_SIDE`
    anchors on each side of it in scan order (along the same wall: the cell's anchor can be
    a cell's width from the query's nearest) and keeps the nearest of them.

    Not exactly the nearest anchor (a point between two walls within a cell of each other
    can take the farther): the point-to-line residual is what ICP uses, and any anchor of the
    same wall gives nearly the same line.
    """

    def __init__(self, anchors: NDArray[np.float64], cell: float, reach: float) -> None:
        self.anchors, self.cell = anchors, cell
        self.ax, self.ay = anchors[:, 0].copy(), anchors[:, 1].copy()
        self._side = np.arange(-_RASTER_SIDE, _RASTER_SIDE + 1)[None, :]
        n_a = anchors.shape[0]
        w = int(np.ceil(reach / cell))
        if n_a == 0:
            self.lo, self.shape = np.zeros(2), (1, 1)
            self.index = np.full(1, -1, dtype=np.int64)
            return
        self.lo = _least(anchors) - (w + 1) * cell
        ext = np.ceil((_greatest(anchors) + (w + 1) * cell - self.lo) / cell).astype(np.int64)
        self.shape = (int(ext[0]) + 1, int(ext[1]) + 1)
        c = np.floor((anchors - self.lo) / cell).astype(np.int64)  # (L, 2)
        off = np.arange(-w, w + 1)
        cx = c[:, 0, None] + off[None, :]  # (L, n)
        cy = c[:, 1, None] + off[None, :]
        dx = self.lo[0] + (cx + 0.5) * cell - anchors[:, 0, None]
        dy = self.lo[1] + (cy + 0.5) * cell - anchors[:, 1, None]
        d2 = dx[:, :, None] ** 2 + dy[:, None, :] ** 2  # (L, n, n)
        lim = (reach + cell) ** 2
        near = d2 <= lim
        lin = (cx[:, :, None] * self.shape[1] + cy[:, None, :])[near]
        # the nearest anchor of a cell: the least of (distance, anchor) packed in one integer
        aid = np.broadcast_to(np.arange(n_a)[:, None, None], d2.shape)[near]
        packed = (d2[near] * (2**30 / lim)).astype(np.int64) << 32 | aid
        table = np.full(self.shape[0] * self.shape[1], np.iinfo(np.int64).max)
        np.minimum.at(table, lin, packed)
        self.index = np.where(table == np.iinfo(np.int64).max, -1, table & 0xFFFFFFFF)

    def query(
        self, q: NDArray[np.float64], gate: float
    ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """Distance and index of the anchor found for each ``q`` (``inf`` and ``L`` when
        none lies within ``gate``), as ``cKDTree.query(q, distance_upper_bound=gate)``."""
        ok, k, dist = self.match(q, gate)
        return np.where(ok, dist, np.inf), np.where(ok, k, self.anchors.shape[0])

    def match(
        self, q: NDArray[np.float64], gate: float
    ) -> tuple[NDArray[np.bool_], NDArray[np.int64], NDArray[np.float64]]:
        """Whether an anchor was found within ``gate`` for each ``q``, its index and distance
        (:meth:`query` without the ``inf`` and ``L`` ICP does not read)."""
        n_a = self.anchors.shape[0]
        # the outermost cells hold no anchor (-1): a point outside is clipped onto them
        cx = np.maximum((q[:, 0] - self.lo[0]) * (1.0 / self.cell), -1.0)
        cy = np.maximum((q[:, 1] - self.lo[1]) * (1.0 / self.cell), -1.0)
        lin = np.minimum(cx, self.shape[0] - 1.0, out=cx).astype(np.int64) * self.shape[1]
        lin += np.minimum(cy, self.shape[1] - 1.0, out=cy).astype(np.int64)
        first = self.index.take(lin, mode="clip")
        found = first >= 0
        cand = first[:, None] + self._side  # (K, 2s+1)
        np.maximum(cand, 0, out=cand)
        np.minimum(cand, max(n_a - 1, 0), out=cand)
        dx = self.ax.take(cand) - q[:, 0, None]
        dy = self.ay.take(cand) - q[:, 1, None]
        d2 = dx * dx + dy * dy
        j = d2.argmin(axis=1)
        rows = np.arange(q.shape[0])
        dist = np.sqrt(d2[rows, j])
        return found & (dist <= gate), cand[rows, j], dist


@dataclass(frozen=True)
class Alignment:
    """The result of :func:`align` (see the module docstring for each measure).

    Attributes
    ----------
    delta : (3,) float
        ``[x, y, θ]`` of the current scan in the reference frame.
    guess : (3,) float
        The initial guess it started from.
    covariance : (3, 3) float
        Gauss–Newton covariance of ``delta`` (NaN when the alignment failed).
    matched_fraction : float
    residual : float
        RMS point-to-line residual of the matched points [m].
    sigma : float
        Robust residual scale at the end [m].
    matches : int
        Number of matched points.
    iterations : int
    converged : bool
    condition : float
        ``λ_min / λ_max`` of the translational information.
    weak_direction : (2,) float
        Unit vector of the least constrained translation, reference frame.
    degenerate : bool
    failed : str
        Why no estimate exists ("" when one does): too few returns or matches.
    """

    delta: NDArray[np.float64]
    guess: NDArray[np.float64]
    covariance: NDArray[np.float64]
    matched_fraction: float
    residual: float
    sigma: float
    matches: int
    iterations: int
    converged: bool
    condition: float
    weak_direction: NDArray[np.float64]
    degenerate: bool
    failed: str = ""


def transform(delta: NDArray[np.float64], points: NDArray[np.float64]) -> NDArray[np.float64]:
    """``R(θ) p + t`` for points ``(K, 2)`` and ``delta = [x, y, θ]``."""
    c, s = np.cos(delta[2]), np.sin(delta[2])
    out = np.empty_like(points)
    out[:, 0] = c * points[:, 0] - s * points[:, 1] + delta[0]
    out[:, 1] = s * points[:, 0] + c * points[:, 1] + delta[1]
    return out


def prepare_scan(
    beam_points: NDArray[np.float64],
    *,
    window: int = 8,
    radius: float = 0.2,
    max_gap: float = 0.3,
    max_curvature: float = 0.05,
) -> PreparedScan:
    """Fit the lines of a scan given in beam order, ``(B, 2)`` with NaN rows for no return.

    Parameters
    ----------
    beam_points : (B, 2) float
        Cartesian returns in the laser frame, one row a beam (NaN: no return), as
        :meth:`slamrel.formats.laser.LaserScans.points` gives them.
    window : int
        Neighbouring beams on each side that may join a line fit (8).
    radius : float
        A neighbour joins only when within ``radius`` of the beam's return [m] (0.2 m: a
        line long enough that 1 cm range noise tilts it little, short enough for corners).
    max_gap : float
        A neighbour ``j`` beams away joins the fit when within ``max_gap · |j|`` [m].
    max_curvature : float
        Largest ``λ_min / λ_max`` of the window's scatter that still counts as a line.
    """
    p = np.asarray(beam_points, dtype=np.float64)
    valid = np.isfinite(p[:, 0]) & np.isfinite(p[:, 1])
    b = p.shape[0]
    offsets = np.arange(-window, window + 1)
    # x and y apart, (beam, window) each, instead of one (beam, window, 2) array
    idx = np.arange(b)[:, None] + offsets[None, :]  # (B, W)
    inside = (idx >= 0) & (idx < b)
    idx = np.clip(idx, 0, max(b - 1, 0))
    px, py = p[:, 0], p[:, 1]
    nx, ny = px[idx], py[idx]  # (B, W)
    with np.errstate(invalid="ignore"):
        dx, dy = nx - px[:, None], ny - py[:, None]
        dist = np.sqrt(dx * dx + dy * dy)
        use = inside & valid[idx] & valid[:, None]
        use &= (dist <= max_gap * np.abs(offsets)[None, :]) & (dist <= radius)
    count = use.sum(axis=1)
    w = use.astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        # the centroid's sums run over the window in order (numpy's sum over the middle
        # axis of a (B, W, 2) array), the scatter's pairwise along each row: as before
        cx = np.ascontiguousarray(np.where(use, nx, 0.0).T).sum(axis=0) / count
        cy = np.ascontiguousarray(np.where(use, ny, 0.0).T).sum(axis=0) / count
        ex = np.where(use, nx - cx[:, None], 0.0)
        ey = np.where(use, ny - cy[:, None], 0.0)
        cxx = (w * ex**2).sum(axis=1)
        cyy = (w * ey**2).sum(axis=1)
        cxy = (w * ex * ey).sum(axis=1)
        half_trace = 0.5 * (cxx + cyy)
        root = np.sqrt(0.25 * (cxx - cyy) ** 2 + cxy**2)
        lam_min, lam_max = half_trace - root, half_trace + root
        phi = 0.5 * np.arctan2(2.0 * cxy, cxx - cyy)
        line = (count >= 3) & (lam_min <= max_curvature * lam_max) & (lam_max > 0)
    normals = np.column_stack((-np.sin(phi), np.cos(phi)))[line]
    anchors = np.column_stack((cx, cy))[line]
    return PreparedScan(p[valid], anchors, normals)


def _cycle(history: list[tuple[float, float, float]], tolerance: float, longest: int = 4) -> int:
    """The period ``p ≤ longest`` with ``x_k = x_{k−p}`` to ``tolerance`` (seen twice), or 0.

    ``history`` holds the iterates as float triples (Python arithmetic: a few hundred
    nanoseconds a test instead of microseconds for numpy's on 3-vectors)."""
    for p in range(2, longest + 1):
        if len(history) > 2 * p and all(
            _close(history[-1 - q], history[-1 - q - p], tolerance) for q in range(p)
        ):
            return p
    return 0


def _close(a: tuple[float, float, float], b: tuple[float, float, float], tol: float) -> bool:
    """``max |a − b| < tol`` (False when a difference is NaN, as numpy's max says)."""
    d0, d1, d2 = abs(a[0] - b[0]), abs(a[1] - b[1]), abs(a[2] - b[2])
    return d0 < tol and d1 < tol and d2 < tol


def _residuals(
    reference: PreparedScan,
    q: NDArray[np.float64],
    k: NDArray[np.int64],
    ok: NDArray[np.bool_],
    opt: IcpOptions,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Normals ``n``, points ``q``, point-to-line residuals ``e`` and ``|e|`` of the matched
    points ``ok`` (nearest anchors ``k``), the largest ``1 − trim`` share of ``|e|`` dropped."""
    at = np.flatnonzero(ok)
    kk = k[at]
    n = reference.normals[kk]
    qo = q[at]
    e = np.einsum("ij,ij->i", n, qo - reference.anchors[kk])
    ae = np.abs(e)
    keep = max(opt.min_matches, int(np.ceil(opt.trim * ae.shape[0])))
    if keep < ae.shape[0]:
        cut = np.partition(ae, keep - 1)[keep - 1]
        sel = np.flatnonzero(ae <= cut)
        n, qo, e, ae = n[sel], qo[sel], e[sel], ae[sel]
    return n, qo, e, ae


def _median(a: NDArray[np.float64]) -> float:
    """The median of a non-empty 1-D array (``np.partition``, without ``np.median``'s checks)."""
    n = a.shape[0]
    h = n // 2
    part = np.partition(a, [h - 1, h] if n % 2 == 0 and n > 1 else h)
    return float(part[h] if n % 2 else 0.5 * (part[h - 1] + part[h]))


def _failed(guess: NDArray[np.float64], why: str, iterations: int = 0) -> Alignment:
    nan3 = np.full((3, 3), np.nan)
    return Alignment(
        guess.copy(),
        guess.copy(),
        nan3,
        0.0,
        float("nan"),
        float("nan"),
        0,
        iterations,
        False,
        float("nan"),
        np.full(2, np.nan),
        False,
        why,
    )


def align(
    reference: PreparedScan,
    current: PreparedScan,
    guess: NDArray[np.float64],
    options: IcpOptions | None = None,
) -> Alignment:
    """Align ``current`` to ``reference`` from ``guess`` by point-to-line ICP.

    Parameters
    ----------
    reference, current : PreparedScan
    guess : (3,) float
        Initial ``[x, y, θ]`` of the current scan in the reference frame.
    options : IcpOptions, optional

    Returns
    -------
    Alignment
        ``failed`` is non-empty (and ``delta`` the guess) when there are too few returns,
        lines or matches to estimate three parameters.
    """
    opt = options or IcpOptions()
    guess = np.asarray(guess, dtype=np.float64).reshape(3)
    x = guess.copy()
    pts = current.points
    if pts.shape[0] < opt.min_matches or reference.anchors.shape[0] < opt.min_matches:
        return _failed(guess, "too few returns or lines")
    gate = opt.max_distance
    converged = False
    it = 0
    sigma = opt.min_sigma
    stalled = 0
    history: list[NDArray[np.float64]] = [x]
    seen: list[tuple[float, float, float]] = [(x[0], x[1], x[2])]
    full, polish = pts, -1
    if opt.coarse_stride > 1 and pts.shape[0] >= opt.coarse_stride * 4 * opt.min_matches:
        pts = full[:: opt.coarse_stride]  # coarse phase: converge on every stride-th return
    for it in range(1, opt.max_iterations + 1):
        q = transform(x, pts)
        ok, k = reference.matches(q, gate, opt)
        if np.count_nonzero(ok) < opt.min_matches * (2 if pts is not full else 1):
            if pts is not full:  # too few for the coarse phase: every return from here on
                pts, polish = full, -1
                q = transform(x, pts)
                ok, k = reference.matches(q, gate, opt)
            if np.count_nonzero(ok) < opt.min_matches:
                return _failed(guess, "too few matches", it)
        n, qo, e, ae = _residuals(reference, q, k, ok, opt)
        sigma = max(_MAD * _median(ae), opt.min_sigma)
        w = 1.0 / (1.0 + (e / (_CAUCHY * sigma)) ** 2)
        jac = np.empty((e.shape[0], 3))
        jac[:, 0] = n[:, 0]
        jac[:, 1] = n[:, 1]
        jac[:, 2] = n[:, 1] * (qo[:, 0] - x[0]) - n[:, 0] * (qo[:, 1] - x[1])
        jw = jac * w[:, None]
        h = jw.T @ jac
        g = jw.T @ e
        try:
            step = -np.linalg.solve(h, g)
        except np.linalg.LinAlgError:
            step = -np.linalg.lstsq(h, g, rcond=None)[0]
        x = x + step
        history.append(x)
        seen.append((float(x[0]), float(x[1]), float(x[2])))
        new_gate = min(opt.max_distance, max(opt.min_distance, opt.gate_sigmas * sigma))
        size = max(float(np.hypot(step[0], step[1])), abs(float(step[2])))
        small = size < opt.tolerance
        stalled = stalled + 1 if size < opt.stall_tolerance else 0
        settled = new_gate >= gate * 0.999
        done = (small or stalled >= opt.stall_iterations) and settled
        period = 0 if done else _cycle(seen, opt.tolerance)
        if period and settled:  # the correspondences repeat: the iteration is periodic
            x = np.mean(history[-period:], axis=0)
            done = True
        if done and pts is not full:  # the coarse phase converged: polish on every return
            pts, polish = full, opt.polish_iterations
            continue
        polish -= 1
        if done or polish == 0:
            converged = True
            break
        gate = min(gate, new_gate) if small or it > opt.shrink_after else gate
    return _summarise(reference, current, x, guess, gate, sigma, it, converged, opt)


def _summarise(
    reference: PreparedScan,
    current: PreparedScan,
    x: NDArray[np.float64],
    guess: NDArray[np.float64],
    gate: float,
    sigma: float,
    iterations: int,
    converged: bool,
    opt: IcpOptions,
) -> Alignment:
    """Quality measures at the solution ``x`` (see the module docstring)."""
    pts = current.points
    q = transform(x, pts)
    ok, k = reference.matches(q, gate, opt)
    kk = k[ok]
    n = reference.normals[kk]
    e = np.einsum("ij,ij->i", n, q[ok] - reference.anchors[kk])
    inlier = np.abs(e) <= 3.0 * sigma
    n, qo, e = n[inlier], q[ok][inlier], e[inlier]
    m = int(e.shape[0])
    if m < opt.min_matches:
        return _failed(guess, "too few matches", iterations)
    w = 1.0 / (1.0 + (e / (_CAUCHY * sigma)) ** 2)
    rp_x, rp_y = qo[:, 0] - x[0], qo[:, 1] - x[1]
    jac = np.column_stack((n[:, 0], n[:, 1], n[:, 1] * rp_x - n[:, 0] * rp_y))
    h = (jac * w[:, None]).T @ jac
    s2 = float((w * e * e).sum() / max(w.sum() - 3.0, 1.0))
    try:
        cov = s2 * np.linalg.inv(h)
    except np.linalg.LinAlgError:
        cov = np.full((3, 3), np.inf)
    if h[2, 2] > 0:
        schur = h[:2, :2] - np.outer(h[:2, 2], h[2, :2]) / h[2, 2]
    else:
        schur = h[:2, :2]
    lam, vec = np.linalg.eigh(schur)
    condition = float(lam[0] / lam[1]) if lam[1] > 0 else 0.0
    out = x.copy()
    out[2] = wrap_angle_float(float(out[2]))
    return Alignment(
        delta=out,
        guess=guess.copy(),
        covariance=cov,
        matched_fraction=m / max(pts.shape[0], 1),
        residual=float(np.sqrt(np.mean(e * e))),
        sigma=sigma,
        matches=m,
        iterations=iterations,
        converged=converged,
        condition=condition,
        weak_direction=vec[:, 0].copy(),
        degenerate=condition < opt.degenerate_ratio,
    )
