"""The scan-relation review page: two scans overlaid after each proposed relation, in the map.

The second half of Burgard, Kümmerle et al.'s recipe for reference relations: the machine
aligns (:mod:`slamrel.scans.relations`), a person confirms or corrects. The page (one
self-contained file, no server, the machinery and style of :mod:`slamrel.review.page`)
shows, for the relation selected, the reference scan (blue) and the current scan moved by
the relation (orange) in the reference scan's frame, over the **map**: every scan drawn from
the estimate's poses, decimated to one point per occupied cell of a grid (5 cm, coarsened
until at most ``map_cells`` cells remain), so that a relation 1.5 m off along a corridor
shows as an orange scan off the map's doorways and as the gap between its pose and the
estimate's (grey). When the data carries a **second hypothesis** per relation (the aligner's
ambiguity test), it is drawn (purple) and ``h`` moves the scan there; the page also plots the
**cost along the weak direction** (the trimmed point-to-line cost of the current scan
shifted ±2 m along it, computed in the page).

Keyboard first: ``n``/``p`` visit unreviewed relations in decreasing suspicion, ``a``
accepts, ``r`` rejects, the arrow keys nudge (1 cm, Shift 10 cm), ``q``/``e`` and the wheel
rotate (0.1°, Shift 1°), dragging translates, ``i`` re-aligns **within a window** around the
hand placement (a correlative search over ±``window_xy`` and ±``window_theta``, then the
point-to-line ICP of :func:`slamrel.scans.matching.align`, in JavaScript, held inside the
window: it cannot fall back into another corridor optimum), ``I`` re-aligns without a
window, ``0`` restores the proposed relation, ``u`` undoes, ``s`` saves.

Save gives two texts (shown in the page and offered as downloads): the Freiburg
``.relations`` file (``t1 t2 x y z roll pitch yaw``) of the **accepted** relations only (and
the unreviewed ones too when "include unreviewed" is ticked), headed by ``#`` comment lines
with the counts of accepted, rejected and unreviewed relations, and the review state
(``slamrel-scan-review/2`` JSON: status and relation per row; the page also loads
``slamrel-scan-review/1`` states, whose ``proposed`` is ``unreviewed``).
"""

from __future__ import annotations

import base64
from typing import Any

import numpy as np
from numpy.typing import NDArray

from relation_metric.se2 import between
from slamrel.formats.laser import LaserScans
from slamrel.formats.text import PathLike, write_text_atomic
from slamrel.review.page import fill_page
from slamrel.scans.matching import prepare_scan
from slamrel.scans.relations import AlignOptions, ScanRelations

__all__ = [
    "scan_review_payload",
    "scan_review_html",
    "write_scan_review",
    "map_cells",
    "SCAN_REVIEW_FORMAT",
]

SCAN_REVIEW_FORMAT = "slamrel-scan-review/2"

#: The re-align window of the page: ±10 cm, ±1° around the hand placement.
WINDOW_XY, WINDOW_THETA = 0.10, float(np.radians(1.0))


def _mm(a: NDArray[np.float64], digits: int = 3) -> list[float]:
    return [float(v) for v in np.round(np.asarray(a, dtype=np.float64).ravel(), digits)]


def _fin(v: NDArray[np.float64], digits: int = 6) -> list[float | None]:
    v = np.asarray(v, dtype=np.float64).ravel()
    return [None if not np.isfinite(x) else float(x) for x in np.round(v, digits).tolist()]


def map_cells(
    scans: LaserScans,
    poses: NDArray[np.float64],
    *,
    min_range: float = 0.0,
    max_range: float | None = None,
    resolution: float = 0.05,
    max_cells: int = 100_000,
    chunk: int = 1024,
) -> tuple[float, NDArray[np.int64]]:
    """The map the page draws: every return of every scan placed by ``poses`` ``(N, 3)``.

    A return ``r`` at beam angle ``a`` of scan ``k`` lands at ``poses[k] ⊕ (r cos a, r sin a)``
    and occupies grid cell ``floor(xy / resolution)``. Returns the resolution used and the
    occupied cells ``(C, 2)`` (sorted, each once); the resolution doubles until ``C ≤
    max_cells`` and the map spans fewer than 65,536 cells each way (the page stores a cell
    in two bytes). Scans whose pose is not finite are left out. Vectorised per ``chunk``
    scans.
    """
    if resolution <= 0 or max_cells < 1:
        raise ValueError("resolution must be > 0 and max_cells >= 1")
    poses = np.asarray(poses, dtype=np.float64)
    beams = np.arange(scans.ranges.shape[1])
    parts: list[NDArray[np.float64]] = []
    for lo in range(0, len(scans), chunk):
        k = np.arange(lo, min(lo + chunk, len(scans)))
        k = k[np.isfinite(poses[k]).all(axis=1)]
        r = scans.ranges[k]
        top = scans.max_range[k] if max_range is None else np.minimum(scans.max_range[k], max_range)
        low = np.full(k.size, min_range)
        if scans.min_range is not None:
            low = np.maximum(low, scans.min_range[k])
        ang = scans.start_angle[k, None] + beams[None, :] * scans.angular_resolution[k, None]
        with np.errstate(invalid="ignore"):
            ok = (r > low[:, None]) & (r < top[:, None]) & (beams[None, :] < scans.beams[k, None])
        pz = poses[k][np.nonzero(ok)[0]]
        th = pz[:, 2] + ang[ok]
        parts.append(pz[:, :2] + r[ok][:, None] * np.column_stack((np.cos(th), np.sin(th))))
    xy = np.concatenate(parts) if parts else np.zeros((0, 2))
    res = resolution
    while True:
        cells = np.floor(xy / res).astype(np.int64)
        if not cells.size:
            return res, cells
        lo_c = cells.min(axis=0)
        span = cells.max(axis=0) - lo_c + 1
        key = np.unique((cells[:, 0] - lo_c[0]) * span[1] + (cells[:, 1] - lo_c[1]))
        if key.size <= max_cells and span.max() < 65536:
            return res, np.column_stack((key // span[1] + lo_c[0], key % span[1] + lo_c[1]))
        res *= 2


def _map_payload(res: float, cells: NDArray[np.int64]) -> dict[str, Any]:
    """The cells as base64 of little-endian ``uint16`` pairs relative to ``origin``."""
    origin = cells.min(axis=0) if cells.size else np.zeros(2, np.int64)
    packed = (cells - origin).astype("<u2").tobytes()
    return {
        "resolution": res,
        "origin": [int(v) for v in origin],
        "count": int(cells.shape[0]),
        "cells": base64.b64encode(packed).decode("ascii"),
    }


def _second(second: NDArray[np.float64] | None, p: int) -> dict[str, list[float | None]]:
    """The optional second hypotheses ``(P, 3)`` or ``(P, 4)`` (``x, y, θ`` and the score
    ratio); NaN rows: none."""
    if second is None:
        return {}
    s = np.asarray(second, dtype=np.float64)
    if s.ndim != 2 or s.shape[0] != p or s.shape[1] not in (3, 4):
        raise ValueError(f"second hypotheses must be ({p}, 3) or ({p}, 4), got {s.shape}")
    ratio = s[:, 3] if s.shape[1] == 4 else np.full(p, np.nan)
    return {"second": _fin(s[:, :3], 6), "secondRatio": _fin(ratio, 4)}


def scan_review_payload(
    scans: LaserScans,
    result: ScanRelations,
    poses: NDArray[np.float64],
    options: AlignOptions | None = None,
    *,
    name: str = "",
    second: NDArray[np.float64] | None = None,
    max_map_cells: int = 100_000,
) -> dict[str, Any]:
    """The JSON the page embeds: each used scan once (returns and fitted lines, mm), the
    relations with their quality measures (and, optionally, ``second`` hypotheses ``(P, 3)``
    or ``(P, 4)``: ``x, y, θ`` and the second/best score ratio, NaN rows where none), the
    estimate's poses, its relation for each pair, the decimated map (:func:`map_cells`) and
    the trajectory for the inset."""
    opt = options or AlignOptions()
    used = np.unique(result.proposals.pairs)
    index = {int(k): n for n, k in enumerate(used.tolist())}
    scan_list = []
    for k in used.tolist():
        prep = prepare_scan(scans.points(k, min_range=opt.min_range, max_range=opt.max_range))
        scan_list.append(
            {
                "p": _mm(prep.points),
                "c": _mm(prep.anchors),
                "n": _mm(prep.normals, 4),
            }
        )
    pr = result.proposals
    icp = opt.icp
    res, cells = map_cells(
        scans, poses, min_range=opt.min_range, max_range=opt.max_range, max_cells=max_map_cells
    )
    track = poses[np.isfinite(poses).all(axis=1)][:, :2]
    track = track[:: max(1, int(np.ceil(track.shape[0] / 3000)))]
    return {
        "format": SCAN_REVIEW_FORMAT,
        "name": name,
        "icp": {
            "maxDistance": icp.max_distance,
            "minDistance": icp.min_distance,
            "gateSigmas": icp.gate_sigmas,
            "trim": icp.trim,
            "minSigma": icp.min_sigma,
            "maxIterations": icp.max_iterations,
            "tolerance": icp.tolerance,
            "minMatches": icp.min_matches,
            "stallTolerance": icp.stall_tolerance,
            "stallIterations": icp.stall_iterations,
        },
        "window": {"xy": WINDOW_XY, "theta": WINDOW_THETA},
        "scans": scan_list,
        "poses": _mm(poses[used], 4),
        "map": _map_payload(res, cells),
        "track": _mm(track, 2),
        "relations": {
            "t1": [float(t) for t in pr.t1],
            "t2": [float(t) for t in pr.t2],
            "i": [index[int(k)] for k in pr.pairs[:, 0]],
            "j": [index[int(k)] for k in pr.pairs[:, 1]],
            "delta": _mm(result.delta, 6),
            "guess": _mm(result.guess, 6),
            "estimate": _fin(between(poses[pr.pairs[:, 0]], poses[pr.pairs[:, 1]]), 6),
            "weak": _fin(result.weak_direction, 4),
            "matched": _fin(result.matched_fraction, 4),
            "residual": _fin(result.residual, 5),
            "condition": _fin(result.condition, 4),
            "flags": [str(f) for f in result.flags],
            "suspicion": _fin(np.minimum(result.suspicion, 1e9), 4),
            **_second(second, len(pr)),
        },
    }


def scan_review_html(
    payload: dict[str, Any], *, title: str = "slamrel scan relation review"
) -> str:
    """The self-contained page (HTML, inline script and style, no network)."""
    return fill_page(
        "scan_review.html",
        title=title,
        styles=("review_page.css", "scan_review.css"),
        script="scan_review.js",
        payload=payload,
    )


def write_scan_review(
    path: PathLike,
    scans: LaserScans,
    result: ScanRelations,
    poses: NDArray[np.float64],
    options: AlignOptions | None = None,
    *,
    name: str = "",
    second: NDArray[np.float64] | None = None,
) -> None:
    """Write the review page of ``result`` to ``path`` atomically (``second``: see
    :func:`scan_review_payload`)."""
    payload = scan_review_payload(scans, result, poses, options, name=name, second=second)
    write_text_atomic(path, scan_review_html(payload))
