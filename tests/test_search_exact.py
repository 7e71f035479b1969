"""The fast paths of the search give the values of their plain definitions (issue 37, speed):
the padded block lookups against the clipping :func:`_score`, the blocked kernel splat
against a per-point loop, the cycle test on float triples against its numpy statement, the
grid's kept padded levels against ``np.pad``, and the store's kept grids and submaps
against building every one anew."""

from __future__ import annotations

import numpy as np
import pytest

import slamrel.scans.global_align as global_align
from slamrel.scans.global_align import align_scans_global
from slamrel.scans.matching import _cycle
from slamrel.scans.proposals import Proposals
from slamrel.scans.search import SearchOptions, _Lookup, _score, likelihood_grid
from slamrel.simulation.corridors import corridor_log, true_pairs


def _grid_and_points(seed: int):
    rng = np.random.default_rng(seed)
    ref = rng.uniform([0.0, 0.0], [3.0, 2.0], (80, 2))
    opt = SearchOptions(levels=3)
    grid = likelihood_grid(ref, np.array([0.2, 0.1]), np.array([2.6, 1.8]), opt)
    cur = rng.uniform([-2.0, -2.0], [5.0, 4.0], (40, 2))  # many beyond every edge
    base = np.floor((cur[None] + rng.normal(0, 0.02, (5, 40, 2)) - grid.lo) / 0.05)
    return grid, base.astype(np.int64), rng


@pytest.mark.parametrize("limit", [2**22, 1])  # padded, and the clip fallback
def test_padded_lookups_equal_the_clipping_score(limit):
    """The padded lookups: the clipping score at the leaves (float32 sums), and at every
    level above a valid bound (each point's largest ``L_0`` over the node's cells, brute
    force) no looser than the clip's edge replication (cells whose lookups all miss the
    table read the zero corner)."""
    grid, base, rng = _grid_and_points(1)
    half = 9
    look = _Lookup(grid, base, half, limit)
    assert look.padded == (limit > 1)
    n = 3000  # more rows than one block of 65,536 lookups holds
    k = rng.integers(0, base.shape[0], n)
    u, v = rng.integers(-half, half + 1, (2, n))
    table = grid.pyramid[0]
    nx, ny = table.shape
    for h in range(len(grid.pyramid)):
        got, clip = look.score(h, k, u, v), _score(grid, base, h, k, u, v)
        if h == 0 or not look.padded:  # the leaves' scores (float32 sums when padded)
            np.testing.assert_allclose(got, clip, rtol=1e-6, atol=1e-7)
            continue
        # a bound: at least the mean over the points of the largest L_0 in the 2^h x 2^h
        # cells the node moves each point over (0 outside the table), at most the clip's
        best = np.zeros((n, base.shape[1]))
        for da in range(2**h):
            for db in range(2**h):
                ix = base[k, :, 0] + u[:, None] + da
                iy = base[k, :, 1] + v[:, None] + db
                inside = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny)
                val = np.where(inside, table[ix.clip(0, nx - 1), iy.clip(0, ny - 1)], 0.0)
                best = np.maximum(best, val)
        assert np.all(got >= best.mean(axis=1) - 1e-6)
        assert np.all(got <= clip + 1e-6)
        assert np.mean(got < clip - 1e-6) > 0.01  # far points read 0, not the edge's bound


def test_padded_levels_equal_numpy_edge_pad_of_the_pyramid():
    """The grid's padded levels (built once, kept while later searches fit them) hold
    ``np.pad(L_h, margin, mode="edge")``; a search reaching farther gets new ones."""
    grid, _, _ = _grid_and_points(4)
    nx, ny = grid.table.shape
    want = grid.pyramid
    for first, last, fresh in [
        ((-3, -5), (nx + 2, ny - 1), True),
        ((-1, 0), (nx - 4, ny - 1), False),  # inside the kept margin: the same tables
        ((-30, -2), (nx + 1, ny + 4), True),
    ]:
        before = grid._kept.get("padded")
        got = grid.padded(np.array(first), np.array(last), 2**22)
        assert got is not None
        tables, margin = got
        assert (got is not before) == fresh
        (a0, a1), (b0, b1) = margin
        assert a0 >= -first[0] and b0 >= -first[1]
        assert a1 >= last[0] - (nx - 1) and b1 >= last[1] - (ny - 1)
        for t, level in zip(tables, want, strict=True):
            np.testing.assert_array_equal(t, np.pad(level, margin, mode="edge"))
    assert grid.padded(np.array([-50, 0]), np.array([nx, ny]), 100 * ny) is None  # too large


def test_kernel_splat_equals_a_per_point_loop():
    """``L(c) = max_k exp(−‖c − q_k‖² / 2σ²)`` over the 7 × 7 cells around each point that
    lie inside the grid (its one-cell border and top padding stay zero)."""
    rng = np.random.default_rng(2)
    pts = np.concatenate(
        [rng.uniform([0.0, 0.0], [2.0, 1.5], (2500, 2)), [[-0.1, 0.7], [2.1, 1.6], [0.0, 0.0]]]
    )
    opt = SearchOptions()
    lo, hi = np.array([0.0, 0.0]), np.array([2.0, 1.5])
    table = likelihood_grid(pts, lo, hi, opt).pyramid[0]
    r, sig = opt.resolution, opt.sigma
    nx, ny = int(np.ceil(2.0 / r)) + 2, int(np.ceil(1.5 / r)) + 2
    want = np.zeros_like(table)
    g0 = lo - r
    for p in pts:
        c = np.floor((p - g0) / r).astype(int)
        for a in range(c[0] - 3, c[0] + 4):
            for b in range(c[1] - 3, c[1] + 4):
                if 1 <= a < nx and 1 <= b < ny:
                    d2 = (g0[0] + (a + 0.5) * r - p[0]) ** 2 + (g0[1] + (b + 0.5) * r - p[1]) ** 2
                    want[a, b] = max(want[a, b], np.float32(np.exp(-d2 / (2 * sig * sig))))
    assert np.array_equal(table > 0, want > 0)
    np.testing.assert_allclose(table, want, rtol=1e-6, atol=0)


def test_cycle_on_triples_equals_its_numpy_statement():
    def numpy_cycle(history, tol, longest=4):
        for p in range(2, longest + 1):
            if len(history) > 2 * p and all(
                np.abs(np.subtract(history[-1 - q], history[-1 - q - p])).max() < tol
                for q in range(p)
            ):
                return p
        return 0

    rng = np.random.default_rng(3)
    for trial in range(300):
        period = int(rng.integers(2, 6))
        loop = [tuple(rng.normal(0, 1e-3, 3)) for _ in range(period)]
        noise = 10 ** rng.uniform(-9, -5)
        hist = [tuple(np.add(loop[i % period], rng.normal(0, noise, 3))) for i in range(12)]
        if trial % 10 == 0:
            hist[-1] = (np.nan, 0.0, 0.0)
        assert _cycle(hist, 1e-6) == numpy_cycle(hist, 1e-6)


@pytest.mark.slow
def test_kept_grids_change_no_result(monkeypatch):
    _, log = corridor_log(8, length=120.0)
    s = log.scans
    pairs, kind = true_pairs(log.truth, s.timestamps, seed=8, max_loops=2)
    loops = pairs[kind == "loop"]  # each loop pair twice (the same grid), then a neighbour
    pairs = np.stack([loops, loops, loops + [0, 1]], axis=1).reshape(-1, 2)
    kind = np.full(len(pairs), "loop")
    t = s.timestamps
    prop = Proposals(pairs, t[pairs[:, 0]], t[pairs[:, 1]], kind, np.zeros(len(pairs)))
    built = []
    real = global_align.likelihood_grid

    def counted(*args):
        built.append(1)
        return real(*args)

    monkeypatch.setattr(global_align, "likelihood_grid", counted)
    kept, _ = align_scans_global(s, prop, s.laser_pose)
    n_kept = len(built)
    monkeypatch.setattr(global_align, "_KEEP_GRIDS", 0)
    monkeypatch.setattr(global_align, "_KEEP_SUBMAPS", 0)  # the submaps' returns anew too
    fresh, _ = align_scans_global(s, prop, s.laser_pose)
    assert len(pairs) >= 6 and n_kept <= len(built) - n_kept - len(loops)  # repeats kept
    np.testing.assert_array_equal(kept.delta, fresh.delta)
    np.testing.assert_array_equal(kept.flags, fresh.flags)
    np.testing.assert_array_equal(kept.score, fresh.score)
    np.testing.assert_array_equal(kept.second_ratio, fresh.second_ratio)
