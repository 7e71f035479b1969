"""Figures of the end-to-end report (matplotlib, Agg; no statistics computed here).

Every time axis is in seconds since the run's start (the caller passes times on that axis,
or the run's start ``t0`` to subtract: :class:`slamrel.runs.time_base.TimeBase`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple, Protocol

import numpy as np
from numpy.typing import NDArray

from relation_metric.consistency import NeesOverTime, NeesSummary
from relation_metric.trajectory import Trajectory
from slamrel.plots.maps import MAP_COLOUR
from slamrel.plots.relation_errors import pyplot

__all__ = [
    "SetPanel",
    "trajectories_figure",
    "nees_figure",
    "relation_sets_figure",
    "mark_stretches_xy",
    "mark_stretches_time",
    "estimate_colours",
]

#: One colour per relation set, the same in every figure.
SET_COLOURS = {"consecutive": "tab:blue", "loops": "tab:orange", "global": "tab:green"}
#: The legend of :func:`trajectories_figure` (below the plot: it hides no landmark).
TRAJECTORY_LEGEND: dict[str, Any] = {
    "loc": "upper center", "bbox_to_anchor": (0.5, -0.07), "ncol": 3, "fontsize": 8,
    "frameon": False,
}  # fmt: skip
#: The legend of :func:`relation_sets_figure`'s timelines (above the top one, right).
TIMELINE_LEGEND: dict[str, Any] = {
    "loc": "lower right", "bbox_to_anchor": (1.0, 1.0), "ncol": 4, "fontsize": 8,
    "markerscale": 4, "frameon": False,
}  # fmt: skip
#: Errors below this are drawn at it on the logarithmic timelines.
ERROR_FLOOR = {"translation": 1e-4, "rotation": 1e-5}


class TimeSpan(Protocol):
    """Anything with a start and an end time [s] (e.g. :class:`recovery.recover.Stretch`)."""

    @property
    def t0(self) -> float: ...

    @property
    def t1(self) -> float: ...


#: Drawing order of :func:`trajectories_figure`: the reference beneath everything, the
#: landmarks above it, the estimates on top (an estimate lying on the reference must show).
TRAJECTORY_ZORDER = {"reference": 1.0, "landmarks": 2.0, "estimates": 3.0}
#: One colour per estimate, the same in every figure (not green: the NEES band; not red: the
#: map/log disagreement; not purple: the map); other names take :data:`OTHER_COLOURS` in turn.
ESTIMATE_COLOURS = {"recovered": "tab:blue", "online": "tab:orange", "dead_reckoning": "tab:brown"}
OTHER_COLOURS = ("tab:cyan", "tab:olive", "tab:pink")
#: The reference of :func:`trajectories_figure`: lighter and thinner than the estimates.
REFERENCE_STYLE: dict[str, Any] = {"color": "0.6", "lw": 0.8}
ESTIMATE_WIDTH = 1.2


def estimate_colours(names: Sequence[str]) -> dict[str, str]:
    """The colour of each estimate (:data:`ESTIMATE_COLOURS`; others in turn)."""
    others = iter(OTHER_COLOURS * (1 + len(names)))
    return {k: ESTIMATE_COLOURS.get(k) or next(others) for k in names}


def trajectories_figure(
    reference: Trajectory | None,
    estimates: Mapping[str, Trajectory],
    *,
    landmarks: NDArray[np.float64] | None = None,
    mapped: NDArray[np.float64] | None = None,
    labels: Mapping[str, str] | None = None,
    title: str | None = None,
) -> Any:
    """Reference and estimated trajectories (and true / mapped landmarks) in one plot.

    The estimates and the map are drawn as given: the caller moves them into the reference's
    frame first and says how in ``labels`` (legend text per estimate name) or ``title``.
    The reference (``None``: there is none) is a thin light grey line beneath the estimates
    (:data:`TRAJECTORY_ZORDER`, :data:`REFERENCE_STYLE`), so that an estimate lying on it
    stays visible, and the first estimate (the main one) lies on top of the others; each
    estimate has its colour (:func:`estimate_colours`, as in :func:`nees_figure`); the map is
    hollow purple circles (:data:`MAP_COLOUR`), true landmarks black crosses.
    """
    plt = pyplot()
    z = TRAJECTORY_ZORDER
    fig, ax = plt.subplots(figsize=(7, 7), constrained_layout=True)
    if reference is not None:
        ax.plot(reference.poses[:, 0], reference.poses[:, 1], "-", label="ground truth",
                zorder=z["reference"], **REFERENCE_STYLE)  # fmt: skip
    n = len(estimates)
    colours = estimate_colours(list(estimates))
    for k, (name, est) in enumerate(estimates.items()):
        label = name if labels is None else labels.get(name, name)
        # the first estimate (the main one) on top of the others, the legend in their order
        ax.plot(est.poses[:, 0], est.poses[:, 1], "-", lw=ESTIMATE_WIDTH, label=label,
                color=colours[name], zorder=z["estimates"] + 0.01 * (n - k))  # fmt: skip
    if landmarks is not None and landmarks.size:
        ax.plot(landmarks[:, 0], landmarks[:, 1], "k+", ms=7, label="true landmarks",
                zorder=z["landmarks"])  # fmt: skip
    if mapped is not None and mapped.size:
        ax.plot(mapped[:, 0], mapped[:, 1], "o", mfc="none", ms=6, color=MAP_COLOUR,
                label="SLAM map", zorder=z["landmarks"])  # fmt: skip
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    if title:
        ax.set_title(title, fontsize=9)
    ax.legend(**TRAJECTORY_LEGEND)
    return fig


def nees_figure(
    times: NDArray[np.float64] | Mapping[str, NDArray[np.float64]],
    curves: Mapping[str, NDArray[np.float64]],
    summaries: Mapping[str, NeesSummary],
    *,
    span: tuple[float, float] | None = None,
) -> Any:
    """NEES over time for each estimate, with the 95% χ² band of a single run.

    ``times``: per curve, the times of its values [s since the run's start] (one array for
    all curves only when every curve has exactly its length: a curve is never drawn against
    times it does not have). ``span``: the x range (the run's, ``(0, duration)``), so that
    the axis shows the whole run whatever part of it the curves cover.
    """
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 3.5), constrained_layout=True)
    band = None
    colours = estimate_colours(list(curves))
    for name, v in curves.items():
        t = times[name] if isinstance(times, Mapping) else times
        if np.shape(t) != np.shape(v):
            raise ValueError(f"NEES of {name}: {np.size(v)} values but {np.size(t)} times")
        ax.semilogy(
            t,
            np.maximum(v, 1e-6),
            lw=1,
            color=colours[name],
            label=f"{name} (mean {summaries[name].mean:.3g})",
        )
        band = summaries[name].band
    if band is not None:
        ax.axhspan(band[0], band[1], color="tab:green", alpha=0.15, label="95% χ² band (3 dof)")
    if span is not None:
        ax.set_xlim(*span)
    ax.set_xlabel("time since the run's start [s]")
    ax.set_ylabel("NEES")
    # below the axes: inside, "best" still covered the low NEES values it could not avoid
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=2, fontsize=8, frameon=False)
    return fig


class SetPanel(NamedTuple):
    """What :func:`relation_sets_figure` draws of one relation set.

    Attributes
    ----------
    name : str
        ``"consecutive"``, ``"loops"``, ``"global"``.
    times : ndarray, shape (M,)
        Mid-times of its scored relations [s since the run's start].
    translation, rotation : ndarray, shape (M,)
        Their translational [m] and rotational [rad] errors.
    pose_xy : ndarray, shape (K, 2)
        The poses its relations end at, in the drawing frame.
    pose_error : ndarray, shape (K,)
        The mean translational error of the relations ending at each [m].
    high : float
        The top of the colour scale [m] (the caller's robust choice, e.g. the 95th
        percentile of ``pose_error``); larger values are drawn in its colour.
    high_label : str
        What ``high`` is, for the colour bar (e.g. ``"p95"``).
    unassociated : int
        Relations of the set that could not be scored.
    absent : str
        Why the set has no relations (drawn instead of the panel); empty when it has some.
    """

    name: str
    times: NDArray[np.float64]
    translation: NDArray[np.float64]
    rotation: NDArray[np.float64]
    pose_xy: NDArray[np.float64]
    pose_error: NDArray[np.float64]
    high: float
    high_label: str = "p95"
    unassociated: int = 0
    absent: str = ""


def relation_sets_figure(
    panels: Sequence[SetPanel],
    track: NDArray[np.float64],
    *,
    reference: NDArray[np.float64] | None = None,
    span: tuple[float, float] | None = None,
) -> Any:
    """Relation errors over time, set by set, and one map panel per relation set.

    Top two rows: translational and rotational errors of each scored relation at its
    mid-time [s since the run's start] (log scale; one colour per set). Bottom row: per set,
    the estimate ``track`` ``(N, 2)`` in grey (the ``reference`` positions faintly beneath)
    and each pose a relation of the set ends at, coloured by the mean translational error
    of those relations on the set's own scale ``[0, high]`` (stated in its colour bar).
    """
    plt = pyplot()
    from matplotlib.gridspec import GridSpec

    cols = max(1, len(panels))
    # at least two panels wide: the timelines' legend (right) must clear their title (left)
    fig = plt.figure(figsize=(4.2 * max(cols, 2), 11.5), constrained_layout=True)
    gs = GridSpec(3, cols, figure=fig, height_ratios=[1, 1, 2.3])
    ax_t = fig.add_subplot(gs[0, :])
    ax_r = fig.add_subplot(gs[1, :], sharex=ax_t)
    present = [p for p in panels if not p.absent]
    # the sets with the largest errors first, so that the small ones stay visible on top
    for p in sorted(present, key=lambda p: -_median(p.translation)):
        colour = SET_COLOURS.get(p.name)
        label = f"{p.name} ({p.times.size} scored)"
        ms = 2 if p.times.size > 500 else 4  # a small set stays visible among large ones
        ax_t.plot(p.times, np.maximum(p.translation, ERROR_FLOOR["translation"]), ".", ms=ms,
                  alpha=0.6, color=colour, label=label)  # fmt: skip
        ax_r.plot(p.times, np.maximum(p.rotation, ERROR_FLOOR["rotation"]), ".", ms=ms,
                  alpha=0.6, color=colour, label=label)  # fmt: skip
    for ax, what, unit in ((ax_t, "translation", "m"), (ax_r, "rotation", "rad")):
        ax.set_yscale("log")
        ax.set_ylabel(f"{what}al error [{unit}]")
        ax.grid(True, which="major", alpha=0.3)
    if present:
        ax_t.legend(**TIMELINE_LEGEND)
    ax_t.set_title(
        "relation errors at the mid-time of each relation\n(log scale; below "
        f"{ERROR_FLOOR['translation']:g} m / {ERROR_FLOOR['rotation']:g} rad drawn at it)",
        fontsize=9, loc="left",
    )  # fmt: skip
    ax_r.set_xlabel("time since the run's start [s]")
    if span is not None:
        ax_t.set_xlim(*span)
    for k, p in enumerate(panels):
        _set_panel(fig, fig.add_subplot(gs[2, k]), p, track, reference)
    return fig


def _set_panel(
    fig: Any, ax: Any, p: SetPanel, track: NDArray[np.float64], ref: NDArray[np.float64] | None
) -> None:
    """One relation set's errors at the poses they end at, over the grey estimate."""
    if ref is not None and ref.size:
        ax.plot(ref[:, 0], ref[:, 1], "-", color="0.6", lw=0.6, zorder=1)
    ax.plot(track[:, 0], track[:, 1], "-", color="0.85", lw=1.5, zorder=1)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    if p.absent:
        ax.set_title(f"{p.name}: no relations", fontsize=9)
        ax.text(0.5, 0.5, _wrap(p.absent, 38), transform=ax.transAxes, ha="center",
                va="center", fontsize=8, bbox={"fc": "white", "ec": "0.7"})  # fmt: skip
        return
    order = np.argsort(p.pose_error, kind="stable")  # the largest errors drawn on top
    sc = ax.scatter(p.pose_xy[order, 0], p.pose_xy[order, 1], c=p.pose_error[order], s=9,
                    cmap="viridis", vmin=0.0, vmax=max(p.high, 1e-12), zorder=2, lw=0)  # fmt: skip
    mean = float(np.mean(p.translation)) if p.translation.size else float("nan")
    ax.set_title(
        f"{p.name}: {p.translation.size} scored, {p.unassociated} unassociated\n"
        f"mean translational error {mean:.3g} m",
        fontsize=9,
    )
    fig.colorbar(
        sc, ax=ax, orientation="horizontal", extend="max", fraction=0.06, pad=0.02,
        label=f"mean error of the {p.name} relations\nending at a pose [m]; scale 0–{p.high_label} "
        f"= {p.high:.3g} m",
    )  # fmt: skip


def _median(x: NDArray[np.float64]) -> float:
    return float(np.median(x)) if x.size else 0.0


def _wrap(text: str, width: int) -> str:
    import textwrap

    return "\n".join(textwrap.wrap(text, width))


def mark_stretches_xy(fig: Any, stretches: Sequence[TimeSpan], estimate: Trajectory | None) -> Any:
    """Mark the poses of ``estimate`` inside each stretch ``[t0, t1]`` on a trajectory plot.

    ``stretches``: a recovery's :class:`recovery.recover.Stretch` list, in time order, on
    the estimate's clock. Returns ``fig``.
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
    ax.legend(**TRAJECTORY_LEGEND)
    return fig


def mark_stretches_time(
    fig: Any,
    stretches: Sequence[TimeSpan],
    *,
    t0: float,
    axes: Sequence[int] = (0,),
    legend: Mapping[str, Any] | None = None,
) -> Any:
    """Shade each stretch ``[t0, t1]`` on the time axes ``axes`` (indices into ``fig.axes``)
    of a figure whose x axis is seconds since the run's start ``t0`` (on the stretches'
    clock); each at least 0.4 % of the axis wide, so that a short one stays visible. The
    legend of the first of ``axes`` is redrawn with ``legend`` (keyword arguments of
    ``Axes.legend``). Returns ``fig``."""
    if not stretches or not fig.axes:
        return fig
    for i in axes:
        ax = fig.axes[i]
        lo, hi = ax.get_xlim()
        for k, s in enumerate(stretches):
            a, b = float(s.t0) - t0, float(s.t1) - t0
            ax.axvspan(a, max(b, a + 0.004 * (hi - lo)), color="tab:red", alpha=0.2, lw=0,
                       label="map/log disagree" if k == 0 else None)  # fmt: skip
        ax.set_xlim(lo, hi)
    first = fig.axes[axes[0]]
    first.legend(**(legend or {"loc": "upper left", "fontsize": 8}))
    return fig


def filter_nees_figure(r: NeesOverTime) -> Any:
    """The NEES of a filter over time (:func:`relation_metric.consistency.nees_over_time`).

    Top: the pose NEES (log scale) with the ``r.probability`` band of one value and the mean
    with its interval; bottom: the position and orientation NEES with their bands.
    """
    plt = pyplot()
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True, constrained_layout=True)
    t = r.times - r.times[0]
    pct = f"{100 * r.probability:g}%"
    runs = f", average of {r.runs} runs" if r.runs > 1 else ""
    top.semilogy(t, np.maximum(r.nees, 1e-6), lw=0.8, color="tab:blue", label=f"NEES{runs}")
    top.axhspan(*r.band, color="tab:green", alpha=0.15, label=f"{pct} χ² band ({r.dof} dof{runs})")
    top.axhline(r.mean, color="tab:red", lw=1, label=f"mean {r.mean:.3g}")
    top.axhspan(*r.mean_band, color="tab:red", alpha=0.15, label=f"{pct} interval of the mean")
    top.set_ylabel("NEES")
    top.set_title(f"{100 * r.inside:.1f}% inside the band; error frame {r.frame}", fontsize=9)
    top.legend(loc="best", fontsize=8)
    for values, dof, name, colour in (
        (r.position, r.position_dof, "position", "tab:orange"),
        (r.orientation, r.orientation_dof, "orientation", "tab:purple"),
    ):
        bottom.semilogy(
            t, np.maximum(values, 1e-6), lw=0.8, color=colour, label=f"{name} ({dof} dof)"
        )
        lo, hi = r.part_band(dof)
        bottom.axhline(lo, color=colour, lw=0.6, ls="--")
        bottom.axhline(hi, color=colour, lw=0.6, ls="--")
    bottom.set_ylabel("NEES (dashed: bands)")
    bottom.set_xlabel("time since the first pose [s]")
    bottom.legend(loc="best", fontsize=8)
    return fig
