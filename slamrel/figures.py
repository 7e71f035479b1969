"""Figures of the end-to-end report (matplotlib, Agg; no statistics computed here)."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from relation_metric.consistency import NeesSummary
from relation_metric.plots import pyplot
from relation_metric.trajectory import Trajectory

__all__ = ["trajectories_figure", "nees_figure"]


def trajectories_figure(
    reference: Trajectory,
    estimates: dict[str, Trajectory],
    *,
    landmarks: NDArray[np.float64] | None = None,
    mapped: NDArray[np.float64] | None = None,
) -> Any:
    """Reference and estimated trajectories (and true / mapped landmarks) in one plot."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 7), constrained_layout=True)
    ax.plot(reference.poses[:, 0], reference.poses[:, 1], "k-", lw=2, label="reference", zorder=3)
    for name, est in estimates.items():
        ax.plot(est.poses[:, 0], est.poses[:, 1], "-", lw=1, label=name)
    if landmarks is not None and landmarks.size:
        ax.plot(landmarks[:, 0], landmarks[:, 1], "k+", ms=5, label="true landmarks")
    if mapped is not None and mapped.size:
        ax.plot(mapped[:, 0], mapped[:, 1], "o", mfc="none", ms=5, color="tab:red", label="map")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(loc="best", fontsize=8)
    return fig


def nees_figure(
    t: NDArray[np.float64],
    curves: dict[str, NDArray[np.float64]],
    summaries: dict[str, NeesSummary],
) -> Any:
    """NEES over time for each estimate, with the 95% χ² band of a single run."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 3.5), constrained_layout=True)
    band = None
    for name, v in curves.items():
        ax.semilogy(
            t[: v.size],
            np.maximum(v, 1e-6),
            lw=1,
            label=f"{name} (mean {summaries[name].mean:.3g})",
        )
        band = summaries[name].band
    if band is not None:
        ax.axhspan(band[0], band[1], color="tab:green", alpha=0.15, label="95% χ² band (3 dof)")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("NEES")
    ax.legend(loc="best", fontsize=8)
    return fig
