"""Words for what a figure draws, read from the artists themselves (issue 38).

A caption that says "red dots" where the legend shows red circles misleads: the captions of
the run report take their words from the legend's own handles (:func:`legend_words`), so that
they change when the drawing does. :func:`hidden_share` measures how much of one drawn line
lies under another, in display units (points and line widths as drawn), for a caption to say
what the reader cannot see.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["colour_word", "artist_words", "legend_words", "hidden_share"]

#: Named colours a caption may use (matplotlib's tab10 and black/white), by RGB.
_NAMED = {
    "blue": "tab:blue",
    "orange": "tab:orange",
    "green": "tab:green",
    "red": "tab:red",
    "purple": "tab:purple",
    "brown": "tab:brown",
    "pink": "tab:pink",
    "olive": "tab:olive",
    "cyan": "tab:cyan",
}
#: Greys by lightness: below each bound, its word.
_GREYS = ((0.15, "black"), (0.45, "dark grey"), (0.7, "grey"), (0.93, "light grey"))
#: Marker code → plural noun (a caption names many points).
_MARKERS = {
    "o": "circles",
    ".": "dots",
    ",": "dots",
    "+": "crosses",
    "x": "diagonal crosses",
    "s": "squares",
    "^": "triangles",
    "v": "triangles",
    "D": "diamonds",
    "*": "stars",
}
#: Line style → adjective ("" for solid).
_STYLES = {"-": "", "solid": "", "--": "dashed", "dashed": "dashed", ":": "dotted",
           "dotted": "dotted", "-.": "dash-dotted", "dashdot": "dash-dotted"}  # fmt: skip


def colour_word(colour: Any) -> str:
    """A word for a matplotlib colour: a grey by its lightness (``black``, ``dark grey``,
    ``grey``, ``light grey``, ``white``) or the nearest of the tab10 colours."""
    from matplotlib.colors import to_rgb

    rgb = np.asarray(to_rgb(colour))
    if np.ptp(rgb) < 0.06:  # no hue: a grey
        v = float(rgb.mean())
        for bound, word in _GREYS:
            if v < bound:
                return word
        return "white"
    names = list(_NAMED)
    ref = np.array([to_rgb(_NAMED[n]) for n in names])
    return names[int(np.argmin(((ref - rgb) ** 2).sum(axis=1)))]


def artist_words(artist: Any) -> str:
    """What one legend handle (a ``Line2D`` or a patch) looks like, e.g. ``"hollow purple
    circles"``, ``"grey line"``, ``"dashed blue line"``, ``"red shading"``."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    if isinstance(artist, Line2D):
        colour = colour_word(artist.get_color())
        marker = artist.get_marker()
        style = artist.get_linestyle()
        if marker not in (None, "", "None", " ") and str(marker) in _MARKERS:
            face = artist.get_markerfacecolor()
            hollow = isinstance(face, str) and face.lower() == "none"
            return f"{'hollow ' if hollow else ''}{colour} {_MARKERS[str(marker)]}"
        adjective = _STYLES.get(str(style), "")
        return f"{adjective + ' ' if adjective else ''}{colour} line"
    if isinstance(artist, Patch):
        return f"{colour_word(artist.get_facecolor())} shading"
    raise TypeError(f"no words for a {type(artist).__name__} legend handle")


def legend_words(ax: Any) -> dict[str, str]:
    """Legend label → :func:`artist_words` of its handle, for the legend of ``ax``."""
    legend = ax.get_legend()
    if legend is None:
        return {}
    return {
        text.get_text(): artist_words(handle)
        for text, handle in zip(legend.get_texts(), legend.legend_handles, strict=True)
        if handle is not None
    }


def _line_distance(
    points: NDArray[np.float64], line: NDArray[np.float64], block: int = 256
) -> NDArray[np.float64]:
    """Distance of each point to the polyline ``line`` (its segments; one vertex: a point)."""
    a = line[:-1] if len(line) > 1 else line
    d = (line[1:] if len(line) > 1 else line) - a
    dd = np.maximum((d**2).sum(axis=1), 1e-300)
    out = np.empty(len(points))
    for i in range(0, len(points), block):  # blocks bound the (points × segments) arrays
        p = points[i : i + block, None, :] - a[None, :, :]
        s = np.clip((p * d[None]).sum(axis=2) / dd[None], 0.0, 1.0)
        r = p - s[..., None] * d[None]
        out[i : i + block] = np.sqrt((r**2).sum(axis=2)).min(axis=1)
    return out


def hidden_share(under: Any, over: Any) -> float:
    """The share of ``under``'s points (a drawn ``Line2D``) that lie within the drawn width of
    ``over`` (another ``Line2D`` drawn above it), measured in display pixels: a point is
    hidden when its distance to ``over``'s polyline is at most half ``over``'s line width.

    The figure must have been laid out (``fig.canvas.draw()``) so that the axes' transform
    is final; the share does not depend on the dpi (widths and data scale with it alike).
    """
    fig = over.get_figure()
    px = over.get_linewidth() * fig.dpi / 72.0
    tu, to = under.get_transform(), over.get_transform()
    pu = tu.transform(np.asarray(under.get_xydata(), dtype=float))
    po = to.transform(np.asarray(over.get_xydata(), dtype=float))
    pu, po = pu[np.isfinite(pu).all(axis=1)], po[np.isfinite(po).all(axis=1)]
    if not len(pu) or not len(po):
        return 0.0
    return float(np.mean(_line_distance(pu, po) <= 0.5 * px))
