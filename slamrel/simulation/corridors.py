"""Seeded corridor worlds for laser reference relations: ring and cross corridors, rooms.

:func:`corridor_world` draws a building from its seed: a rectangular **ring** of corridors
(outer size ``W × H``, ``W ∈ [24, 40]`` m, ``H ∈ [16, 28]`` m, width ``w ∈ [1.8, 2.6]`` m),
one or two **cross corridors** joining opposite sides of the ring, **rooms** (3–6 m) off the
corridors behind a 0.2 m wall with a 0.9 m doorway, **door niches** (0.9 m wide, 0.15–0.3 m
deep) along the corridor walls and a few **pillars** in the rooms. The free space is drawn on
a 0.1 m grid and the walls are the boundary between free and occupied cells, merged into
maximal axis-aligned segments ``(S, 4)`` ``[x1, y1, x2, y2]`` (so any layout the rectangles
make is a valid closed world for :func:`slamrel.simulation.laser.ray_cast`).

:func:`corridor_log` drives a robot through it: a random walk over the corridor graph (ring
corners and the cross corridors' junctions, never turning straight back) until ``length``
metres, waypoints jittered ±0.25 m off the centre line, ``step`` [m] a scan (0.1 m, 0.2 s:
0.5 m/s), turns on the spot in 0.1 rad steps. Scans: 361-beam SICK, 1 cm range noise
(:class:`~slamrel.simulation.laser.LaserSensor`); odometry: the true increments with
``N(0, σ²)`` noise per step (:func:`~slamrel.simulation.laser.simulate_laser_log`).

:func:`true_pairs` gives the pairs the acceptance is measured at: consecutive keyframes
(1 m or 0.5 rad of true motion apart) and loop pairs (keyframes within ``radius`` of each
other, headings within ``max_angle``, more than ``min_gap`` seconds apart), at most
``max_loops`` of them drawn by the seed. Pure functions of their arguments.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from relation_metric import se2
from slamrel.simulation.laser import LaserSensor, SimulatedLog, simulate_laser_log

__all__ = ["CorridorWorld", "corridor_world", "corridor_log", "true_pairs", "grid_walls"]

_CELL = 0.1


class CorridorWorld(NamedTuple):
    """A drawn building.

    Attributes
    ----------
    walls : (S, 4) float
        Wall segments ``[x1, y1, x2, y2]`` [m].
    nodes : (K, 2) float
        Corridor graph nodes (centre line) [m].
    edges : (E, 2) int
        Node pairs joined by a straight corridor.
    free : (X, Y) bool
        The free-space grid (cell 0.1 m, origin at ``(0, 0)``).
    """

    walls: NDArray[np.float64]
    nodes: NDArray[np.float64]
    edges: NDArray[np.int64]
    free: NDArray[np.bool_]


def _runs(mask: NDArray[np.bool_]) -> list[tuple[int, int, int]]:
    """Maximal runs of True along axis 1 of ``mask`` ``(A, B)``: ``(a, b_start, b_end)``."""
    pad = np.zeros((mask.shape[0], 1), dtype=np.int8)
    d = np.diff(np.concatenate((pad, mask.astype(np.int8), pad), axis=1), axis=1)
    starts, ends = np.nonzero(d == 1), np.nonzero(d == -1)
    return list(zip(starts[0].tolist(), starts[1].tolist(), ends[1].tolist(), strict=True))


def grid_walls(free: NDArray[np.bool_], cell: float = _CELL) -> NDArray[np.float64]:
    """Boundary of the free cells of ``free`` ``(X, Y)`` as merged segments ``(S, 4)``.

    Cell ``(i, j)`` covers ``[i c, (i+1) c] × [j c, (j+1) c]``; the grid's border counts as
    occupied. A vertical wall lies at ``x = (i+1) c`` where cells ``i`` and ``i+1`` of a
    column differ; runs of such edges along ``y`` become one segment (and alike for
    horizontal walls).
    """
    f = np.pad(free, 1, constant_values=False)
    vert = f[1:, 1:-1] != f[:-1, 1:-1]  # (X+1, Y): wall at x = i c between rows i-1 and i
    horiz = f[1:-1, 1:] != f[1:-1, :-1]  # (X, Y+1): wall at y = j c
    out = [[i * cell, a * cell, i * cell, b * cell] for i, a, b in _runs(vert)]
    out += [[a * cell, j * cell, b * cell, j * cell] for j, a, b in _runs(horiz.T)]
    return np.asarray(out, dtype=np.float64).reshape(-1, 4)


def _cells(v: float) -> int:
    return int(round(v / _CELL))


def _carve(free: NDArray[np.bool_], x0: float, y0: float, x1: float, y1: float) -> None:
    """Mark ``[x0, x1] × [y0, y1]`` free (clipped to the grid)."""
    a, b = sorted((_cells(x0), _cells(x1)))
    c, d = sorted((_cells(y0), _cells(y1)))
    free[max(a, 0) : max(b, 0), max(c, 0) : max(d, 0)] = True


def _layout(
    rng: np.random.Generator,
) -> tuple[float, float, float, list[tuple[float, float, float, float]], list[float], list[float]]:
    """Sizes, the corridor rectangles and the cross corridors' positions of one building."""
    m = 8.0  # margin for rooms outside the ring
    w_out, h_out = rng.uniform(24.0, 40.0), rng.uniform(16.0, 28.0)
    w = rng.uniform(1.8, 2.6)
    x0, y0, x1, y1 = m, m, m + w_out, m + h_out
    rects = [
        (x0, y0, x1, y0 + w),
        (x0, y1 - w, x1, y1),
        (x0, y0, x0 + w, y1),
        (x1 - w, y0, x1, y1),
    ]
    n_cross = int(rng.integers(1, 3))
    vx: list[float] = []
    hy: list[float] = []
    for k in range(n_cross):
        if k == 0 or rng.random() < 0.5:  # a vertical cross corridor, then maybe horizontal
            if k == 0:
                c = float(rng.uniform(x0 + 0.35 * w_out, x0 + 0.65 * w_out))
                rects.append((c - w / 2, y0, c + w / 2, y1))
                vx.append(c)
                continue
        c = float(rng.uniform(y0 + 0.35 * h_out, y0 + 0.65 * h_out))
        rects.append((x0, c - w / 2, x1, c + w / 2))
        hy.append(c)
    return w_out, h_out, w, rects, vx, hy


def _rooms_and_niches(
    rng: np.random.Generator,
    free: NDArray[np.bool_],
    rects: list[tuple[float, float, float, float]],
) -> list[tuple[float, float]]:
    """Carve rooms (with doorways and pillars) and door niches along each corridor's long
    sides; return the pillars' centres (boxes are put back as occupied afterwards)."""
    pillars: list[tuple[float, float]] = []
    for cx0, cy0, cx1, cy1 in rects:
        horizontal = (cx1 - cx0) > (cy1 - cy0)
        length = (cx1 - cx0) if horizontal else (cy1 - cy0)
        pos = rng.uniform(2.0, 6.0)
        while pos < length - 2.5:
            side = int(rng.integers(0, 2))
            kind = rng.random()
            depth = rng.uniform(0.15, 0.3) if kind < 0.6 else rng.uniform(3.0, 6.0)
            width = 0.9 if kind < 0.6 else rng.uniform(3.0, 6.0)
            # the strip beyond the corridor wall, on the chosen side
            if horizontal:
                wy = cy1 if side else cy0
                sgn = 1.0 if side else -1.0
                door = (cx0 + pos, wy, cx0 + pos + 0.9, wy + sgn * (0.2 + 0.01))
                room = (cx0 + pos - 0.5, wy + sgn * 0.2, cx0 + pos - 0.5 + width, wy + sgn * depth)
            else:
                wx = cx1 if side else cx0
                sgn = 1.0 if side else -1.0
                door = (wx, cy0 + pos, wx + sgn * 0.21, cy0 + pos + 0.9)
                room = (wx + sgn * 0.2, cy0 + pos - 0.5, wx + sgn * depth, cy0 + pos - 0.5 + width)
            if kind < 0.6:  # a niche: the door recess itself
                niche = (door[0], door[1], door[2], door[3])
                if horizontal:
                    niche = (door[0], door[1], door[2], door[1] + sgn * depth)
                else:
                    niche = (door[0], door[1], door[0] + sgn * depth, door[3])
                if _clear(free, niche, margin=0.0):
                    _carve(free, *niche)
            elif _clear(free, room, margin=0.1):
                _carve(free, *room)
                _carve(free, *door)
                if rng.random() < 0.7:
                    pillars.append(
                        (
                            float(
                                rng.uniform(min(room[0], room[2]) + 1, max(room[0], room[2]) - 1)
                            ),
                            float(
                                rng.uniform(min(room[1], room[3]) + 1, max(room[1], room[3]) - 1)
                            ),
                        )
                    )
            pos += width + rng.uniform(2.0, 7.0)
    return pillars


def _clear(free: NDArray[np.bool_], rect: tuple[float, float, float, float], margin: float) -> bool:
    """Is ``rect`` (grown by ``margin``) inside the grid and away from free space?"""
    a, b = sorted((_cells(rect[0]), _cells(rect[2])))
    c, d = sorted((_cells(rect[1]), _cells(rect[3])))
    g = _cells(margin)
    a, b, c, d = a - g, b + g, c - g, d + g
    if a < 1 or c < 1 or b >= free.shape[0] - 1 or d >= free.shape[1] - 1:
        return False
    return not free[a:b, c:d].any()


def corridor_world(seed: int) -> CorridorWorld:
    """A building drawn from ``seed`` (see the module docstring)."""
    rng = np.random.default_rng([seed, 37])
    w_out, h_out, w, rects, vx, hy = _layout(rng)
    size = (_cells(w_out + 16.0), _cells(h_out + 16.0))
    free = np.zeros(size, dtype=bool)
    for r in rects:
        _carve(free, *r)
    pillars = _rooms_and_niches(rng, free, rects)
    for px, py in pillars:
        free[_cells(px - 0.2) : _cells(px + 0.2), _cells(py - 0.2) : _cells(py + 0.2)] = False
    x0, y0, x1, y1 = 8.0 + w / 2, 8.0 + w / 2, 8.0 + w_out - w / 2, 8.0 + h_out - w / 2
    xs = sorted([x0, x1, *vx])
    ys = sorted([y0, y1, *hy])
    nodes, edges = _graph(xs, ys, vx, hy, (x0, x1, y0, y1))
    return CorridorWorld(grid_walls(free), nodes, edges, free)


def _graph(
    xs: list[float],
    ys: list[float],
    vx: list[float],
    hy: list[float],
    ring: tuple[float, float, float, float],
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Corridor graph: nodes at the ring's corners and where corridors meet, edges along the
    corridors' centre lines."""
    x0, x1, y0, y1 = ring
    pts: list[tuple[float, float]] = []
    for x in xs:
        for y in ys:
            on_v = x in (x0, x1) or x in vx
            on_h = y in (y0, y1) or y in hy
            if on_v and on_h:
                pts.append((x, y))
    nodes = np.asarray(pts, dtype=np.float64)
    edges = []
    for a in range(len(pts)):
        for b in range(a + 1, len(pts)):
            (ax, ay), (bx, by) = pts[a], pts[b]
            same_x = ax == bx and (ax in (x0, x1) or ax in vx)
            same_y = ay == by and (ay in (y0, y1) or ay in hy)
            if not (same_x or same_y):
                continue
            between_any = any(
                (c != a and c != b)
                and (
                    (same_x and pts[c][0] == ax and min(ay, by) < pts[c][1] < max(ay, by))
                    or (same_y and pts[c][1] == ay and min(ax, bx) < pts[c][0] < max(ax, bx))
                )
                for c in range(len(pts))
            )
            if not between_any:
                edges.append((a, b))
    return nodes, np.asarray(edges, dtype=np.int64).reshape(-1, 2)


def _route(world: CorridorWorld, rng: np.random.Generator, length: float) -> NDArray[np.float64]:
    """Waypoints ``(K, 2)`` of a random walk over the corridor graph, about ``length`` m."""
    adj: dict[int, list[int]] = {}
    for a, b in world.edges.tolist():
        adj.setdefault(a, []).append(b)
        adj.setdefault(b, []).append(a)
    cur = int(rng.integers(0, world.nodes.shape[0]))
    prev = -1
    way = [world.nodes[cur]]
    total = 0.0
    while total < length:
        options = [n for n in adj[cur] if n != prev] or adj[cur]
        nxt = int(options[int(rng.integers(0, len(options)))])
        total += float(np.hypot(*(world.nodes[nxt] - world.nodes[cur])))
        prev, cur = cur, nxt
        way.append(world.nodes[cur])
    pts = np.asarray(way, dtype=np.float64)
    return pts + rng.uniform(-0.25, 0.25, pts.shape)


def _poses_along(way: NDArray[np.float64], step: float, turn_step: float) -> NDArray[np.float64]:
    """Poses ``(N, 3)`` along the polyline ``way``: ``step`` apart on each leg, heading along
    it, turning on the spot at each waypoint in steps of at most ``turn_step``."""
    poses: list[list[float]] = []
    heading = float(np.arctan2(*(way[1] - way[0])[::-1]))
    for k in range(way.shape[0] - 1):
        p, q = way[k], way[k + 1]
        new = float(np.arctan2(q[1] - p[1], q[0] - p[0]))
        turn = se2.wrap_angle_float(new - heading)
        n_turn = int(np.ceil(abs(turn) / turn_step))
        for s in range(n_turn):
            poses.append([p[0], p[1], heading + turn * s / n_turn])
        heading = new
        n = max(int(np.floor(np.hypot(*(q - p)) / step)), 1)
        for s in range(n):
            poses.append([*(p + (q - p) * s / n), heading])
    out = np.asarray(poses, dtype=np.float64)
    out[:, 2] = se2.wrap_angle(out[:, 2])
    return out


def corridor_log(
    seed: int,
    *,
    length: float = 200.0,
    step: float = 0.1,
    dt: float = 0.2,
    odometry_sigma: tuple[float, float, float] = (0.003, 0.0015, 0.002),
    sensor: LaserSensor | None = None,
) -> tuple[CorridorWorld, SimulatedLog]:
    """The world of ``seed`` and a log of a drive through it (see the module docstring)."""
    world = corridor_world(seed)
    rng = np.random.default_rng([seed, 38])
    truth = _poses_along(_route(world, rng, length), step, 0.1)
    log = simulate_laser_log(
        world.walls, truth, sensor=sensor, odometry_sigma=odometry_sigma, dt=dt, seed=seed
    )
    return world, log


def true_pairs(
    truth: NDArray[np.float64],
    times: NDArray[np.float64],
    *,
    seed: int = 0,
    distance: float = 1.0,
    angle: float = 0.5,
    radius: float = 1.5,
    max_angle: float = np.pi / 4,
    min_gap: float = 30.0,
    max_loops: int = 300,
) -> tuple[NDArray[np.int64], NDArray[np.str_]]:
    """Scan index pairs ``(P, 2)`` and their kind (``"consecutive"``/``"loop"``).

    Keyframes: where the true travel ``Σ ‖Δp‖`` crosses a multiple of ``distance`` or the
    turned angle ``Σ |Δθ|`` a multiple of ``angle``.
    """
    from scipy.spatial import cKDTree

    step = se2.between(truth[:-1], truth[1:])
    travel = np.concatenate(([0.0], np.cumsum(np.hypot(step[:, 0], step[:, 1]))))
    turned = np.concatenate(([0.0], np.cumsum(np.abs(step[:, 2]))))
    cell = np.floor(travel / distance) + np.floor(turned / angle)
    key = np.flatnonzero(np.concatenate(([True], np.diff(cell) > 0)))
    cons = np.column_stack((key[:-1], key[1:]))
    near = np.array(sorted(cKDTree(truth[key, :2]).query_pairs(radius)), dtype=np.int64)
    lp = key[near.reshape(-1, 2)]
    dth = np.abs(se2.between(truth[lp[:, 0]], truth[lp[:, 1]])[:, 2])
    lp = lp[(np.abs(times[lp[:, 1]] - times[lp[:, 0]]) > min_gap) & (dth <= max_angle)]
    if lp.shape[0] > max_loops:
        pick = np.sort(np.random.default_rng([seed, 39]).choice(lp.shape[0], max_loops, False))
        lp = lp[pick]
    pairs = np.concatenate((cons, lp)).astype(np.int64)
    kind = np.array(["consecutive"] * cons.shape[0] + ["loop"] * lp.shape[0])
    return pairs, kind
