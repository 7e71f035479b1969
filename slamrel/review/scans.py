"""The scan-relation review page: two scans overlaid after each proposed relation.

The second half of Burgard, Kümmerle et al.'s recipe for reference relations: the machine
aligns (:mod:`slamrel.scans.relations`), a person confirms or corrects. The page (one
self-contained file, no server, the machinery and style of :mod:`slamrel.review.page`)
shows, for the relation selected, the reference scan (blue) and the current scan moved by
the relation (orange) in the reference scan's frame, and an inset with the estimate's
trajectory and the two poses. Keyboard first: ``n``/``p`` visit relations in decreasing
suspicion, ``a`` accepts, ``r`` rejects, the arrow keys nudge (1 cm, Shift 10 cm), ``q``/``e``
and the wheel rotate (0.1°, Shift 1°), dragging translates, ``i`` re-aligns from the nudged
relation (the same point-to-line ICP as :func:`slamrel.scans.matching.align`, in JavaScript,
on the lines fitted here), ``0`` restores the proposed relation, ``u`` undoes, ``s`` saves.

Save gives two texts (shown in the page and offered as downloads): the Freiburg
``.relations`` file of every relation not rejected (``t1 t2 x y z roll pitch yaw``, the
corrected relation where one was nudged or re-aligned) and the review state
(``slamrel-scan-review/1`` JSON: status and relation per row) that the page loads back.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from slamrel.formats.laser import LaserScans
from slamrel.formats.text import PathLike, write_text_atomic
from slamrel.review.page import fill_page
from slamrel.scans.matching import prepare_scan
from slamrel.scans.relations import AlignOptions, ScanRelations

__all__ = ["scan_review_payload", "scan_review_html", "write_scan_review", "SCAN_REVIEW_FORMAT"]

SCAN_REVIEW_FORMAT = "slamrel-scan-review/1"


def _mm(a: NDArray[np.float64], digits: int = 3) -> list[float]:
    return [float(v) for v in np.round(np.asarray(a, dtype=np.float64).ravel(), digits)]


def scan_review_payload(
    scans: LaserScans,
    result: ScanRelations,
    poses: NDArray[np.float64],
    options: AlignOptions | None = None,
    *,
    name: str = "",
) -> dict[str, Any]:
    """The JSON the page embeds: each used scan once (returns and fitted lines, mm), the
    relations with their quality measures, and the estimate's poses for the inset."""
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

    def fin(v: NDArray[np.float64], digits: int = 6) -> list[float | None]:
        return [None if not np.isfinite(x) else float(x) for x in np.round(v, digits).tolist()]

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
        "scans": scan_list,
        "poses": _mm(poses[used], 4),
        "relations": {
            "t1": [float(t) for t in pr.t1],
            "t2": [float(t) for t in pr.t2],
            "i": [index[int(k)] for k in pr.pairs[:, 0]],
            "j": [index[int(k)] for k in pr.pairs[:, 1]],
            "delta": _mm(result.delta, 6),
            "guess": _mm(result.guess, 6),
            "matched": fin(result.matched_fraction, 4),
            "residual": fin(result.residual, 5),
            "condition": fin(result.condition, 4),
            "flags": [str(f) for f in result.flags],
            "suspicion": fin(np.minimum(result.suspicion, 1e9), 4),
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
) -> None:
    """Write the review page of ``result`` to ``path`` atomically."""
    payload = scan_review_payload(scans, result, poses, options, name=name)
    write_text_atomic(path, scan_review_html(payload))
