"""Trajectory recovery from a SLAM result bundle: filter, smoother or batch (no I/O here).

Burgard et al. 2009 recover the trajectory of an EKF-SLAM run "by localisation: run EKF-based
localisation given the landmark locations, data associations, and motion/sensor model used
during SLAM". :func:`recover` does that (:mod:`recovery.ekf`), and, the recovery being
offline, smooths it (:mod:`recovery.smoother`) or refines it as a batch MAP problem
(:mod:`recovery.batch`). Gated measurements are counted and reported: a large gated fraction
is a finding about the map, not noise.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from recovery.bundle import Bundle
from recovery.ekf import GATED, OUTSIDE, UNASSOCIATED, USED, FilterInput, FilterResult, run_filter
from recovery.smoother import smooth
from recovery.steps import Steps, build_steps
from relation_metric import consistency
from relation_metric.errors import InputError
from relation_metric.trajectory import Trajectory, readonly

__all__ = ["METHODS", "MAP_MODES", "Recovery", "filter_input", "recover"]

Array = NDArray[np.float64]
METHODS = ("filter", "smoother", "batch")
MAP_MODES = ("joint", "marginal", "ignore")


@dataclass(frozen=True)
class Recovery:
    """A recovered trajectory.

    Attributes
    ----------
    method : str
    trajectory : Trajectory
        One pose per grid time (control/odometry times and measurement times).
    covariances : ndarray, shape (N, 3, 3)
    counts : dict
        ``measurements``, ``used``, ``gated``, ``unassociated``, ``outside`` (of the control
        span), ``skipped_unknown`` (dropped by the reader), and ``gated_fraction`` (of the
        associated measurements inside the span).
    status : ndarray of int, shape (J,)
        Per measurement: 0 used, 1 gated, 2 unassociated, 3 outside.
    nis : ndarray, shape (J,)
        Filter innovation NIS per measurement (NaN where not evaluated).
    nees : ndarray, shape (N,) or None
        Pose NEES against ground truth at grid times that have one (NaN elsewhere).
    map_mode : str
        How the map's uncertainty entered: ``joint`` (Schmidt), ``marginal`` or ``ignore``.
    """

    method: str
    trajectory: Trajectory
    covariances: Array
    counts: dict[str, float]
    status: NDArray[np.int64]
    nis: Array
    nees: Array | None
    map_mode: str
    iterations: int = 0
    extra: dict[str, object] = field(default_factory=dict)

    def report(self) -> dict[str, object]:
        """A JSON-ready summary."""
        out: dict[str, object] = {
            "method": self.method,
            "map_uncertainty": self.map_mode,
            "poses": len(self.trajectory),
            "measurements": dict(self.counts),
        }
        if self.nees is not None:
            ok = np.isfinite(self.nees)
            out["nees"] = {
                "mean": float(np.mean(self.nees[ok])) if ok.any() else None,
                "poses": int(ok.sum()),
                "band95_single_pose": list(consistency.nees_band(3, 1, 0.95)),
            }
        if self.method == "batch":
            out["iterations"] = self.iterations
        out.update(self.extra)
        return out


def filter_input(
    bundle: Bundle, steps: Steps | None = None, *, map_mode: str = "joint"
) -> FilterInput:
    """Arrays for :func:`recovery.ekf.run_filter` from a bundle.

    ``map_mode``: ``joint`` uses ``map_covariance.npy`` when present (else the marginals),
    ``marginal`` the per-landmark covariances only, ``ignore`` treats the map as exact.
    """
    if map_mode not in MAP_MODES:
        raise InputError(f"unknown map mode {map_mode!r}; expected one of {', '.join(MAP_MODES)}")
    st = build_steps(bundle) if steps is None else steps
    marg = bundle.map_marginals if map_mode != "ignore" else np.zeros_like(bundle.map_marginals)
    joint = bundle.map_covariance if map_mode == "joint" else None
    lines = bundle.measurement_lines
    src = "measurements.csv"
    labels = tuple(
        f"measurement {j} ({src}:{int(lines[j])})" if lines[j] > 0 else f"measurement {j}"
        for j in range(lines.shape[0])
    )
    return FilterInput(
        times=st.times,
        u=st.u,
        sigma=st.sigma,
        x0=bundle.initial_pose,
        p0=bundle.initial_covariance,
        meas_grid=st.measurement_grid,
        meas_z=bundle.measurements,
        meas_landmark=bundle.map_index(),
        map_xy=bundle.map_xy,
        map_marginals=marg,
        map_covariance=joint,
        r=bundle.sensor.covariance,
        meas_labels=labels,
    )


def _counts(status: NDArray[np.int64], skipped: int) -> dict[str, float]:
    used = int((status == USED).sum())
    gated = int((status == GATED).sum())
    c: dict[str, float] = {
        "measurements": int(status.shape[0]) + skipped,
        "used": used,
        "gated": gated,
        "unassociated": int((status == UNASSOCIATED).sum()),
        "outside": int((status == OUTSIDE).sum()),
        "skipped_unknown": skipped,
    }
    c["gated_fraction"] = gated / (used + gated) if used + gated else 0.0
    return c


def pose_nees_against(truth: Trajectory, times: Array, poses: Array, covs: Array) -> Array:
    """NEES at the grid times that equal a ground-truth time (within 1 µs), NaN elsewhere."""
    gt_t = truth.timestamps
    idx = np.clip(np.searchsorted(gt_t, times), 0, len(gt_t) - 1)
    prev = np.clip(idx - 1, 0, len(gt_t) - 1)
    best = np.where(np.abs(gt_t[prev] - times) < np.abs(gt_t[idx] - times), prev, idx)
    ok = np.abs(gt_t[best] - times) <= 1e-6
    out = np.full(times.shape[0], np.nan)
    if ok.any():
        out[ok] = consistency.pose_nees(poses[ok], truth.poses[best[ok]], covs[ok])
    return out


def recover(
    bundle: Bundle,
    *,
    method: str = "smoother",
    gate: float | None = None,
    map_mode: str = "joint",
    max_outlier_run: int | None = 100,
    progress: bool = False,
) -> Recovery:
    """Recover the trajectory of a SLAM run by localisation in its final map.

    Parameters
    ----------
    bundle : Bundle
    method : {"filter", "smoother", "batch"}
        EKF only; EKF + extended RTS smoother; smoother followed by Gauss–Newton/LM over all
        poses with the map fixed.
    gate : float, optional
        χ² probability of the innovation gate; ``None`` (default) gates nothing, so a broken
        map shows in the score instead of being filtered away.
    map_mode : {"joint", "marginal", "ignore"}
    max_outlier_run : int, optional
        See :func:`recovery.ekf.run_filter`.
    progress : bool
        tqdm bar on the filter's epochs.

    Returns
    -------
    Recovery
    """
    if method not in METHODS:
        raise InputError(f"unknown method {method!r}; expected one of {', '.join(METHODS)}")
    if gate is not None and not 0.0 < gate < 1.0:
        raise InputError(f"gate probability must be in (0, 1), got {gate}")
    inp = filter_input(bundle, map_mode=map_mode)
    fr: FilterResult = run_filter(
        inp, gate=gate, max_outlier_run=max_outlier_run, progress=progress
    )
    iterations = 0
    extra: dict[str, object] = {}
    if method == "filter":
        poses, covs = fr.poses, fr.covariances
    else:
        sm = smooth(fr)
        poses, covs = sm.poses, sm.covariances
        if method == "batch":
            from recovery.batch import refine

            br = refine(inp, poses, used=fr.status == USED)
            poses, covs, iterations = br.poses, br.covariances, br.iterations
            extra["batch"] = {"cost_initial": br.cost_initial, "cost_final": br.cost_final}
    _check_finite(poses, covs, inp.times)
    traj = Trajectory(inp.times, poses)
    nees = None
    if bundle.groundtruth is not None:
        nees = pose_nees_against(bundle.groundtruth, inp.times, traj.poses, covs)
    mode = map_mode if (map_mode != "joint" or bundle.map_covariance is not None) else "marginal"
    return Recovery(
        method=method,
        trajectory=traj,
        covariances=readonly(covs),
        counts=_counts(np.asarray(fr.status), bundle.skipped_unknown),
        status=fr.status,
        nis=fr.nis,
        nees=None if nees is None else readonly(nees),
        map_mode=mode,
        iterations=iterations,
        extra=extra,
    )


def _check_finite(poses: Array, covs: Array, times: Array) -> None:
    from relation_metric.errors import DivergenceError

    bad = ~(np.isfinite(poses).all(axis=1) & np.isfinite(covs).all(axis=(1, 2)))
    if not bad.any():
        ev = np.linalg.eigvalsh(covs)
        scale = np.maximum(np.abs(ev).max(axis=1), 1e-300)
        bad = ev[:, 0] < -1e-9 * scale
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise DivergenceError(
            f"recovery diverged at t={float(times[k]):.6f} s (pose {k}): non-finite or non-PSD "
            "covariance"
        )
