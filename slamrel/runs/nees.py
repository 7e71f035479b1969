"""The NEES of an estimate against the ground truth: one computation for every report.

The pose NEES ``eᵀ P⁻¹ e`` (3 dof, :func:`relation_metric.consistency.pose_nees`) of an
estimate with covariances, at the ground-truth times where the estimate has a pose (within
1 µs), in the frame of :mod:`recovery.anchoring` (:func:`placed_frame`). ``slamrel run``
(``metrics.json`` ``nees``, ``nees_truth_frame`` and ``divergence.nees_stretches``, the report's
consistency section and verdict) and ``slamrel recover --report`` read it from here, so that a
trajectory has one NEES wherever it is shown.

**The prior is left out.** The first of those poses is the run's start pose, given to the
filter with its covariance, not estimated: its NEES measures the start pose's own covariance
(``≈ 0`` when the run starts at the true pose, as every simulated bundle does), not the
recovery. Counting it pulled the mean NEES of ``slamrel run simple1`` from 2.028 (84 poses)
to 2.004 (85 poses) in the recovery's own summary.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from recovery.anchoring import Anchoring, NeesFrame, start_frame, truth_at_start
from recovery.bundle import Bundle
from recovery.ekf import DEFAULT_MAX_OUTLIER_RUN
from recovery.placement import Placement, condition_on_placement
from recovery.results import Recovery
from relation_metric.consistency import (
    NeesBlowup,
    NeesSummary,
    nees_blowups,
    pose_nees,
    summarize_nees,
)
from relation_metric.errors import InputError
from relation_metric.time_association import match_nearest_times, nearest_index
from relation_metric.trajectory import Trajectory
from slamrel.runs.time_base import TimeBase

if TYPE_CHECKING:
    from landmark_graph.map_compare import MapComparison

__all__ = [
    "NeesCurve",
    "PlacementNees",
    "at_truth_times",
    "blowups",
    "estimate_nees",
    "frame_by_id",
    "map_pairs",
    "placed_frame",
    "placement_nees",
    "recovery_nees",
    "truth_at",
]


class NeesCurve(NamedTuple):
    """The NEES of one estimate: its summary, the per-step values, shape (steps,), and their
    times [s] (the estimate's poses where the NEES exists; ``None``: not known)."""

    summary: NeesSummary
    values: NDArray[np.float64]
    times: NDArray[np.float64] | None = None


def truth_at(truth: Trajectory, t: ArrayLike) -> NDArray[np.float64]:
    """Ground-truth poses nearest in time to ``t`` (the callers pass ground-truth times)."""
    return truth.poses[nearest_index(truth.timestamps, np.asarray(t, dtype=np.float64))]


def at_truth_times(
    estimate: Trajectory, truth: Trajectory
) -> tuple[Trajectory, NDArray[np.int64]] | None:
    """The estimate's poses at the ground-truth times it has (within 1 µs), and their rows in
    ``estimate``; ``None`` when no estimate pose lies at a ground-truth time."""
    at, rows = match_nearest_times(truth.timestamps, estimate.timestamps, 1e-6)
    if not at.size:
        return None
    return Trajectory(truth.timestamps[at], estimate.poses[rows]), rows


def placed_frame(bundle: Bundle, map_anchoring: Anchoring | None = None) -> NeesFrame:
    """The frame the NEES is computed in: placed by the run's start pose at the log's start
    (:func:`recovery.anchoring.start_frame`), the landmark fit ``map_anchoring`` reported
    beside it (not applied)."""
    assert bundle.groundtruth is not None
    g0 = truth_at_start(bundle.groundtruth, TimeBase.of(bundle).t0)
    return start_frame(bundle.initial_pose, bundle.initial_covariance, g0, map_anchoring)


def frame_by_id(bundle: Bundle) -> NeesFrame:
    """:func:`placed_frame` with the landmark fit on the landmarks the map shares by id with
    ``landmarks_groundtruth`` reported beside it (``slamrel recover``; ``slamrel run`` fits on
    the map comparison's pairs instead, :func:`slamrel.pipeline.landmark_frame`). The fit
    is reported, never applied: the NEES does not depend on it."""
    by_id = NeesFrame.by_id(bundle.map_ids, bundle.map_xy, bundle.landmarks_groundtruth)
    return placed_frame(bundle, by_id.anchoring)


def estimate_nees(
    truth: Trajectory, estimate: Trajectory, covariances: ArrayLike, frame: NeesFrame
) -> tuple[NeesCurve, NeesSummary]:
    """The NEES of an estimate in ``frame``, and its summary in the truth frame, unaligned.

    Parameters
    ----------
    truth : Trajectory
    estimate : Trajectory
        At ground-truth times (:func:`at_truth_times`); its first pose, the prior, is left
        out (module docstring).
    covariances : array_like, shape (N, 3, 3)
        One per pose of ``estimate`` (rows ``[x, y, θ]``).
    frame : NeesFrame
        With an anchoring, the poses and covariances are taken into the truth frame by it
        first; the unaligned summary compares them as they are.

    Returns
    -------
    curve : NeesCurve
        Summary, values and times (``N − 1`` of each) in ``frame``.
    unaligned : NeesSummary
        The same poses compared with the ground truth as they are (equal to
        ``curve.summary`` when ``frame`` has no anchoring).
    """
    covs = np.asarray(covariances, dtype=np.float64)[1:]
    poses, ref = estimate.poses[1:], truth_at(truth, estimate.timestamps)[1:]
    v0 = pose_nees(poses, ref, covs)
    unaligned = summarize_nees(v0, dof=3)
    v = v0
    if frame.anchoring is not None:
        poses, covs = frame.anchoring.apply(poses, covs)
        v = pose_nees(poses, ref, covs)
    return NeesCurve(summarize_nees(v, dof=3), v, estimate.timestamps[1:]), unaligned


def blowups(curve: NeesCurve, max_outlier_run: int | None) -> list[NeesBlowup]:
    """The NEES blow-ups of a curve (:func:`relation_metric.consistency.nees_blowups`), in runs
    of the recovery's ``max_outlier_run`` poses (its default when ``None``), as its stretches
    of disagreement are in runs of innovations."""
    assert curve.times is not None
    run = max_outlier_run if max_outlier_run else DEFAULT_MAX_OUTLIER_RUN
    return nees_blowups(curve.times, curve.values, min_run=run)


def recovery_nees(
    bundle: Bundle, recovery: Recovery, frame: NeesFrame | None = None
) -> tuple[NeesCurve, NeesSummary] | None:
    """The NEES of a recovery against its bundle's ground truth, as ``slamrel run`` computes
    it (:func:`estimate_nees` at the ground-truth times), in ``frame`` (default
    :func:`frame_by_id`).

    ``None`` without ground truth, or when no recovered pose after the first lies at a
    ground-truth time.
    """
    truth = bundle.groundtruth
    if truth is None:
        return None
    got = at_truth_times(recovery.trajectory, truth)
    if got is None or len(got[0]) < 2:  # the first pose, the prior, has no NEES
        return None
    frame = frame_by_id(bundle) if frame is None else frame
    return estimate_nees(truth, got[0], recovery.covariances[got[1]], frame)


class PlacementNees(NamedTuple):
    """The recovered NEES conditioned on the map's placement (:mod:`recovery.placement`).

    ``curve`` as :func:`estimate_nees` gives it (in the NEES frame, the prior left out);
    ``placement`` the conditioning, at the recovery's poses at ground-truth times (the first
    included)."""

    curve: NeesCurve
    placement: Placement


def map_pairs(
    comparison: MapComparison, frame: NeesFrame | None
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """The map rows the comparison associated and their true positions ``(n, 2)`` taken into
    the map frame: by the inverse of ``frame``'s anchoring (truth ← map) when it has one,
    else as they are."""
    a = comparison.association
    t = np.asarray(comparison.reference.xy, dtype=np.float64)[np.asarray(a.reference_rows)]
    if frame is not None and frame.anchoring is not None:
        an = frame.anchoring
        c, s = np.cos(an.dtheta), np.sin(an.dtheta)
        d = t - np.array([an.dx, an.dy])
        t = np.column_stack((c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]))
    return np.asarray(a.estimate_rows, dtype=np.int64), t


def placement_nees(
    bundle: Bundle,
    recovery: Recovery,
    frame: NeesFrame,
    map_rows: ArrayLike,
    map_truth: ArrayLike,
) -> PlacementNees | None:
    """The recovered NEES with each pose conditioned on the map's placement, fitted on the
    map rows ``map_rows`` whose true positions ``map_truth`` ``(n, 2)`` are given in the map
    frame (:func:`map_pairs`).

    ``None`` where it is not defined: no ground truth, a recovery without map loadings (the
    filter), a map without uncertainty, fewer than 3 landmarks with a true position, or a map
    covariance over them that is not positive definite.
    """
    truth = bundle.groundtruth
    rows = np.asarray(map_rows, dtype=np.int64)
    mu = recovery.map_uncertainty
    if (
        truth is None
        or recovery.map_loadings is None
        or recovery.map_link is None
        or mu is None
        or mu.rank == 0
        or rows.size < 3
    ):
        return None
    got = at_truth_times(recovery.trajectory, truth)
    if got is None or len(got[0]) < 2:
        return None
    est, at = got
    idx = np.column_stack((2 * rows, 2 * rows + 1)).ravel()
    try:
        pl = condition_on_placement(
            est.poses,
            recovery.covariances[at],
            recovery.map_loadings[at],
            recovery.map_link,
            mu.factor[idx],
            np.asarray(bundle.map_xy)[rows],
            map_truth,
        )
    except InputError:
        return None
    moved = Trajectory(est.timestamps, pl.poses)
    curve = estimate_nees(truth, moved, pl.covariances, frame)[0]
    return PlacementNees(curve, pl)
