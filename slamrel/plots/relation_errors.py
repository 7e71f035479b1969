"""Figures of relation errors: where along the trajectory the estimate is wrong.

matplotlib is imported lazily (Agg unless the user or Jupyter chose a backend, see
:func:`pyplot`); figures are written atomically. Statistics live in
:mod:`relation_metric.stats`, not here.
"""

from __future__ import annotations

import io
from typing import TYPE_CHECKING

import numpy as np

from relation_metric.evaluate import Evaluation
from relation_metric.trajectory import Trajectory
from slamrel.constants import PLOT_MODES
from slamrel.formats.text import PathLike, write_bytes_atomic

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = [
    "evaluation_figure",
    "save_figure",
    "pyplot",
    "plot_plane",
    "literal_text",
    "PLOT_MODES",
]

#: The planes of :func:`evaluation_figure` (``plot_mode``): two position axes, horizontal then
#: vertical, or ``"auto"`` (:func:`plot_plane`); defined in :mod:`slamrel.constants`.
_AXES = "xyz"


def plot_plane(mode: str, positions: np.ndarray) -> tuple[int, int, int | None]:
    """The drawn plane's axes ``(horizontal, vertical, remaining)`` for ``positions (N, d)``.

    ``"auto"``: the two axes of largest extent (max − min), in x, y, z order, and the third as
    the remaining axis (3-D): a KITTI drive in its camera frame (x right, y down, z forward)
    is drawn in x-z with y as the remaining, "height", axis; a planar or a TUM-style z-up
    trajectory in x-y. A named plane (``"xz"``: x horizontal, z vertical) is drawn as named;
    in 2-D only ``xy``, ``yx`` and ``auto``. The remaining axis is ``None`` in 2-D.
    """
    dim = positions.shape[1]
    if mode not in PLOT_MODES:
        raise ValueError(f"plot mode: expected one of {', '.join(PLOT_MODES)}, got {mode!r}")
    if mode == "xyz":
        raise ValueError("plot mode 'xyz' is a 3-D view, not a plane")
    if mode == "auto":
        if dim == 2:
            return 0, 1, None
        extent = positions.max(axis=0) - positions.min(axis=0) if len(positions) else np.zeros(3)
        order = np.argsort(-extent, kind="stable")
        h, v = sorted(int(i) for i in order[:2])
        return h, v, int(order[2])
    h, v = _AXES.index(mode[0]), _AXES.index(mode[1])
    if max(h, v) >= dim:
        raise ValueError(f"plot mode {mode!r} needs 3-D positions; the trajectory is planar")
    rest = ({0, 1, 2} - {h, v}).pop() if dim == 3 else None
    return h, v, rest


def pyplot():  # type: ignore[no-untyped-def]
    """``matplotlib.pyplot``, imported lazily.

    The non-interactive Agg backend is chosen only when nobody chose before: not when pyplot
    is already imported, not inside IPython/Jupyter (whose inline backend shows the
    figures), not when ``MPLBACKEND`` is set. A library must not take the user's backend.
    """
    import os
    import sys

    import matplotlib

    chosen = "matplotlib.pyplot" in sys.modules or "MPLBACKEND" in os.environ
    if not chosen and "IPython" not in sys.modules:
        matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def literal_text(text: str) -> str:
    """``text`` as matplotlib draws it literally: every ``$`` escaped.

    A pair of unescaped ``$`` makes matplotlib parse the text between as mathtext, so a
    user's name (a dataset or algorithm, ``a$\\frac$``) would be drawn as formula or fail
    to draw at all; outside ``$`` nothing else is special (a backslash is drawn as itself).
    Every user-given text put into a figure goes through here.
    """
    return text.replace("$", r"\$")


def evaluation_figure(
    evaluation: Evaluation,
    estimate: Trajectory,
    *,
    degrees: bool = False,
    title: str | None = None,
    plot_mode: str = "xy",
    reference: Trajectory | None = None,
) -> Figure:
    """Errors over time (top) and the estimate with each relation coloured by its error.

    The estimate is drawn in the plane of ``plot_mode`` (:data:`PLOT_MODES`; ``"auto"``:
    the plane of largest extent, :func:`plot_plane`); a 3-D estimate gets a third panel of its
    remaining axis over time (its height when the plane is horizontal). ``"xyz"`` (3-D
    estimates only) draws a perspective view of all three axes instead, the touched poses
    coloured by their error. ``reference`` (a
    trajectory, drawn as given: the relation metric aligns nothing) is drawn beneath it.

    The estimate is coloured pose by pose with the largest translational error of the
    relations that touch each pose, and the ends of the ten worst relations are marked, so
    that large errors point at the part of the map that is wrong. Unassociated relations are
    counted in the title, not drawn.
    """
    plt = pyplot()
    three_d = estimate.group.position_dim == 3
    if plot_mode == "xyz":
        return _figure_xyz(evaluation, estimate, degrees, title, reference)
    h, v, rest = plot_plane(plot_mode, estimate.positions)
    fig, axes = plt.subplots(
        3 if three_d else 2,
        1,
        figsize=(8.0, 13.0 if three_d else 10.0),
        gridspec_kw={"height_ratios": [1, 2, 1] if three_d else [1, 2]},
        constrained_layout=True,
    )
    _errors_over_time(axes[0], evaluation, estimate, degrees)
    pose_err, hit = _pose_errors(evaluation, len(estimate))
    ax_xy = axes[1]
    if reference is not None and len(reference):
        ref = reference.lifted() if three_d else reference
        if ref.group.position_dim == estimate.group.position_dim:
            p = ref.positions
            ax_xy.plot(
                p[:, h], p[:, v], "--", color="0.35", lw=1.0, zorder=0, label="reference (as given)"
            )
    _coloured_estimate(fig, ax_xy, evaluation, estimate, pose_err, (h, v))
    ax_xy.set_aspect("equal", adjustable="datalim")
    ax_xy.set_xlabel(f"{_AXES[h]} [m]")
    ax_xy.set_ylabel(f"{_AXES[v]} [m]")
    plane = f" ({_AXES[h]}-{_AXES[v]} plane)" if three_d else ""
    ax_xy.set_title(title or ("estimate coloured by relation error" + plane))
    if reference is not None:
        ax_xy.legend(loc="best")
    if three_d:
        assert rest is not None  # 3-D: the axis not drawn
        _height_over_time(axes[2], estimate, pose_err, hit, rest)
    return fig


def _figure_xyz(
    evaluation: Evaluation,
    estimate: Trajectory,
    degrees: bool,
    title: str | None,
    reference: Trajectory | None,
) -> Figure:
    """``plot_mode="xyz"``: errors over time and a 3-D view of reference and estimate."""
    if estimate.group.position_dim != 3:
        raise ValueError("plot mode 'xyz' needs a 3-D estimate; the trajectory is planar")
    plt = pyplot()
    fig = plt.figure(figsize=(8.0, 12.0), constrained_layout=True)
    ax_t = fig.add_subplot(3, 1, 1)
    ax = fig.add_subplot(3, 1, (2, 3), projection="3d")
    _errors_over_time(ax_t, evaluation, estimate, degrees)
    pose_err, hit = _pose_errors(evaluation, len(estimate))
    if reference is not None and len(reference):
        p = reference.lifted().positions
        ax.plot(p[:, 0], p[:, 1], p[:, 2], "--", color="0.35", lw=1.0, label="reference (as given)")
    q = estimate.positions
    ax.plot(q[:, 0], q[:, 1], q[:, 2], "-", color="0.7", lw=1.0, label="estimate")
    if hit.any():
        sc = ax.scatter(q[hit, 0], q[hit, 1], q[hit, 2], c=pose_err[hit], s=4, cmap="viridis")
        fig.colorbar(sc, ax=ax, shrink=0.6, label="largest translational error at a pose [m]")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")
    ax.set_title(title or "estimate coloured by relation error (3-D view)")
    ax.legend(loc="best")
    return fig


def _errors_over_time(ax_t: Axes, ev: Evaluation, estimate: Trajectory, degrees: bool) -> None:
    """Translational (left axis) and rotational (right axis) errors by relation mid-time."""
    valid = ev.valid
    a = ev.association
    if ev.relations.key == "index":  # pose indices: the estimate's times of the two ends
        t = estimate.timestamps
        t_mid = 0.5 * (t[a.index_first[valid]] + t[a.index_second[valid]])
    else:
        t_mid = 0.5 * (ev.relations.first + ev.relations.second)[valid]
    order = np.argsort(t_mid, kind="stable")
    trans = ev.errors.translation[valid][order]
    rot = ev.errors.rotation[valid][order]
    if degrees:
        rot = np.degrees(rot)
    x_axis = t_mid[order] - (t_mid.min() if t_mid.size else 0.0)
    ax_t.plot(x_axis, trans, ".", ms=3, color="tab:blue", label="translation [m]")
    ax_t.set_xlabel("time of relation (mid-point) since start [s]")
    ax_t.set_ylabel("translational error [m]", color="tab:blue")
    ax_r = ax_t.twinx()
    ax_r.plot(x_axis, rot, ".", ms=3, color="tab:red", alpha=0.6)
    ax_r.set_ylabel(f"rotational error [{'deg' if degrees else 'rad'}]", color="tab:red")
    s = ev.translation.abs
    ax_t.set_title(
        f"{s.count} relations scored, {int((~valid).sum())} unassociated; "
        f"translation {s.mean:.4g} ± {s.std:.4g} m"
    )


def _pose_errors(ev: Evaluation, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Largest translational error of the relations touching each of ``n`` poses (NaN where
    none does), shape (n,), and the mask of touched poses."""
    valid = ev.valid
    a = ev.association
    err = ev.errors.translation[valid]
    pose_err = np.full(n, np.nan)
    idx = np.concatenate((a.index_first[valid], a.index_second[valid]))
    touched = np.zeros(n)
    np.maximum.at(touched, idx, np.concatenate((err, err)))
    hit = np.zeros(n, dtype=bool)
    hit[idx] = True
    pose_err[hit] = touched[hit]
    return pose_err, hit


def _coloured_estimate(
    fig: Figure,
    ax_xy: Axes,
    ev: Evaluation,
    estimate: Trajectory,
    pose_err: np.ndarray,
    plane: tuple[int, int] = (0, 1),
) -> None:
    """The estimate in grey, each segment coloured by the larger error of its two poses (the
    wrong part of the map lights up), and the ends of the ten worst relations marked."""
    from matplotlib.collections import LineCollection

    valid = ev.valid
    a = ev.association
    err = ev.errors.translation[valid]
    cols = list(plane)
    xy = estimate.poses[:, cols]
    ax_xy.plot(xy[:, 0], xy[:, 1], "-", color="0.8", lw=1.0, zorder=1, label="estimate")
    if not (err.size and len(estimate) > 1):
        return
    seg_err = np.fmax(pose_err[:-1], pose_err[1:])
    has = np.isfinite(seg_err)
    segments = np.stack((xy[:-1], xy[1:]), axis=1)[has]
    hi = max(float(np.percentile(err, 99)), 1e-12)
    lc = LineCollection(segments, cmap="viridis", linewidths=2.0, zorder=2)  # type: ignore[arg-type]
    lc.set_array(seg_err[has])
    lc.set_clim(0.0, hi)
    ax_xy.add_collection(lc)
    worst = np.argsort(err)[-min(10, err.size) :]
    ends = np.concatenate(
        (a.pose_first[valid][worst][:, cols], a.pose_second[valid][worst][:, cols])
    )
    ax_xy.plot(
        ends[:, 0],
        ends[:, 1],
        "x",
        color="tab:red",
        ms=7,
        zorder=3,
        label="ends of the 10 worst relations",
    )
    fig.colorbar(
        lc,
        ax=ax_xy,
        label="largest translational error of the relations at a pose [m] (clipped at p99)",
    )
    ax_xy.legend(loc="best")


def _height_over_time(
    ax_z: Axes, estimate: Trajectory, pose_err: np.ndarray, hit: np.ndarray, axis: int = 2
) -> None:
    """The remaining axis (default z, the height) of a 3-D estimate over time, the touched
    poses coloured by their error."""
    t0 = float(estimate.timestamps[0]) if len(estimate) else 0.0
    ax_z.plot(estimate.timestamps - t0, estimate.poses[:, axis], "-", color="0.5", lw=1.0)
    if hit.any():
        ax_z.scatter(
            estimate.timestamps[hit] - t0,
            estimate.poses[hit, axis],
            c=pose_err[hit],
            s=4,
            cmap="viridis",
            zorder=2,
        )
    ax_z.set_xlabel("time since start [s]")
    ax_z.set_ylabel(f"{_AXES[axis]} [m]")
    what = "height (z)" if axis == 2 else f"the remaining axis ({_AXES[axis]})"
    ax_z.set_title(f"{what} of the estimate, coloured by relation error")


def save_figure(fig: Figure, path: PathLike, *, dpi: int = 120) -> None:
    """Save a figure atomically (PNG, SVG or PDF by the file extension) and close it."""
    plt = pyplot()
    fmt = str(path).rsplit(".", 1)[-1].lower() if "." in str(path) else "png"
    buf = io.BytesIO()
    try:
        fig.savefig(buf, format=fmt, dpi=dpi)
    finally:
        plt.close(fig)
    write_bytes_atomic(path, buf.getvalue())
