"""Point-to-line ICP of many scan pairs at once: :func:`align_many`.

The same iteration as :func:`slamrel.scans.matching.align` (every rule of it: the coarse
phase and its polish, the trimmed and Cauchy-weighted Gauss–Newton step, the adaptive gate,
the stop at a small or stalled step, the periodic iterates' mean), run in lock step over
all pairs: each iteration stacks the returns of every pair still running, looks their
nearest anchors up in one pass (``"grid"`` and ``"raster"``; ``"tree"`` pair by pair),
trims and weighs them per pair (a per-pair sort of ``|e|`` on a padded array), sums the
normal equations per pair (``np.bincount``) and solves the 3x3 systems as one stack. A pair
leaves the stack when it converges or fails. Per pair the answer is :func:`align`'s but for
the rounding of the sums (a different summation order: the last digits of ``delta``); the
quality measures at the solution are :func:`align`'s own (``_summarise``).

Why: one ICP iteration of a 361-beam scan is ~60 numpy calls on arrays of a few hundred
elements, so :func:`align` spends most of its time in call overhead; stacked, the calls are
made once per iteration for all pairs.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple, cast

import numpy as np
from numpy.typing import NDArray

from relation_metric.se2 import wrap_angle_float
from slamrel.scans.matching import (
    _CAUCHY,
    _GRID_SIDE,
    _MAD,
    _NONE,
    _RASTER_SIDE,
    Alignment,
    IcpOptions,
    NearestGrid,
    NearestRaster,
    PreparedScan,
    _failed,
    align,
)

__all__ = ["align_many"]


#: Pairs :func:`align_many` stacks at most (the rest in further batches): the per-iteration
#: overhead is shared by this many, and the stacked arrays stay near 100 MB for 361 beams.
_BATCH = 512


class _Lookup:
    """The nearest anchors of many references at once (``"grid"`` or ``"raster"``)."""

    def __init__(self, refs: Sequence[PreparedScan], opt: IcpOptions) -> None:
        self.mode = opt.nearest
        if self.mode == "grid":
            self.tabs: list[NearestGrid | NearestRaster] = [r.grid for r in refs]
            side = _GRID_SIDE
        else:
            reach = min(opt.raster_reach, opt.max_distance)
            self.tabs = [r.raster(opt.raster_cell, reach) for r in refs]
            side = _RASTER_SIDE
        self.side = np.arange(-side, side + 1)[None, :]
        n = np.array([r.anchors.shape[0] for r in refs], dtype=np.int64)
        self.n = n
        self.off = np.concatenate(([0], np.cumsum(n)[:-1])).astype(np.int64)
        anchors = np.concatenate([r.anchors for r in refs]) if refs else np.zeros((0, 2))
        self.ax, self.ay = anchors[:, 0].copy(), anchors[:, 1].copy()
        # padded stack: each reference's anchors with side copies of its first and last on
        # either side, so that a window around any anchor stays in its block (the copies
        # stand for NearestGrid.match's clip: the same coordinates, distances and choice)
        self.poff = self.off + 2 * side * np.arange(n.size) + side  # where anchor 0 sits
        pads = [
            np.concatenate((np.repeat(b, side), b + np.arange(c), np.repeat(b + c - 1, side)))
            for b, c in zip(self.off.tolist(), n.tolist(), strict=True)
        ]
        self.real = np.concatenate(pads) if pads else np.zeros(0, dtype=np.int64)
        self.px, self.py = self.ax.take(self.real), self.ay.take(self.real)
        self.lo = np.array([t.lo for t in self.tabs]).reshape(-1, 2)
        self.shape = np.array([t.shape for t in self.tabs], dtype=np.int64).reshape(-1, 2)
        self.cell = float(self.tabs[0].cell) if refs else 1.0
        if any(t.cell != self.cell for t in self.tabs):
            raise ValueError("the references' lookups differ in cell size")

    def match(
        self,
        links: NDArray[np.int64],
        seg: NDArray[np.int64],
        bounds: NDArray[np.int64],
        q0: NDArray[np.float64],
        q1: NDArray[np.float64],
        gate: NDArray[np.float64],
    ) -> tuple[NDArray[np.bool_], NDArray[np.int64]]:
        """Whether each query has its anchor within its link's gate, and the anchor's index in
        the stacked anchors. ``seg`` numbers the queries' links within ``links`` (sorted,
        contiguous); ``bounds`` the segments' starts and the end; ``gate`` per link."""
        lo, shape = self.lo[links], self.shape[links]
        inv = 1.0 / self.cell
        floor = 0.0 if self.mode == "grid" else -1.0
        cx = np.maximum((q0 - lo[seg, 0]) * inv, floor)
        cy = np.maximum((q1 - lo[seg, 1]) * inv, floor)
        lin = np.minimum(cx, shape[seg, 0] - 1.0, out=cx).astype(np.int64) * shape[seg, 1]
        lin += np.minimum(cy, shape[seg, 1] - 1.0, out=cy).astype(np.int64)
        b = bounds.tolist()
        first = np.empty(lin.shape[0], dtype=np.int64)
        n_a = self.n[links]
        if self.mode == "grid":
            s2 = np.empty(lin.shape[0])
            for i, ln in enumerate(links.tolist()):
                g = self.tabs[ln]
                sl = slice(b[i], b[i + 1])
                if g.cells is None:  # type: ignore[union-attr]
                    g.table.take(lin[sl], mode="clip", out=first[sl])  # type: ignore[union-attr]
                    g.s2.take(lin[sl], mode="clip", out=s2[sl])  # type: ignore[union-attr]
                else:  # a sparse table (NearestGrid.match)
                    cells = g.cells  # type: ignore[union-attr]
                    at = np.searchsorted(cells, lin[sl]).clip(0, cells.shape[0] - 1)
                    got = g.table.take(at)  # type: ignore[union-attr]
                    got[cells.take(at) != lin[sl]] = _NONE
                    first[sl] = got
                    s2[sl] = g.s2.take(at)  # type: ignore[union-attr]
            found = first != _NONE
            first &= 0xFFFFFFFF
        else:
            for i, ln in enumerate(links.tolist()):
                sl = slice(b[i], b[i + 1])
                self.tabs[ln].index.take(lin[sl], mode="clip", out=first[sl])  # type: ignore[union-attr]
            found = first >= 0
        # the window of 2 side + 1 anchors around the cell's, in the padded stack
        np.minimum(first, np.maximum(n_a - 1, 0)[seg], out=first)
        np.maximum(first, 0, out=first)
        first += self.poff[links][seg]
        cand = first[:, None] + self.side
        d2 = self.px.take(cand)
        d2 -= q0[:, None]
        d2 *= d2
        dy = self.py.take(cand)
        dy -= q1[:, None]
        dy *= dy
        d2 += dy
        j = d2.argmin(axis=1)
        best2 = np.take_along_axis(d2, j[:, None], axis=1)[:, 0]
        k = self.real.take(cand[:, 0] + j)
        g_pt = gate[seg]
        if self.mode != "grid":
            return found & (np.sqrt(best2) <= g_pt), k
        g0 = self.tabs[0]
        h, lim = g0.h, g0.lim  # type: ignore[union-attr]
        bound = np.sqrt(s2) - h
        sure = np.where(
            found, (np.minimum(best2, g_pt * g_pt) <= bound * bound) & (bound > 0), g_pt <= lim - h
        )
        unsure = np.flatnonzero(~sure)
        if unsure.size:  # NearestGrid._sweep, reference by reference
            useg = seg[unsure]
            cut = np.flatnonzero(np.diff(useg)) + 1
            for part in np.split(unsure, cut):
                i = int(seg[part[0]])
                ln = int(links[i])
                qq = np.column_stack((q0[part], q1[part]))
                bb, kk = self.tabs[ln]._sweep(qq, float(gate[i]))  # type: ignore[union-attr]
                best2[part] = bb
                k[part] = kk + self.off[ln]
        return best2 < g_pt * g_pt, k


def align_many(
    references: Sequence[PreparedScan],
    currents: Sequence[PreparedScan],
    guesses: NDArray[np.float64],
    options: IcpOptions | None = None,
) -> list[Alignment]:
    """``[align(references[b], currents[b], guesses[b], options) for b ...]``, all at once
    (module docstring): the same iteration, the same stops and flags; ``delta`` may differ
    from :func:`align`'s in its last digits (the sums' rounding)."""
    opt = options or IcpOptions()
    nb = len(references)
    guesses = np.asarray(guesses, dtype=np.float64).reshape(nb, 3)
    if opt.nearest not in ("grid", "raster"):
        return [align(r, c, g, opt) for r, c, g in zip(references, currents, guesses, strict=True)]
    out: list[Alignment | None] = [None] * nb
    kk = np.array([c.points.shape[0] for c in currents], dtype=np.int64)
    ll = np.array([r.anchors.shape[0] for r in references], dtype=np.int64)
    bad = (kk < opt.min_matches) | (ll < opt.min_matches)
    for b in np.flatnonzero(bad).tolist():
        out[b] = _failed(guesses[b], "too few returns or lines")
    ids = np.flatnonzero(~bad)
    for start in range(0, ids.size, _BATCH):  # bounded memory: ~100 MB of arrays a batch
        part = ids[start : start + _BATCH]
        refs = [references[b] for b in part.tolist()]
        curs = [currents[b] for b in part.tolist()]
        got = _run(refs, curs, guesses[part], opt)
        for b, a in zip(part.tolist(), got, strict=True):
            out[b] = a
    return [a for a in out if a is not None]


class _Stacked(NamedTuple):
    """A batch's scans stacked. The references': ``look`` (their anchors ``look.ax,
    look.ay``, ``(L,)``) and the anchors' normals ``nx, ny`` ``(L,)``. The currents': the
    points ``px, py`` ``(P,)``, per pair (``(n,)``) their number ``size`` and the first's
    index ``poff``."""

    look: _Lookup
    nx: NDArray[np.float64]
    ny: NDArray[np.float64]
    px: NDArray[np.float64]
    py: NDArray[np.float64]
    size: NDArray[np.int64]
    poff: NDArray[np.int64]

    @classmethod
    def of(cls, refs: list[PreparedScan], curs: list[PreparedScan], opt: IcpOptions) -> _Stacked:
        """The stack of ``refs`` and ``curs`` (pair ``b``: ``refs[b]`` and ``curs[b]``)."""
        look = _Lookup(refs, opt)
        normals = np.concatenate([r.normals for r in refs])
        pts = np.concatenate([c.points for c in curs])
        size = np.array([c.points.shape[0] for c in curs], dtype=np.int64)
        poff = np.concatenate(([0], np.cumsum(size)[:-1])).astype(np.int64)
        nx, ny = normals[:, 0].copy(), normals[:, 1].copy()
        return cls(look, nx, ny, pts[:, 0].copy(), pts[:, 1].copy(), size, poff)


@dataclass
class _State:
    """Per pair (``n`` of them) what the iteration carries from one step to the next; the
    arrays are updated in place. ``T`` is ``max_iterations``."""

    #: ``(n, 3)`` the estimates
    x: NDArray[np.float64]
    #: ``(n, T + 1, 3)`` the iterates (row 0: the guess), filled up to the pair's last
    hist: NDArray[np.float64]
    #: ``(n,)`` the matching gate and the robust scale of the last step
    gate: NDArray[np.float64]
    sigma: NDArray[np.float64]
    #: ``(n,)`` the points' stride (> 1: the coarse phase), the count of stalled steps, the
    #: polish steps left (-1: not polishing) and the iterations made
    stride: NDArray[np.int64]
    stalled: NDArray[np.int64]
    polish: NDArray[np.int64]
    iters: NDArray[np.int64]
    #: ``(n,)`` converged; still iterating
    converged: NDArray[np.bool_]
    active: NDArray[np.bool_]
    #: the pairs that lost their matches, with the iteration at which they did
    failed: dict[int, int]

    @classmethod
    def start(cls, guess: NDArray[np.float64], size: NDArray[np.int64], opt: IcpOptions) -> _State:
        """The state before the first step: ``guess`` ``(n, 3)``; ``size`` ``(n,)`` the
        currents' points (enough of them: a coarse phase first)."""
        n = guess.shape[0]
        stride = np.ones(n, dtype=np.int64)
        if opt.coarse_stride > 1:
            stride[size >= opt.coarse_stride * 4 * opt.min_matches] = opt.coarse_stride
        x = guess.copy()
        hist = np.empty((n, opt.max_iterations + 1, 3))
        hist[:, 0] = x
        return cls(
            x=x,
            hist=hist,
            gate=np.full(n, float(opt.max_distance)),
            sigma=np.full(n, float(opt.min_sigma)),
            stride=stride,
            stalled=np.zeros(n, dtype=np.int64),
            polish=np.full(n, -1, dtype=np.int64),
            iters=np.zeros(n, dtype=np.int64),
            converged=np.zeros(n, dtype=bool),
            active=np.ones(n, dtype=bool),
            failed={},
        )


class _Matched(NamedTuple):
    """One step's matches of the pairs ``links`` ``(A,)`` it runs on. Per query ``(Q,)``: its
    link's number in ``links`` ``seg``, its point moved by the estimate ``q0, q1``, whether
    its anchor is within the gate ``ok`` and the anchor ``k`` (in the stacked anchors). Per
    link ``(A,)``: the estimate ``xl`` ``(A, 3)``, the matches ``m`` (float counts) and
    whether it is in its coarse phase ``coarse``."""

    links: NDArray[np.int64]
    seg: NDArray[np.int64]
    q0: NDArray[np.float64]
    q1: NDArray[np.float64]
    ok: NDArray[np.bool_]
    k: NDArray[np.int64]
    xl: NDArray[np.float64]
    m: NDArray[np.float64]
    coarse: NDArray[np.bool_]


class _Residuals(NamedTuple):
    """Matched queries ``(M,)``: their link's number ``sg``, the point-to-line residual
    ``e``, the anchor's normal ``n0, n1`` and the moved point ``qa0, qa1``."""

    sg: NDArray[np.int64]
    e: NDArray[np.float64]
    n0: NDArray[np.float64]
    n1: NDArray[np.float64]
    qa0: NDArray[np.float64]
    qa1: NDArray[np.float64]

    def take(self, at: NDArray[np.int64]) -> _Residuals:
        """The rows ``at`` ``(M',)``."""
        return _Residuals(
            self.sg[at], self.e[at], self.n0[at], self.n1[at], self.qa0[at], self.qa1[at]
        )


def _run(
    refs: list[PreparedScan],
    curs: list[PreparedScan],
    guess: NDArray[np.float64],
    opt: IcpOptions,
) -> list[Alignment]:
    """``align`` of pairs ``(refs[b], curs[b])`` from ``guess[b]`` (``guess`` ``(n, 3)``)
    in lock step: each step runs on the pairs still active."""
    data = _Stacked.of(refs, curs, opt)
    state = _State.start(guess, data.size, opt)
    for it in range(1, opt.max_iterations + 1):
        links = np.flatnonzero(state.active)
        if not links.size:
            break
        mt = _drop_lost(state, _match(data, state, links, opt), it, opt.min_matches)
        if not mt.links.size:
            continue
        res = _residuals(data, mt.seg, (mt.q0, mt.q1), mt.ok, mt.k)
        sel, sig = _trimmed_scale(res, mt.m, opt)
        state.sigma[mt.links] = sig
        res = res.take(np.flatnonzero(sel))
        step = _solve(*_normal_equations(res, mt.xl, sig, mt.links.size))
        _advance(state, mt, step, sig, it, opt)
    return _results(data, state, guess, opt)


def _moved(
    data: _Stacked, x: NDArray[np.float64], links: NDArray[np.int64], st: NDArray[np.int64]
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
    """Every ``st[a]``-th point ``(A,)`` of the current of pair ``links[a]`` ``(A,)``, moved
    by its estimate ``x[links[a]]`` (``x`` ``(n, 3)``): per query ``(Q,)`` its link's number
    ``seg`` and its point ``q0, q1``, and ``bounds`` ``(A + 1,)`` where each link's queries
    start and the end; as ``(seg, bounds, q0, q1)``."""
    cnt = -(-data.size[links] // st)
    bounds = np.concatenate(([0], np.cumsum(cnt)))
    seg = np.repeat(np.arange(links.size), cnt)
    pos = np.arange(bounds[-1]) - bounds[:-1][seg]
    idx = data.poff[links][seg] + pos * st[seg]
    xl = x[links]
    c, s = np.cos(xl[:, 2]), np.sin(xl[:, 2])
    p0, p1 = data.px[idx], data.py[idx]
    cs, ss = c[seg], s[seg]
    q0 = cs * p0 - ss * p1 + xl[seg, 0]
    q1 = ss * p0 + cs * p1 + xl[seg, 1]
    return seg, bounds, q0, q1


def _match(data: _Stacked, state: _State, links: NDArray[np.int64], opt: IcpOptions) -> _Matched:
    """The matches of the pairs ``links`` ``(A,)`` at their estimates, every stride-th point.
    A pair in its coarse phase with fewer than ``2 min_matches`` matches goes on with all its
    points (stride 1, no polish) and is matched again: at most twice."""
    mm = opt.min_matches
    while True:
        st = state.stride[links]
        seg, bounds, q0, q1 = _moved(data, state.x, links, st)
        ok, k = data.look.match(links, seg, bounds, q0, q1, state.gate[links])
        m = cast("NDArray[np.float64]", np.bincount(seg, weights=ok, minlength=links.size))
        coarse = st > 1
        switch = coarse & (m < 2 * mm)
        if not switch.any():
            return _Matched(links, seg, q0, q1, ok, k, state.x[links], m, coarse)
        state.stride[links[switch]] = 1
        state.polish[links[switch]] = -1


def _drop_lost(state: _State, mt: _Matched, it: int, mm: int) -> _Matched:
    """``mt`` without the links of fewer than ``mm`` matches: these pairs fail at step
    ``it`` (``state.failed``) and leave; their queries are no longer ``ok``."""
    lost = mt.m < mm
    if not lost.any():
        return mt
    links = mt.links
    for b in links[lost].tolist():
        state.failed[b] = it
    state.active[links[lost]] = False
    keep_link = ~lost
    ok = mt.ok
    ok &= keep_link[mt.seg]
    relabel = np.cumsum(keep_link) - 1
    return mt._replace(
        links=links[keep_link],
        m=mt.m[keep_link],
        coarse=mt.coarse[keep_link],
        xl=mt.xl[keep_link],
        seg=relabel[mt.seg],
        ok=ok,
    )


def _residuals(
    data: _Stacked,
    seg: NDArray[np.int64],
    q: tuple[NDArray[np.float64], NDArray[np.float64]],
    ok: NDArray[np.bool_],
    k: NDArray[np.int64],
) -> _Residuals:
    """The queries ``(Q,)`` (link's number ``seg``, point ``q``) that are ``ok``, with the
    point-to-line residuals to their anchors ``k``."""
    at = np.flatnonzero(ok)
    ka = k[at]
    qa0, qa1 = q[0][at], q[1][at]
    n0, n1 = data.nx[ka], data.ny[ka]
    e = n0 * (qa0 - data.look.ax[ka]) + n1 * (qa1 - data.look.ay[ka])
    return _Residuals(seg[at], e, n0, n1, qa0, qa1)


def _trimmed_scale(
    res: _Residuals, m: NDArray[np.float64], opt: IcpOptions
) -> tuple[NDArray[np.bool_], NDArray[np.float64]]:
    """Per link ``(A,)`` (``m`` its matches) the largest ``1 - trim`` share of ``|e|``
    dropped (``max(min_matches, ceil(trim m))`` kept): which residuals are kept ``(M,)``,
    and the robust scale of the kept, ``max(MAD · median |e|, min_sigma)`` ``(A,)``."""
    sg = res.sg
    ae = np.abs(res.e)
    nl = m.size
    mi = m.astype(np.int64)
    keep = np.maximum(opt.min_matches, np.ceil(opt.trim * mi).astype(np.int64))
    mb = np.concatenate(([0], np.cumsum(mi)))
    width = int(mi.max())
    pad = np.full((nl, width), np.inf)
    pad[sg, np.arange(sg.size) - mb[:-1][sg]] = ae
    pad.sort(axis=1)
    rows = np.arange(nl)
    cut = np.where(keep < mi, pad[rows, np.minimum(keep, mi) - 1], np.inf)
    sel = ae <= cut[sg]
    kept = np.bincount(sg, weights=sel, minlength=nl).astype(np.int64)
    half = kept // 2
    odd = kept % 2 == 1
    med = np.where(
        odd, pad[rows, half], 0.5 * (pad[rows, np.maximum(half - 1, 0)] + pad[rows, half])
    )
    return sel, np.maximum(_MAD * med, opt.min_sigma)


def _normal_equations(
    res: _Residuals, xl: NDArray[np.float64], sig: NDArray[np.float64], nl: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The Cauchy-weighted Gauss–Newton normal equations of the ``nl`` links (estimates
    ``xl`` ``(nl, 3)``, scales ``sig`` ``(nl,)``) from the kept residuals ``res``: ``H``
    ``(nl, 3, 3)`` and ``g`` ``(nl, 3, 1)``."""
    sg, e, n0, n1, qa0, qa1 = res
    r = e / (_CAUCHY * sig)[sg]
    w = 1.0 / (1.0 + r * r)
    j2 = n1 * (qa0 - xl[sg, 0]) - n0 * (qa1 - xl[sg, 1])
    w0, w1, w2 = w * n0, w * n1, w * j2
    hm = np.empty((nl, 3, 3))
    gv = np.empty((nl, 3, 1))
    for a, wa in enumerate((w0, w1, w2)):
        for bcol, jb in enumerate((n0, n1, j2)):
            if bcol < a:
                hm[:, a, bcol] = hm[:, bcol, a]
                continue
            hm[:, a, bcol] = np.bincount(sg, weights=wa * jb, minlength=nl)
        gv[:, a, 0] = np.bincount(sg, weights=wa * e, minlength=nl)
    return hm, gv


def _solve(hm: NDArray[np.float64], gv: NDArray[np.float64]) -> NDArray[np.float64]:
    """The steps ``-H⁻¹ g`` ``(nl, 3)`` of :func:`_normal_equations`' systems, as one stack;
    if one is singular, system by system (least squares for the singular ones)."""
    try:
        return cast("NDArray[np.float64]", -np.linalg.solve(hm, gv)[:, :, 0])
    except np.linalg.LinAlgError:
        step = np.empty((hm.shape[0], 3))
        for a in range(hm.shape[0]):
            try:
                step[a] = -np.linalg.solve(hm[a], gv[a, :, 0])
            except np.linalg.LinAlgError:
                step[a] = -np.linalg.lstsq(hm[a], gv[a, :, 0], rcond=None)[0]
        return step


def _advance(
    state: _State,
    mt: _Matched,
    step: NDArray[np.float64],
    sig: NDArray[np.float64],
    it: int,
    opt: IcpOptions,
) -> None:
    """Step ``it`` taken by the links of ``mt`` (``step`` ``(A, 3)``, scales ``sig``
    ``(A,)``): the estimates moved; then the stops (a small or stalled step at a settled
    gate, or a cycle: its iterates' mean), the polish after a coarse phase, and the gate."""
    links = mt.links
    xl = mt.xl + step
    state.x[links] = xl
    state.hist[links, it] = xl
    g_old = state.gate[links]
    new_gate = np.minimum(opt.max_distance, np.maximum(opt.min_distance, opt.gate_sigmas * sig))
    sz = np.maximum(np.hypot(step[:, 0], step[:, 1]), np.abs(step[:, 2]))
    small = sz < opt.tolerance
    stl = np.where(sz < opt.stall_tolerance, state.stalled[links] + 1, 0)
    state.stalled[links] = stl
    settled = new_gate >= g_old * 0.999
    done = (small | (stl >= opt.stall_iterations)) & settled
    _stop_cycles(state, links, done, settled, it, opt.tolerance)
    to_polish = done & mt.coarse
    if to_polish.any():
        state.stride[links[to_polish]] = 1
        state.polish[links[to_polish]] = opt.polish_iterations
    rest = ~to_polish
    pl = state.polish[links]
    pl[rest] -= 1
    state.polish[links] = pl
    fin = rest & (done | (pl == 0))
    if fin.any():
        state.converged[links[fin]] = True
        state.active[links[fin]] = False
        state.iters[links[fin]] = it
    upd = rest & ~fin
    shrink = upd & (small | (it > opt.shrink_after))
    state.gate[links[shrink]] = np.minimum(g_old[shrink], new_gate[shrink])


def _stop_cycles(
    state: _State,
    links: NDArray[np.int64],
    done: NDArray[np.bool_],
    settled: NDArray[np.bool_],
    it: int,
    tol: float,
) -> None:
    """The links ``(A,)`` not ``done`` at a ``settled`` gate whose iterates cycle
    (:func:`_periods`) are ``done`` (in place), at the mean of their last period."""
    check = np.flatnonzero(~done & settled)
    if check.size:
        period = _periods(state.hist[links[check], : it + 1], tol)
        for a, p in zip(check[period > 0].tolist(), period[period > 0].tolist(), strict=True):
            b = int(links[a])
            state.x[b] = np.mean(state.hist[b, it + 1 - p : it + 1], axis=0)
            done[a] = True


def _results(
    data: _Stacked, state: _State, guess: NDArray[np.float64], opt: IcpOptions
) -> list[Alignment]:
    """The :class:`Alignment` of each pair ``(n,)`` after the last step (``guess``
    ``(n, 3)``): failed, or its estimate with :func:`_summaries`' measures."""
    n = guess.shape[0]
    failed, x, iters = state.failed, state.x, state.iters
    iters[state.active] = opt.max_iterations
    done_ok = np.array([b not in failed for b in range(n)], dtype=bool)
    summary = _summaries(data, x, state.gate, state.sigma, np.flatnonzero(done_ok), opt)
    res = []
    for b in range(n):
        if b in failed:
            res.append(_failed(guess[b], "too few matches", failed[b]))
            continue
        got = summary[b]
        if got is None:
            res.append(_failed(guess[b], "too few matches", int(iters[b])))
            continue
        cov, frac, resid, n_in, cond, weak = got
        out = x[b].copy()
        out[2] = wrap_angle_float(float(out[2]))
        res.append(
            Alignment(
                delta=out,
                guess=guess[b].copy(),
                covariance=cov,
                matched_fraction=frac,
                residual=resid,
                sigma=float(state.sigma[b]),
                matches=n_in,
                iterations=int(iters[b]),
                converged=bool(state.converged[b]),
                condition=cond,
                weak_direction=weak,
                degenerate=cond < opt.degenerate_ratio,
            )
        )
    return res


def _summaries(
    data: _Stacked,
    x: NDArray[np.float64],
    gate: NDArray[np.float64],
    sigma: NDArray[np.float64],
    links: NDArray[np.int64],
    opt: IcpOptions,
) -> dict[int, tuple[NDArray[np.float64], float, float, int, float, NDArray[np.float64]] | None]:
    """:func:`slamrel.scans.matching._summarise`'s measures at the solutions ``x`` of
    ``links``, all at once: covariance, matched fraction, residual, matches, condition and
    weak direction per link (None: fewer than ``min_matches`` inliers)."""
    out: dict[int, tuple[NDArray[np.float64], float, float, int, float, NDArray[np.float64]] | None]
    out = {}
    if not links.size:
        return out
    cnt = data.size[links]
    seg, bounds, q0, q1 = _moved(data, x, links, np.ones(links.size, dtype=np.int64))
    ok, k = data.look.match(links, seg, bounds, q0, q1, gate[links])
    sg, e, n0, n1, qa0, qa1 = _residuals(data, seg, (q0, q1), ok, k)
    xl = x[links]
    sig = sigma[links]
    keep = np.abs(e) <= 3.0 * sig[sg]
    e, n0, n1, qa0, qa1, sg = e[keep], n0[keep], n1[keep], qa0[keep], qa1[keep], sg[keep]
    nl = links.size
    m = np.bincount(sg, minlength=nl)
    r = e / (_CAUCHY * sig)[sg]
    w = 1.0 / (1.0 + r * r)
    j2 = n1 * (qa0 - xl[sg, 0]) - n0 * (qa1 - xl[sg, 1])
    hm = np.empty((nl, 3, 3))
    cols = (n0, n1, j2)
    for a in range(3):
        for b in range(a, 3):
            hm[:, a, b] = hm[:, b, a] = np.bincount(sg, weights=w * cols[a] * cols[b], minlength=nl)
    wsum = np.bincount(sg, weights=w, minlength=nl)
    s2 = np.bincount(sg, weights=w * e * e, minlength=nl) / np.maximum(wsum - 3.0, 1.0)
    ee = np.bincount(sg, weights=e * e, minlength=nl)
    good = m >= opt.min_matches
    with np.errstate(invalid="ignore", divide="ignore"):
        resid = np.sqrt(ee / np.maximum(m, 1))
        h22 = hm[:, 2, 2]
        pos = h22 > 0
        den = np.where(pos, h22, 1.0)
        schur = hm[:, :2, :2] - np.where(
            pos[:, None, None], hm[:, :2, 2, None] * hm[:, None, 2, :2] / den[:, None, None], 0.0
        )
    lam, vec = np.linalg.eigh(schur)
    for a, b in enumerate(links.tolist()):
        if not good[a]:
            out[b] = None
            continue
        try:
            cov = s2[a] * np.linalg.inv(hm[a])
        except np.linalg.LinAlgError:
            cov = np.full((3, 3), np.inf)
        cond = float(lam[a, 0] / lam[a, 1]) if lam[a, 1] > 0 else 0.0
        out[b] = (
            cov,
            int(m[a]) / max(int(cnt[a]), 1),
            float(resid[a]),
            int(m[a]),
            cond,
            vec[a, :, 0].copy(),
        )
    return out


def _periods(hist: NDArray[np.float64], tol: float, longest: int = 4) -> NDArray[np.int64]:
    """Per row of ``hist`` ``(A, T, 3)`` (the iterates so far), the least period ``p ≤
    longest`` with ``x_k = x_{k−p}`` to ``tol`` over the last ``p`` iterates, or 0
    (:func:`slamrel.scans.matching._cycle`)."""
    a, t = hist.shape[0], hist.shape[1]
    out = np.zeros(a, dtype=np.int64)
    for p in range(2, longest + 1):
        if t <= 2 * p:
            break
        close = np.ones(a, dtype=bool)
        for q in range(p):
            d = np.abs(hist[:, t - 1 - q] - hist[:, t - 1 - q - p])
            close &= (d < tol).all(axis=1)
        out[(out == 0) & close] = p
    return out
