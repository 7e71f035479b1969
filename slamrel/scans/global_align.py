"""Reference relations that do not depend on the guess: a scan-matched chain, local submaps,
a branch-and-bound search over a window from the chain's drift, an ambiguity test, ICP.

1. **Chain** (scan-matched odometry). The scans the pairs use, plus fill-in keyframes where
   two of them are more than ``chain_gap`` apart along the path, sorted in time, are linked
   by point-to-line ICP from the given poses' motion (the log's odometry, or an estimate's);
   a link ICP leaves failed or lost (low overlap, high residual) is searched again by
   branch and bound over ``±link_xy, ±link_theta``; the chain poses compose the links.
   Its own travel ``D_ij`` (path length between two scans) sizes the windows below.
2. **Local pairs** (``D_ij ≤ local_travel``): ICP from the chain's relation, judged as
   :func:`slamrel.scans.relations.align_scans` judges, except that a ``large correction``
   (from the given poses' relation) is one beyond the link window ``link_xy + drift_xy D``,
   ``link_theta + drift_theta D``: within it, it is the given motion's error.
3. **Distant pairs** (loops): the reference is a **local submap** — the returns of the chain
   scans within ``submap_travel`` of scan ``i`` along the path, moved into ``i``'s frame by
   the chain — and so is the current side (around ``j``). Branch and bound
   (:mod:`slamrel.scans.search`) over ``centre ± [w_xy, w_xy, w_θ]``,
   ``w_xy = window_xy + drift_xy · D_ij`` and ``w_θ = window_theta + drift_theta · D_ij``
   (the chain's error grows with the travel between the scans), centred on the chain's
   relation; the best candidate is refined by ICP of the two scans themselves.
   Flags: ``ambiguous`` (a second hypothesis at a distinct pose scores at least
   ``ambiguity`` of the best, or the window held too many near-equal ones), ``low score``
   (best below ``min_score``), ``unstable`` (ICP moved more than ``max_refine`` /
   ``max_refine_angle`` from the search's answer), and the ICP's own ``failed``,
   ``not converged``, ``degenerate``, ``low overlap``, ``high residual``.

A window whose grid would exceed :attr:`SearchOptions.max_cells` is refused with
:class:`~relation_metric.errors.InputError` (the scan's line, the travel, the window).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from relation_metric.errors import InputError
from relation_metric.se2 import between, cumulative_compose
from slamrel.formats.laser import LaserScans
from slamrel.scans.batch_icp import align_many
from slamrel.scans.matching import Alignment, PreparedScan, align, prepare_scan, transform
from slamrel.scans.proposals import Proposals
from slamrel.scans.relations import AlignOptions, ScanRelations, _judge, far_guess_error
from slamrel.scans.search import (
    LikelihoodGrid,
    SearchOptions,
    SearchResult,
    branch_and_bound,
    grid_cells,
    likelihood_grid,
)

__all__ = ["GlobalOptions", "align_scans_global", "Chain", "scan_chain"]


@dataclass(frozen=True)
class GlobalOptions:
    """Parameters of :func:`align_scans_global` (metres, radians; see the module docstring).

    Attributes
    ----------
    search : SearchOptions
    window_xy, window_theta : float
        Window at zero travel (0.3 m, 0.05 rad).
    drift_xy, drift_theta : float
        Window growth per metre travelled between the two scans (0.01, 0.0005 rad/m).
    local_travel : float
        Pairs at most this far apart along the path are aligned from the chain (3 m).
    submap_travel : float
        Scans within this travel of a pair's scan join its submap (5 m).
    retry_travel : float
        A distant pair whose search is ambiguous or scores low is searched again with
        submaps this large (10 m; not above ``submap_travel``: no retry).
    search_range : float
        Returns beyond this range are left out of the search (not of ICP) (15 m).
    max_points : int
        The current submap's returns are thinned to about this many for the search (250; 150
        made the searches of lost chain links slip on ``mit-csail.clf``: 90 more failed
        relations).
    refine_points : int
        The current submap's returns are thinned to about this many for the submap ICP
        that resolves a degenerate loop pair's weak direction (1000).
    chain_gap : float
        Fill-in keyframes where the pairs' scans are farther apart than this (1.5 m).
    link_xy, link_theta : float
        Window of a chain link's search when ICP loses it (0.5 m, 0.2 rad).
    ambiguity, min_score : float
        Flag thresholds (0.95, 0.25; calibrated on corridor worlds 101–102).
    weak_geometry : bool
        Flag ``weak geometry`` (False: a corridor's weak direction is what the submap
        search and its ambiguity test judge; the condition stays in the report).
    max_refine, max_refine_angle : float
        ``unstable`` when ICP moves farther from the search's answer (0.1 m, 0.03 rad).
    icp_tolerance, icp_stall_tolerance, icp_stall_iterations : float, float, int
        The ICP runs of this aligner stop at a step below ``icp_tolerance`` (1e-4 m and rad),
        or after ``icp_stall_iterations`` (2) steps in a row below ``icp_stall_tolerance``
        (5e-4) at a settled gate: :class:`~slamrel.scans.matching.IcpOptions`'
        ``tolerance``, ``stall_tolerance`` and ``stall_iterations`` (its defaults 1e-6,
        1e-4, 4 took twice the iterations for changes of hundredths of a millimetre;
        corridor worlds 103-105, measured).
    icp_coarse_stride : int
        :attr:`~slamrel.scans.matching.IcpOptions.coarse_stride` of this aligner's ICP runs
        (2: converge on every second return, then two steps with all of them; corridor
        worlds 103-105: 1.15x the pairs per CPU-second, unflagged median 2.46 -> 2.60 mm,
        p99 unchanged).
    icp_shrink_after : int
        :attr:`~slamrel.scans.matching.IcpOptions.shrink_after` of this aligner's ICP runs
        (2, its default 5: the gate settles three steps sooner; corridor worlds 103-105:
        15 % fewer iterations, the same flags and accuracy).
    icp_nearest, icp_raster_reach : str, float
        :attr:`~slamrel.scans.matching.IcpOptions.nearest` and ``raster_reach`` of this
        aligner's ICP runs (``"raster"``, 0.3 m: no k-d tree to build or query, and no
        ``scipy.spatial`` to import; the gate's first steps reach 0.3 m instead of 0.5).
    fast_links : bool
        The chain's links use the ``icp_*`` settings above too (False: they keep the
        caller's ICP, exact and strict; on ``mit-csail.clf`` the fast settings slipped a
        link now and then, and every later chain pose with it: 27-116 failed relations
        instead of 15-20).
    """

    search: SearchOptions = field(default_factory=SearchOptions)
    window_xy: float = 0.3
    window_theta: float = 0.05
    drift_xy: float = 0.01
    drift_theta: float = 0.0005
    local_travel: float = 3.0
    submap_travel: float = 5.0
    retry_travel: float = 10.0
    search_range: float = 15.0
    max_points: int = 250
    refine_points: int = 1000
    chain_gap: float = 1.5
    link_xy: float = 0.5
    link_theta: float = 0.2
    ambiguity: float = 0.95
    min_score: float = 0.25
    weak_geometry: bool = False
    max_refine: float = 0.1
    max_refine_angle: float = 0.03
    icp_tolerance: float = 1e-4
    icp_stall_tolerance: float = 5e-4
    icp_stall_iterations: int = 2
    icp_coarse_stride: int = 2
    icp_shrink_after: int = 2
    icp_nearest: str = "raster"
    fast_links: bool = False
    icp_raster_reach: float = 0.3


@dataclass(frozen=True)
class Chain:
    """Scan-matched odometry over some scans.

    Attributes
    ----------
    nodes : (n,) int
        Scan indices, in time order.
    poses : (n, 3) float
        Chain poses (the first node at its given pose).
    travel : (n,) float
        Path length from the first node [m].
    links : list of Alignment
        ``links[k]`` aligns ``nodes[k + 1]`` to ``nodes[k]``.
    link_guess : (n − 1, 3) float
        The given poses' motion of each link.
    fallback : int
        Links neither ICP nor the search could align (the given motion kept).
    """

    nodes: NDArray[np.int64]
    poses: NDArray[np.float64]
    travel: NDArray[np.float64]
    links: list[Alignment]
    link_guess: NDArray[np.float64]
    fallback: int


#: Likelihood grids :class:`_Scans` keeps (oldest dropped first).
_KEEP_GRIDS = 4


class _Scans:
    """Prepared scans (ICP) and search returns, made once per scan."""

    def __init__(self, scans: LaserScans, opt: AlignOptions, gopt: GlobalOptions) -> None:
        self.scans, self.opt, self.gopt = scans, opt, gopt
        self._prep: dict[int, PreparedScan] = {}
        self._near: dict[int, NDArray[np.float64]] = {}
        self._grids: dict[tuple[object, bytes, bytes], LikelihoodGrid] = {}
        self._bounds: dict[object, tuple[NDArray[np.float64], NDArray[np.float64]]] = {}
        self.submaps: dict[tuple[int, float], NDArray[np.float64]] = {}
        self.link_icp = opt.icp

    def prep(self, k: int) -> PreparedScan:
        if k not in self._prep:
            pts = self.scans.points(k, min_range=self.opt.min_range, max_range=self.opt.max_range)
            self._prep[k] = prepare_scan(pts)
        return self._prep[k]

    def near(self, k: int) -> NDArray[np.float64]:
        """Returns within ``search_range``."""
        got = self._near.get(k)
        if got is None:
            p = self.prep(k).points
            got = self._near[k] = p[np.hypot(p[:, 0], p[:, 1]) <= self.gopt.search_range]
        return got

    def bounds(
        self, key: object, ref: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Per-axis least and greatest of ``ref`` ``(K, 2)``, kept for a named reference."""
        got = self._bounds.get(key) if key is not None else None
        if got is None:
            xs, ys = ref[:, 0], ref[:, 1]
            got = (np.array([xs.min(), ys.min()]), np.array([xs.max(), ys.max()]))
            if key is not None:
                self._bounds[key] = got
                while len(self._bounds) > 4 * _KEEP_GRIDS:
                    self._bounds.pop(next(iter(self._bounds)))
        return got

    def grid(
        self,
        key: object,
        ref: NDArray[np.float64],
        lo: NDArray[np.float64],
        hi: NDArray[np.float64],
    ) -> LikelihoodGrid:
        """``likelihood_grid(ref, lo, hi)``, kept for the next searches of the same reference
        ``key`` over the same area (the pairs of one scan come together: a few suffice)."""
        k = (key, lo.tobytes(), hi.tobytes())
        got = self._grids.get(k)
        if got is None:
            got = self._grids[k] = likelihood_grid(ref, lo, hi, self.gopt.search)
            while len(self._grids) > _KEEP_GRIDS:
                self._grids.pop(next(iter(self._grids)))
        return got


def _unique(values: NDArray[np.int64]) -> NDArray[np.int64]:
    """``np.unique`` of integers by a sort (``np.unique`` imports ``numpy.ma``, 16 ms of the
    command's start-up, to test for a masked array)."""
    v = np.sort(np.asarray(values, dtype=np.int64).ravel())
    return v[np.concatenate(([True], v[1:] != v[:-1]))] if v.size else v


def _chain_nodes(
    poses: NDArray[np.float64], used: NDArray[np.int64], gap: float
) -> NDArray[np.int64]:
    """``used`` (sorted, unique) plus scans every ``gap / 1.5`` m of the given poses' travel
    wherever two used scans are more than ``gap`` apart."""
    step = between(poses[:-1], poses[1:])
    travel = np.concatenate(([0.0], np.cumsum(np.hypot(step[:, 0], step[:, 1]))))
    t = travel[used]
    extra = []
    spacing = gap / 1.5
    for a in np.flatnonzero(np.diff(t) > gap).tolist():
        if (t[a + 1] - t[a]) / spacing > used[a + 1] - used[a]:  # more marks than scans
            extra.append(np.arange(used[a] + 1, used[a + 1]))  # (a jump): every scan between
            continue
        marks = np.arange(t[a] + spacing, t[a + 1] - spacing / 2, spacing)
        extra.append(np.searchsorted(travel, marks))
    allk = np.concatenate([used, *extra]) if extra else used
    return _unique(allk)


def scan_chain(
    scans: LaserScans,
    poses: NDArray[np.float64],
    used: NDArray[np.int64],
    store: _Scans,
) -> Chain:
    """The chain over ``used`` (and fill-ins), see the module docstring, step 1."""
    gopt, opt = store.gopt, store.opt
    nodes = _chain_nodes(poses, _unique(used), gopt.chain_gap)
    guess = between(poses[nodes[:-1]], poses[nodes[1:]])
    links: list[Alignment] = []
    motion = guess.copy()
    fallback = 0
    pairs = list(zip(nodes[:-1].tolist(), nodes[1:].tolist(), strict=True))
    first = align_many(
        [store.prep(i) for i, _ in pairs], [store.prep(j) for _, j in pairs], guess, store.link_icp
    )
    for k, (i, j) in enumerate(pairs):
        a = first[k]
        flags = _judge(a, opt.limits, guess[k])[0]
        if {"failed", "low overlap", "high residual"} & set(flags):
            centre = guess[k]
            s = _search(store, [i], [j], np.zeros(3), centre, gopt.link_xy, gopt.link_theta)
            b = align(store.prep(i), store.prep(j), s.delta, store.link_icp)
            if not b.failed and (a.failed or b.matched_fraction > a.matched_fraction):
                a = b
        a = pinned(a, guess[k], gopt.drift_xy * float(np.hypot(guess[k, 0], guess[k, 1])))
        if a.failed:
            fallback += 1
        else:
            motion[k] = a.delta
        links.append(a)
    if not nodes.size:  # no pair proposed (e.g. --distance beyond the whole drive)
        return Chain(nodes, np.zeros((0, 3)), np.zeros(0), [], np.zeros((0, 3)), 0)
    chain = cumulative_compose(motion, poses[nodes[0]])
    travel = np.concatenate(([0.0], np.cumsum(np.hypot(motion[:, 0], motion[:, 1]))))
    return Chain(nodes, chain, travel, links, guess, fallback)


def pinned(al: Alignment, prior: NDArray[np.float64], sd: float) -> Alignment:
    """``al`` with its weak direction taken from ``prior`` when ICP calls it degenerate.

    Solution remapping (Zhang, Kaess & Singh 2016, "On degeneracy of optimization-based
    state estimation problems"): along the weak direction ``w`` (translation, rotation
    marginalised out) the scans do not tell where the answer lies, and ICP slides there
    by up to tens of centimetres (corridor worlds: 36 cm on 1 m pairs whose odometry is
    within 3 cm). The translation keeps ICP's component across ``w`` and ``prior``'s along
    it, ``t = t* − d w``, ``d = wᵀ(t* − t_prior)``; the rotation follows its conditional
    optimum ``θ = θ* − Λ_θθ⁻¹ Λ_θt (t − t*)`` (``Λ = Σ⁻¹``); the covariance gains
    ``sd² v vᵀ`` along that move ``v``. Not degenerate, or failed: ``al`` unchanged.
    """
    from dataclasses import replace

    if al.failed or not al.degenerate or not np.isfinite(al.covariance).all():
        return al
    w = np.asarray(al.weak_direction, dtype=np.float64)
    info = np.linalg.pinv(al.covariance)
    v = np.array([w[0], w[1], -float(info[2, :2] @ w) / info[2, 2] if info[2, 2] > 0 else 0.0])
    d = float(w @ (al.delta[:2] - prior[:2]))
    delta = al.delta - d * v
    return replace(al, delta=delta, covariance=al.covariance + sd * sd * np.outer(v, v))


def _resolved(al: Alignment) -> Alignment:
    """``al`` judged as not degenerate: :func:`pinned` took its weak direction from the
    chain or the search (the report keeps its ``condition`` and weak direction)."""
    from dataclasses import replace

    return replace(al, degenerate=False)


def _submap(store: _Scans, chain: Chain, a: int, reach: float | None = None) -> list[int]:
    """Chain positions within ``reach`` (default ``submap_travel``) of position ``a``."""
    t = chain.travel
    reach = store.gopt.submap_travel if reach is None else reach
    return np.flatnonzero(np.abs(t - t[a]) <= reach).tolist()


def _points_in(
    store: _Scans, chain: Chain, a: int, members: list[int], stride: int = 1
) -> NDArray[np.float64]:
    """Search returns of the chain scans ``members`` in the frame of chain position ``a``."""
    rel = between(chain.poses[a], chain.poses[members])
    parts = [
        transform(rel[q], store.near(int(chain.nodes[m]))[::stride]) for q, m in enumerate(members)
    ]
    return np.concatenate(parts) if parts else np.zeros((0, 2))


#: Submaps' returns :func:`_submap_points` keeps (oldest dropped first).
_KEEP_SUBMAPS = 16


def _submap_points(store: _Scans, chain: Chain, a: int, reach: float) -> NDArray[np.float64]:
    """``_points_in`` of the submap of chain position ``a`` (``reach``), kept for the next
    pairs of the same scan (a scan's pairs come together; a submap is the same each time)."""
    key = (a, reach)
    got = store.submaps.get(key)
    if got is None:
        got = store.submaps[key] = _points_in(store, chain, a, _submap(store, chain, a, reach))
        while len(store.submaps) > _KEEP_SUBMAPS:
            store.submaps.pop(next(iter(store.submaps)))
    return got


def _thinned(points: NDArray[np.float64], n: int) -> NDArray[np.float64]:
    """Every ``⌈K / n⌉``-th of ``points`` ``(K, 2)``."""
    return points[:: max(1, -(-points.shape[0] // n))]


#: A guess farther than this [m] from where its scans could overlap is refused as input
#: (a pose at 1e20 m), not searched: no drive moves that far between two scans.
MAX_GUESS_DISTANCE = 1e7


def _refuse_hopeless(
    store: _Scans, i: int, j: int, centre: NDArray[np.float64], reach: float
) -> None:
    """Refuse a guess that puts scan ``j`` more than :data:`MAX_GUESS_DISTANCE` beyond any
    overlap with scan ``i`` (file and line of ``j``)."""
    apart = float(np.hypot(centre[0], centre[1]))
    if not apart > reach + MAX_GUESS_DISTANCE:
        return
    raise far_guess_error(
        store.scans, (i, j), apart, reach, ": no placement it tries lets them overlap"
    )


def _search(
    store: _Scans,
    ref_scans: list[int],
    cur_scans: list[int],
    _unused: NDArray[np.float64],
    centre: NDArray[np.float64],
    wxy: float,
    wth: float,
    ref_pts: NDArray[np.float64] | None = None,
    cur_pts: NDArray[np.float64] | None = None,
    ref_key: object = None,
) -> SearchResult:
    """Branch and bound of ``cur_pts`` (default: scan ``cur_scans[0]``'s search returns)
    against ``ref_pts`` (default: ``ref_scans[0]``'s), refusing a grid over ``max_cells``;
    ``ref_key`` names ``ref_pts`` for the store's grids (None: not kept)."""
    sopt = store.gopt.search
    ref = store.near(ref_scans[0]) if ref_pts is None else ref_pts
    cur = _thinned(store.near(cur_scans[0]), store.gopt.max_points) if cur_pts is None else cur_pts
    if ref.shape[0] < 3 or cur.shape[0] < 3:
        nan3 = np.full(3, np.nan)
        return SearchResult(np.asarray(centre, float).copy(), 0.0, nan3, 0.0, 0, False)
    reach = float(np.max(np.hypot(cur[:, 0], cur[:, 1]))) + wxy + 4 * sopt.sigma
    ref_min, ref_max = store.bounds(ref_key, ref)
    lo = np.maximum(ref_min, centre[:2] - reach) - 4 * sopt.sigma
    hi = np.minimum(ref_max, centre[:2] + reach) + 4 * sopt.sigma
    empty = bool(np.any(hi < lo))  # no placement in the window overlaps the reference
    hi = np.maximum(hi, lo + sopt.resolution)
    cells = grid_cells(lo, hi, sopt.resolution)
    window_cells = (2 * wxy / sopt.resolution + 1) ** 2
    if cells > sopt.max_cells or window_cells > sopt.max_cells:
        line = int(store.scans.lines[cur_scans[0]])
        raise InputError(
            f"the search window ±{wxy:.4g} m around the guess of the scan of line {line} "
            f"against the scan of line {int(store.scans.lines[ref_scans[0]])} needs "
            f"{max(cells, window_cells):.3g} grid cells (limit {sopt.max_cells}); expected "
            "poses whose motion between the two scans is a plausible drive (the window "
            "grows with the travel between them)",
            path=store.scans.path,
            line=line,
        )
    if empty:  # no match (and no grid cell to index: a far centre overflows the cast)
        _refuse_hopeless(store, ref_scans[0], cur_scans[0], centre, reach)
        nan3 = np.full(3, np.nan)
        return SearchResult(np.asarray(centre, float).copy(), 0.0, nan3, 0.0, 0, False)
    whole_lo = ref_min - 4 * sopt.sigma
    whole_hi = np.maximum(ref_max + 4 * sopt.sigma, whole_lo + sopt.resolution)
    if ref_key is None or grid_cells(whole_lo, whole_hi, sopt.resolution) > sopt.max_cells:
        grid = likelihood_grid(ref, lo, hi, sopt)
    else:  # a named reference: one grid over all of it, kept for every search against it
        grid = store.grid(ref_key, ref, whole_lo, whole_hi)
    return branch_and_bound(grid, cur, centre, wxy, wth, sopt)


def _submap_search(
    store: _Scans,
    chain: Chain,
    pair: tuple[int, int],
    at: tuple[int, int],
    travel: float,
    reach: float,
) -> SearchResult:
    """Branch and bound of the submap around ``at[1]`` against the one around ``at[0]``
    (chain scans within ``reach`` of travel), window from the travel between them."""
    gopt = store.gopt
    (i, j), (a, b) = pair, at
    centre = between(chain.poses[a], chain.poses[b])
    ref_pts = _submap_points(store, chain, a, reach)
    cur_pts = _thinned(_submap_points(store, chain, b, reach), gopt.max_points)
    wxy = gopt.window_xy + gopt.drift_xy * travel
    wth = gopt.window_theta + gopt.drift_theta * travel
    return _search(
        store, [i], [j], centre, centre, wxy, wth, ref_pts, cur_pts, ("submap", a, reach)
    )


def _submap_pair(
    store: _Scans, chain: Chain, at: tuple[int, int]
) -> tuple[PreparedScan, PreparedScan]:
    """The two sides of :func:`_submap_icp`: the lines of ``at[0]``'s submap and the returns
    of ``at[1]``'s (thinned to ``refine_points``), moved by the chain."""
    a, b = at
    members = _submap(store, chain, a)
    rel = between(chain.poses[a], chain.poses[members])
    preps = [store.prep(int(chain.nodes[m])) for m in members]
    anchors = np.concatenate([transform(rel[q], p.anchors) for q, p in enumerate(preps)])
    normals = np.concatenate(
        [transform(np.array([0.0, 0.0, rel[q, 2]]), p.normals) for q, p in enumerate(preps)]
    )
    ref = PreparedScan(np.zeros((0, 2)), anchors, normals)
    cur = _thinned(
        _submap_points(store, chain, b, store.gopt.submap_travel), store.gopt.refine_points
    )
    return ref, PreparedScan(cur, cur[:0], cur[:0])


def _submap_choice(start: NDArray[np.float64], got: Alignment, limits: Any) -> NDArray[np.float64]:
    """:func:`_submap_icp`'s answer from its ICP ``got``: ``start`` when it failed, is
    degenerate itself, or moved farther than the limits from it."""
    move = between(start, got.delta)
    if (
        got.failed
        or got.degenerate
        or np.hypot(move[0], move[1]) > limits.max_correction
        or abs(move[2]) > limits.max_correction_angle
    ):
        return start
    return got.delta


def _submap_icp(
    store: _Scans, chain: Chain, at: tuple[int, int], start: NDArray[np.float64], limits: Any
) -> NDArray[np.float64]:
    """Submap-to-submap ICP from the search's answer ``start``: the returns of ``at[1]``'s
    submap (thinned to ``refine_points``) against the lines of ``at[0]``'s, moved by the
    chain. Finer than the search's grid along a corridor, whose doors and niches the two
    scans alone may not see. ``start`` when it fails, is degenerate itself, or moves farther
    than ``limits.max_correction`` / ``max_correction_angle`` from it."""
    ref, cur = _submap_pair(store, chain, at)
    return _submap_choice(start, align(ref, cur, start, store.opt.icp), limits)


def _refine_limits(store: _Scans) -> Any:
    """The limits of a distant pair's refinement (``max_refine``, ``max_refine_angle``)."""
    from dataclasses import replace

    gopt = store.gopt
    return replace(
        store.opt.limits,
        max_correction=gopt.max_refine,
        max_correction_angle=gopt.max_refine_angle,
    )


def _ambiguous(s: SearchResult, gopt: GlobalOptions) -> bool:
    """A second hypothesis scores at least ``ambiguity`` of the best (or the window held
    too many near-equal ones)."""
    return bool(s.truncated or s.ratio >= gopt.ambiguity)


def _doubtful(s: SearchResult, gopt: GlobalOptions) -> bool:
    """Ambiguous or below ``min_score``: worth a second search with larger submaps."""
    return _ambiguous(s, gopt) or s.score < gopt.min_score


def _distant_search(
    store: _Scans, chain: Chain, pair: tuple[int, int], at: tuple[int, int], travel: float
) -> SearchResult:
    """Search the submaps of a distant pair (module docstring, 3), again with larger submaps
    when the first search is doubtful."""
    gopt = store.gopt
    s = _submap_search(store, chain, pair, at, travel, gopt.submap_travel)
    if gopt.retry_travel > gopt.submap_travel and _doubtful(s, gopt):
        s = _submap_search(store, chain, pair, at, travel, gopt.retry_travel)
    return s


def _distant_judge(
    store: _Scans,
    chain: Chain,
    at: tuple[int, int],
    s: SearchResult,
    al: Alignment,
    refined: NDArray[np.float64] | None = None,
) -> tuple[Alignment, str, list[str], float]:
    """Judge a distant pair's ICP ``al`` from the search's answer ``s`` (module docstring, 3);
    a degenerate one keeps its weak direction from the submaps' ICP (``refined``: its answer,
    already made; None: made here)."""
    gopt = store.gopt
    limits = _refine_limits(store)
    if al.degenerate and not al.failed:
        if refined is None:
            refined = _submap_icp(store, chain, at, s.delta, limits)
        al = pinned(al, refined, gopt.search.resolution)
    flags, susp = _judge(_resolved(al), limits, s.delta)
    flags = ["unstable" if f == "large correction" else f for f in flags]
    extra = []
    if _ambiguous(s, gopt):
        extra.append("ambiguous")
    if s.score < gopt.min_score:
        extra.append("low score")
    if extra:
        flags = flags + extra
        susp = max(susp, s.ratio / gopt.ambiguity, gopt.min_score / max(s.score, 1e-9), 1 + 1e-9)
    return (al, "search", flags, susp)


def align_scans_global(
    scans: LaserScans,
    proposals: Proposals,
    poses: NDArray[np.float64],
    options: AlignOptions | None = None,
    global_options: GlobalOptions | None = None,
) -> tuple[ScanRelations, Chain]:
    """Align every proposed pair without leaning on the given poses beyond the chain's links
    (module docstring); ``poses`` ``(N, 3)`` are the scans' given laser poses."""
    from dataclasses import replace

    from slamrel.scans.relations import collect_relations

    opt = options or AlignOptions()
    gopt = global_options or GlobalOptions()
    if not gopt.weak_geometry:
        opt = replace(opt, limits=replace(opt.limits, min_condition=0.0))
    icp = replace(
        opt.icp,
        tolerance=gopt.icp_tolerance,
        stall_tolerance=gopt.icp_stall_tolerance,
        stall_iterations=gopt.icp_stall_iterations,
        coarse_stride=gopt.icp_coarse_stride,
        shrink_after=gopt.icp_shrink_after,
        nearest=gopt.icp_nearest,
        raster_reach=gopt.icp_raster_reach,
    )
    store = _Scans(scans, replace(opt, icp=icp), gopt)
    # the chain's links keep the caller's ICP (exact nearest anchors, full gate and returns,
    # stricter stop): one slipped link moves every later chain pose, and with it the loop
    # pairs' windows (mit-csail.clf: 15 failed relations with it, 27-116 without)
    store.link_icp = icp if gopt.fast_links else opt.icp
    opt = store.opt
    pairs = proposals.pairs
    chain = scan_chain(scans, poses, pairs.ravel(), store)
    pos = {int(n): k for k, n in enumerate(chain.nodes.tolist())}
    given = between(poses[pairs[:, 0]], poses[pairs[:, 1]])
    p = len(proposals)
    score, ratio = np.full(p, np.nan), np.zeros(p)
    second = np.full((p, 3), np.nan)
    # searches first (in the pairs' order: a scan's pairs come together and share its grid),
    # then the ICP of every pair at once (align_many), then the judgement
    at = np.array([[pos[i], pos[j]] for i, j in pairs.tolist()], dtype=np.int64).reshape(-1, 2)
    travel = np.abs(chain.travel[at[:, 1]] - chain.travel[at[:, 0]]) if p else np.zeros(0)
    searches: dict[int, SearchResult] = {}
    start = np.zeros((p, 3))
    icp_rows: list[int] = []
    for k, (i, j) in enumerate(pairs.tolist()):
        a, b = int(at[k, 0]), int(at[k, 1])
        if travel[k] > gopt.local_travel:
            s = searches[k] = _distant_search(store, chain, (i, j), (a, b), float(travel[k]))
            score[k], ratio[k], second[k] = s.score, s.ratio, s.second
            start[k] = s.delta
            icp_rows.append(k)
        elif b != a + 1:
            start[k] = between(chain.poses[a], chain.poses[b])
            icp_rows.append(k)
    rows = np.array(icp_rows, dtype=np.int64)
    got = align_many(
        [store.prep(int(pairs[k, 0])) for k in icp_rows],
        [store.prep(int(pairs[k, 1])) for k in icp_rows],
        start[rows],
        opt.icp,
    )
    fitted = dict(zip(icp_rows, got, strict=True))
    # the submap ICP of the degenerate distant pairs, all at once
    weak = [k for k in searches if fitted[k].degenerate and not fitted[k].failed]
    sides = [_submap_pair(store, chain, (int(at[k, 0]), int(at[k, 1]))) for k in weak]
    starts = np.array([searches[k].delta for k in weak]).reshape(-1, 3)
    limits = _refine_limits(store)
    refined = {
        k: _submap_choice(starts[q], g, limits)
        for q, (k, g) in enumerate(
            zip(
                weak,
                align_many([r for r, _ in sides], [c for _, c in sides], starts, opt.icp),
                strict=True,
            )
        )
    }
    out: list[tuple[Alignment, str, list[str], float]] = []
    for k in range(p):
        a, b = int(at[k, 0]), int(at[k, 1])
        tr = float(travel[k])
        if k in searches:
            out.append(_distant_judge(store, chain, (a, b), searches[k], fitted[k], refined.get(k)))
            continue
        if b == a + 1:
            al = chain.links[a]
        else:
            al = pinned(fitted[k], start[k], gopt.drift_xy * tr)
        # a correction within the window a chain link searches is the given motion's error
        # (real odometry turns 3-10° wrong between scans), not a slipped alignment
        local = replace(
            opt.limits,
            max_correction=max(opt.limits.max_correction, gopt.link_xy + gopt.drift_xy * tr),
            max_correction_angle=max(
                opt.limits.max_correction_angle, gopt.link_theta + gopt.drift_theta * tr
            ),
        )
        flags, susp = _judge(_resolved(al), local, given[k])
        out.append((al, "chain", flags, susp))
    result = collect_relations(
        proposals, given, out, score=score, second=second, second_ratio=ratio
    )
    return result, chain
