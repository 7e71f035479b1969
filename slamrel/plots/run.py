"""Figures of the end-to-end report (matplotlib, Agg; no statistics computed here)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from relation_metric.consistency import NeesSummary
from relation_metric.evaluate import Evaluation
from relation_metric.trajectory import Trajectory
from slamrel.plots.relation_errors import pyplot

__all__ = ["trajectories_figure", "nees_figure", "mark_stretches_xy", "mark_stretches_time"]


class TimeSpan(Protocol):
    """Anything with a start and an end time [s] (e.g. :class:`recovery.recover.Stretch`)."""

    @property
    def t0(self) -> float: ...

    @property
    def t1(self) -> float: ...


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


def mark_stretches_xy(fig: Any, stretches: Sequence[TimeSpan], estimate: Trajectory | None) -> Any:
    """Mark the poses of ``estimate`` inside each stretch ``[t0, t1]`` on a trajectory plot.

    ``stretches``: a recovery's :class:`recovery.recover.Stretch` list, in time order.
    Returns ``fig``.
    """
    if not stretches or estimate is None or not fig.axes:
        return fig
    t = estimate.timestamps
    t0 = np.array([float(s.t0) for s in stretches])
    t1 = np.array([float(s.t1) for s in stretches])
    k = np.searchsorted(t0, t, side="right") - 1
    inside = (k >= 0) & (t <= t1[np.clip(k, 0, None)])
    ax = fig.axes[0]
    xy = estimate.poses[inside, :2]
    ax.plot(xy[:, 0], xy[:, 1], ".", ms=4, color="tab:red", zorder=4, label="map/log disagree")
    ax.legend(loc="best", fontsize=8)
    return fig


def mark_stretches_time(fig: Any, stretches: Sequence[TimeSpan], evaluation: Evaluation) -> Any:
    """Shade each stretch ``[t0, t1]`` on the error timeline of an evaluation figure.

    The timeline's axis is the relation mid-time since the first scored relation
    (:func:`slamrel.plots.relation_errors.evaluation_figure`). Returns ``fig``.
    """
    if not stretches or not fig.axes:
        return fig
    ev = evaluation
    mid = 0.5 * (ev.relations.first + ev.relations.second)[ev.valid]
    origin = float(mid.min()) if mid.size else 0.0
    ax = fig.axes[0]
    for k, s in enumerate(stretches):
        a, b = float(s.t0) - origin, float(s.t1) - origin
        ax.axvspan(a, max(b, a + 0.5), color="tab:red", alpha=0.15, lw=0,
                   label="map/log disagree" if k == 0 else None)  # fmt: skip
    ax.legend(loc="upper left", fontsize=8)
    return fig
