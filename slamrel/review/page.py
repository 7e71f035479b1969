"""What the association review page shows, and the page itself (one self-contained HTML file).

A person checks the association between an estimated and a reference landmark map the way
Burgard et al. check ground-truth relations: the machine proposes, the person accepts,
rejects or corrects. :func:`review_data` computes, vectorised, everything the page needs:

* the estimate moved into the reference frame by the alignment the association implies,
  the frame rule of :mod:`landmark_graph.map_compare` whatever the association's source:
  the least-squares rigid transform of the matched pairs (Umeyama 1991; a translation for
  one pair, the identity for none) — the frame ``map-compare`` scores the maps in;
* per proposed pair its **residual** ``d = ‖R e + t − r‖`` [m] and its **margin**
  ``d₂ − d`` [m], ``d₂`` the distance to the second-best candidate: the nearest *other*
  reference landmark to the moved estimate or the nearest *other* moved estimate to the
  reference landmark, whichever is closer. A margin near zero (or negative) means another
  landmark would fit as well: the pair is ambiguous;
* a **suspicion** ``max(d / c, d / d₂)`` (``c`` the cut-off): the page visits pairs in
  decreasing suspicion (a large residual, or a second candidate nearly as close);
* the unmatched landmarks on both sides (missed reference, spurious estimate).

:func:`review_html` renders the page: the data as JSON inside the HTML, the hand-written
script ``review_page.js`` and style ``review_page.css`` of this package inline, no network.
Its Save writes the association CSV that
:func:`~slamrel.formats.associations.read_association_csv` reads (``slamrel map-compare
--associate FILE``), with a ``# unreviewed:`` comment line that lets the page resume a review.
"""

from __future__ import annotations

import html
import json
import re
from dataclasses import dataclass
from importlib import resources
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from landmark_graph.landmark_association import Association
from landmark_graph.map_compare import fit_map_alignment
from landmark_graph.maps import LandmarkMap
from relation_metric.alignment import Alignment
from slamrel.formats.text import PathLike, write_text_atomic

__all__ = ["ReviewData", "review_data", "review_html", "write_review", "implied_alignment"]

#: Format tag of the JSON embedded in the page.
REVIEW_FORMAT = "slamrel-review/1"


@dataclass(frozen=True)
class ReviewData:
    """Everything the review page shows (K proposed pairs, M estimated, N reference landmarks).

    Attributes
    ----------
    estimate_ids : ndarray of int, shape (M,)
    estimate_xy : ndarray, shape (M, 2)
        Estimated landmarks moved into the reference frame by ``alignment``.
    reference_ids : ndarray of int, shape (N,)
    reference_xy : ndarray, shape (N, 2)
    estimate_rows, reference_rows : ndarray of int, shape (K,)
        The proposed pairs (rows of the two maps).
    residual : ndarray, shape (K,)
        Distance [m] of each pair after the alignment.
    margin : ndarray, shape (K,)
        ``d₂ − d`` [m]: how much farther the second-best candidate is (``inf`` when there is
        none).
    suspicion : ndarray, shape (K,)
        ``max(d / c, d / d₂)``; pairs are visited in decreasing suspicion.
    missed, spurious : ndarray of int
        Reference rows and estimate rows without a pair.
    alignment : Alignment
        Takes the estimate onto the reference.
    alignment_source : str
        How ``alignment`` was obtained (shown on the page).
    cutoff : float
        The association cut-off ``c`` [m]; residual colours saturate at ``c``.
    """

    estimate_ids: NDArray[np.int64]
    estimate_xy: NDArray[np.float64]
    reference_ids: NDArray[np.int64]
    reference_xy: NDArray[np.float64]
    estimate_rows: NDArray[np.int64]
    reference_rows: NDArray[np.int64]
    residual: NDArray[np.float64]
    margin: NDArray[np.float64]
    suspicion: NDArray[np.float64]
    missed: NDArray[np.int64]
    spurious: NDArray[np.int64]
    alignment: Alignment
    alignment_source: str
    cutoff: float

    def as_dict(self) -> dict[str, Any]:
        """The JSON embedded in the page (``inf`` margins become ``null``)."""
        a = self.alignment

        def num(v: NDArray[np.float64]) -> list[float | None]:
            r = np.round(v, 6)
            return [None if not np.isfinite(x) else x for x in r.tolist()]

        return {
            "format": REVIEW_FORMAT,
            "cutoff": float(self.cutoff),
            "alignment": {
                "angle": float(a.angle),
                "translation": [float(a.translation[0]), float(a.translation[1])],
                "source": self.alignment_source,
            },
            "estimate": {
                "ids": self.estimate_ids.tolist(),
                "x": num(self.estimate_xy[:, 0]),
                "y": num(self.estimate_xy[:, 1]),
            },
            "reference": {
                "ids": self.reference_ids.tolist(),
                "x": num(self.reference_xy[:, 0]),
                "y": num(self.reference_xy[:, 1]),
            },
            "pairs": {
                "estimate": self.estimate_rows.tolist(),
                "reference": self.reference_rows.tolist(),
                "residual": num(self.residual),
                "margin": num(self.margin),
                "suspicion": num(self.suspicion),
            },
        }


def implied_alignment(
    est: LandmarkMap, ref: LandmarkMap, assoc: Association
) -> tuple[Alignment, str]:
    """The rigid alignment an association implies, and a phrase saying where it came from.

    The frame rule of :mod:`landmark_graph.map_compare` (:func:`~landmark_graph.map_compare.
    fit_map_alignment` on the pairs), whatever the association's source: the page shows the
    maps in the frame ``map-compare`` scores them in.
    """
    fit = fit_map_alignment(est.xy[assoc.estimate_rows], ref.xy[assoc.reference_rows])
    k = fit.pairs
    if k >= 2:
        return fit.alignment, f"least-squares rigid fit of the {k} pairs"
    if k == 1:
        return fit.alignment, "translation of the one pair"
    return fit.alignment, "none (no pairs): the frames as given"


def _nearest_other(
    tree: cKDTree, points: NDArray[np.float64], exclude: NDArray[np.int64]
) -> NDArray[np.float64]:
    """Distance from each point to its nearest tree point other than row ``exclude``."""
    k = min(2, tree.n)
    d, i = tree.query(points, k)
    d, i = d.reshape(len(points), k), i.reshape(len(points), k)
    first_is_self = i[:, 0] == exclude
    if k == 1:
        return np.where(first_is_self, np.inf, d[:, 0])
    return np.where(first_is_self, d[:, 1], d[:, 0])


def review_data(
    est: LandmarkMap, ref: LandmarkMap, assoc: Association, *, cutoff: float = 1.0
) -> ReviewData:
    """Align, and score every proposed pair (see the module docstring).

    Parameters
    ----------
    est, ref : LandmarkMap
        M estimated and N reference landmarks.
    assoc : Association
        The proposed pairs (by id, automatic or from a file).
    cutoff : float
        ``c`` [m] of the suspicion and of the colour scale.

    Returns
    -------
    ReviewData
    """
    al, source = implied_alignment(est, ref, assoc)
    moved = al.apply(np.column_stack((est.xy, np.zeros(len(est)))))[:, :2]
    er, rr = assoc.estimate_rows, assoc.reference_rows
    residual = np.hypot(*(moved[er] - ref.xy[rr]).T)
    if er.size:
        d2 = np.minimum(
            _nearest_other(cKDTree(ref.xy), moved[er], rr),
            _nearest_other(cKDTree(moved), ref.xy[rr], er),
        )
    else:
        d2 = np.empty(0)
    margin = d2 - residual
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(d2 > 0, residual / np.where(d2 > 0, d2, 1.0), np.inf)
    ratio = np.where(residual == 0, 0.0, ratio)
    suspicion = np.maximum(residual / cutoff, ratio)
    return ReviewData(
        estimate_ids=est.ids,
        estimate_xy=moved,
        reference_ids=ref.ids,
        reference_xy=ref.xy,
        estimate_rows=er,
        reference_rows=rr,
        residual=residual,
        margin=margin,
        suspicion=suspicion,
        missed=assoc.missed,
        spurious=assoc.spurious,
        alignment=al,
        alignment_source=source,
        cutoff=float(cutoff),
    )


def _asset(name: str) -> str:
    return resources.files("slamrel.review").joinpath(name).read_text(encoding="utf-8")


def fill_page(
    template: str, *, title: str, styles: tuple[str, ...], script: str, payload: Any
) -> str:
    """A self-contained page from this package's ``template`` with its assets inline.

    ``/*{{TITLE}}*/``, ``/*{{STYLE}}*/``, ``/*{{DATA}}*/`` and ``/*{{SCRIPT}}*/`` are filled
    in one pass (nothing substituted is substituted again); ``payload`` becomes JSON with
    no ``<`` (so that ``</script`` or ``<!--`` cannot change how HTML parses it).
    """
    blob = json.dumps(payload, allow_nan=False, separators=(",", ":")).replace("<", "\\u003c")
    parts = {
        "TITLE": html.escape(title),
        "STYLE": "\n".join(_asset(name) for name in styles),
        "DATA": blob,
        "SCRIPT": _asset(script),
    }
    return re.sub(r"/\*\{\{(\w+)\}\}\*/", lambda m: parts[m.group(1)], _asset(template))


def review_html(
    data: ReviewData,
    *,
    title: str = "slamrel association review",
    names: tuple[str, str] = ("", ""),
) -> str:
    """The self-contained review page (HTML, inline script and style, no network).

    ``names`` are the estimate's and the reference's file names, shown on the page and
    written into the saved CSV's comment lines.
    """
    payload = data.as_dict()
    payload["names"] = {"estimate": names[0], "reference": names[1]}
    return fill_page(
        "review_page.html",
        title=title,
        styles=("review_page.css",),
        script="review_page.js",
        payload=payload,
    )


def write_review(
    path: PathLike,
    est: LandmarkMap,
    ref: LandmarkMap,
    assoc: Association,
    *,
    cutoff: float = 1.0,
    names: tuple[str, str] = ("", ""),
    title: str = "slamrel association review",
) -> ReviewData:
    """Compute the review of ``assoc`` and write its page to ``path`` atomically."""
    data = review_data(est, ref, assoc, cutoff=cutoff)
    write_text_atomic(path, review_html(data, title=title, names=names))
    return data
