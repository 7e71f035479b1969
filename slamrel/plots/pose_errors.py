"""The figure of ``slamrel ape|rpe --plot/--save_plot``: evo's two plots in one figure.

Top: the errors over time (seconds from the first synchronised pose; the pair index for
KITTI, which has no times) with the rmse, mean and median as lines and ± std around the
mean as a band, as evo's raw-value plot. Bottom: the reference (dashed grey) and the
estimate as scored (aligned), each segment coloured by the error at its end pose (RPE: the
error of the first pair ending there or later), as evo's map plot, in the plane ``plot_mode`` names.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from slamrel.plots.relation_errors import literal_text, plot_plane, pyplot

__all__ = ["pose_error_figure", "EVO_PLOT_MODES"]

#: evo's planes (``--plot_mode``), horizontal axis first.
EVO_PLOT_MODES = ("xy", "xz", "yx", "yz", "zx", "zy")


def pose_error_figure(result: Any, plot_mode: str = "xy", plt: Any = None) -> Any:
    """The figure of an APE or RPE result (module doc): ``result`` an ``EvoResult`` of
    :mod:`slamrel.evo_metrics` (not imported: figures sit below the commands' work);
    ``plt`` a pyplot to draw with (default: :func:`~slamrel.plots.relation_errors.pyplot`,
    Agg unless chosen)."""
    plt = pyplot() if plt is None else plt
    from matplotlib.collections import LineCollection

    fig, (ax_t, ax_xy) = plt.subplots(2, 1, figsize=(8, 9), height_ratios=(1, 1.6))
    err = result.errors
    timed = result.seconds_from_start is not None
    x = result.seconds_from_start if timed else np.arange(err.size, dtype=np.float64)
    unit = result.info["label"]
    ax_t.plot(x, err, "-", color="0.3", lw=1.0, label=literal_text(unit))
    s = result.stats
    ax_t.axhspan(s["mean"] - s["std"], s["mean"] + s["std"], color="tab:blue", alpha=0.15)
    for name, colour in (("rmse", "tab:red"), ("mean", "tab:blue"), ("median", "tab:green")):
        ax_t.axhline(s[name], color=colour, lw=1.2, label=f"{name} {s[name]:.6g}")
    ax_t.set_xlabel("time since start [s]" if timed else "pair index (no times)")
    ax_t.set_ylabel(literal_text(unit))
    ax_t.set_title(literal_text(result.title.replace("\n", " ")), fontsize=9)
    ax_t.legend(loc="best", fontsize=8)

    est = result.estimate.poses
    fit = result.pairs.alignment
    if fit is not None:
        est = fit.apply(est)
    ref_xyz, est_xyz = result.reference.poses[:, :3], est[:, :3]
    h, v, _ = plot_plane(plot_mode, ref_xyz)
    ax_xy.plot(ref_xyz[:, h], ref_xyz[:, v], "--", color="0.5", lw=1.0, label="reference")
    at_pose = _error_at_pose(result.pairs.second, err, est_xyz.shape[0])
    seg = np.stack((est_xyz[:-1][:, (h, v)], est_xyz[1:][:, (h, v)]), axis=1)
    has = np.isfinite(at_pose[1:])
    ax_xy.plot(est_xyz[:, h], est_xyz[:, v], "-", color="0.85", lw=1.0, label="estimate")
    lc = LineCollection(seg[has], cmap="viridis", linewidths=2.0)  # type: ignore[arg-type]
    lc.set_array(at_pose[1:][has])
    ax_xy.add_collection(lc)
    fig.colorbar(lc, ax=ax_xy, label=literal_text(unit))
    ax_xy.set_xlabel(f"{plot_mode[0]} [m]")
    ax_xy.set_ylabel(f"{plot_mode[1]} [m]")
    ax_xy.set_aspect("equal", adjustable="datalim")
    ax_xy.legend(loc="best", fontsize=8)
    fig.tight_layout()
    return fig


def _error_at_pose(second: np.ndarray, err: np.ndarray, n: int) -> np.ndarray:
    """``(n,)``: pose k takes the error of the first pair (by end pose) ending at k or later
    (APE: each pose's own error, ``second = k``); NaN after the last pair's end."""
    order = np.argsort(second, kind="stable")
    ends = second[order]
    k = np.arange(n)
    idx = np.searchsorted(ends, k, side="left")
    out = np.full(n, np.nan)
    inside = idx < ends.size
    out[inside] = err[order[idx[inside]]]
    return out
