"""Figures of map comparisons: both maps, the reference mesh, edges coloured by error."""

from __future__ import annotations

from typing import Any

import numpy as np

from landmark_graph.map_compare import MapComparison
from slamrel.plots.relation_errors import pyplot

__all__ = ["MAP_COLOUR", "MAP_LEGEND", "map_figure"]

#: The SLAM map's markers, in this figure and the run report's trajectory figure: hollow
#: purple circles (red is the colour of the stretches where the map and the log disagree).
MAP_COLOUR = "tab:purple"

#: The legend of :func:`map_figure`: below the plot, where it covers no landmark.
MAP_LEGEND: dict[str, Any] = {
    "loc": "upper center", "bbox_to_anchor": (0.5, -0.08), "ncol": 3, "fontsize": 8,
    "frameon": False,
}  # fmt: skip


def map_figure(res: MapComparison) -> Any:
    """Reference and estimated landmarks in the comparison's frame (the estimate moved onto the
    reference by the fit on the associated pairs, :mod:`landmark_graph.map_compare`, unless
    the comparison was asked to be unaligned), the reference mesh with each edge coloured by
    its length error, thin triangles dotted, missed, unobserved and spurious landmarks
    marked. The legend sits below the plot and the title is two short lines, so that the
    figure hides no landmark and cuts no word (:data:`MAP_LEGEND`)."""
    plt = pyplot()
    from matplotlib.collections import LineCollection

    a = res.association
    ref = res.reference.xy[a.reference_rows]
    fig, ax = plt.subplots(figsize=(7, 7), constrained_layout=True)
    segs = np.stack((ref[res.mesh.edges[:, 0]], ref[res.mesh.edges[:, 1]]), axis=1)
    err = res.errors.edge_length
    lc = LineCollection(list(segs), cmap="viridis", linewidths=2)
    lc.set_array(err)
    if err.size:
        lc.set_clim(0, max(float(np.percentile(err, 99)), 1e-12))
    ax.add_collection(lc)
    fig.colorbar(lc, ax=ax, label="edge length error [m] (clipped at p99)")
    ax.plot(res.reference.xy[:, 0], res.reference.xy[:, 1], "k+", ms=8, label="reference")
    est = res.estimate_xy
    ax.plot(est[:, 0], est[:, 1], "o", mfc="none", color=MAP_COLOUR, label="estimate")
    if res.missed.size:
        m = res.reference.xy[res.missed]
        ax.plot(m[:, 0], m[:, 1], "x", ms=9, color="tab:gray", label="missed (reference)")
    if res.unobserved.size:
        u = res.reference.xy[res.unobserved]
        ax.plot(u[:, 0], u[:, 1], ".", ms=5, color="tab:gray", label="never within reach")
    if a.spurious.size:
        s = est[a.spurious]
        ax.plot(s[:, 0], s[:, 1], "s", mfc="none", color="tab:orange", label="spurious (estimate)")
    if res.mesh.thin.any():
        t = res.mesh.triangles[res.mesh.thin]
        ring = ref[np.concatenate((t, t[:, :1]), axis=1)]  # (K, 4, 2) closed outlines
        thin = LineCollection(list(ring), colors="tab:gray", linewidths=0.6, linestyles=":")
        ax.add_collection(thin)
        ax.plot([], [], ":", color="tab:gray", lw=0.6, label="thin triangle")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(**MAP_LEGEND)
    al = res.alignment
    frame = f"aligned on {al.pairs} pairs" if al.applied else "as given"
    unobserved = f", {res.unobserved.size} unobserved" if res.unobserved.size else ""
    ax.set_title(
        f"{a.estimate_rows.size} matched, {res.missed.size} missed{unobserved}, "
        f"{a.spurious.size} spurious\n"
        f"OSPA {res.ospa:.3g} m (c = {res.cutoff:g}, p = {res.order:g}, {frame})",
        fontsize=10,
    )
    return fig
