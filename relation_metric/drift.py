"""KITTI odometry drift: translational [%] and rotational [deg/m] errors over path segments.

The definition is the KITTI odometry devkit's (``evaluate_odometry.cpp``, Geiger et al. 2012),
the number odometry papers print:

* the path length ``s_k`` of the **reference** (ground truth), ``s_0 = 0``,
  ``s_k = s_{k-1} + ‖t_k − t_{k-1}‖``;
* start frames ``f = 0, step, 2·step, ...`` (``step = 10``: "every second" at 10 Hz) and for each
  segment length ``L`` (100, 200, ..., 800 m) the end frame ``l`` = the first frame with
  ``s_l > s_f + L`` (strictly greater); a start frame without one is skipped for that ``L``;
* the pose error of the segment ``E = (P_f⁻¹ P_l)⁻¹ (G_f⁻¹ G_l)`` (``P`` the estimate, ``G`` the
  ground truth, 4×4 poses mapping the body frame into the world frame);
* translational error ``‖t(E)‖ / L`` and rotational error ``angle(R(E)) / L`` (the angle of
  ``R(E)``, ``arccos((tr R − 1) / 2)``, in ``[0, π]``).

The devkit's sequence numbers (``stats.txt``) are the means of these ratios over **all**
segments, every length pooled (:attr:`KittiDrift.translation_percent`,
:attr:`KittiDrift.rotation_deg_per_m`); its plots show them averaged per length
(:attr:`KittiDrift.per_length`). Some tools (e.g. the kitti-odom-eval scripts) print instead the
mean of the per-length means (:attr:`KittiDrift.translation_percent_by_length`); the two agree
when every length has as many segments. The devkit computes in single precision; this module
in double precision, so the last printed digit may differ.

Poses are ``(N, 7)`` ``[x, y, z, qx, qy, qz, qw]`` (SE(3), :mod:`relation_metric.se3`), matched
one to one (pose ``k`` of the estimate is the estimate of frame ``k``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relation_metric import se3
from relation_metric.errors import InputError

__all__ = ["KITTI_LENGTHS", "KITTI_STEP", "KittiDrift", "SegmentLength", "kitti_drift"]

#: Segment lengths of the devkit [m].
KITTI_LENGTHS = (100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0)
#: Start frames: every 10th frame (one a second at KITTI's 10 Hz).
KITTI_STEP = 10


@dataclass(frozen=True)
class SegmentLength:
    """The errors of the segments of one length ``length`` [m].

    ``translation_percent`` is the mean of ``100 ‖t(E)‖ / L``, ``rotation_deg_per_m`` the mean
    of ``angle(R(E)) / L`` in degrees per metre, over ``count`` segments (NaN when none).
    """

    length: float
    count: int
    translation_percent: float
    rotation_deg_per_m: float


@dataclass(frozen=True)
class KittiDrift:
    """KITTI drift of an estimate (see the module's docstring for the definition).

    Attributes
    ----------
    translation_percent, rotation_deg_per_m : float
        The devkit's sequence errors: means over all segments (every length pooled).
    translation_percent_by_length, rotation_deg_per_m_by_length : float
        The mean of the per-length means (over the lengths with at least one segment).
    per_length : tuple of SegmentLength
        One per segment length, in the order given.
    segments : int
        Segments scored (all lengths).
    first_frame, last_frame : ndarray, shape (segments,)
        The start and end frame of each segment.
    segment_length : ndarray, shape (segments,)
        Its length ``L`` [m].
    translation, rotation : ndarray, shape (segments,)
        ``‖t(E)‖ / L`` [m/m] and ``angle(R(E)) / L`` [rad/m] of each segment.
    """

    translation_percent: float
    rotation_deg_per_m: float
    translation_percent_by_length: float
    rotation_deg_per_m_by_length: float
    per_length: tuple[SegmentLength, ...]
    segments: int
    first_frame: NDArray[np.int64]
    last_frame: NDArray[np.int64]
    segment_length: NDArray[np.float64]
    translation: NDArray[np.float64]
    rotation: NDArray[np.float64]

    def as_dict(self) -> dict[str, object]:
        """JSON-ready: the sequence numbers and the per-length table (NaN as None)."""

        def num(v: float) -> float | None:
            return None if not np.isfinite(v) else float(v)

        return {
            "translation_percent": num(self.translation_percent),
            "rotation_deg_per_m": num(self.rotation_deg_per_m),
            "translation_percent_by_length": num(self.translation_percent_by_length),
            "rotation_deg_per_m_by_length": num(self.rotation_deg_per_m_by_length),
            "segments": self.segments,
            "per_length": [
                {
                    "length_m": s.length,
                    "count": s.count,
                    "translation_percent": num(s.translation_percent),
                    "rotation_deg_per_m": num(s.rotation_deg_per_m),
                }
                for s in self.per_length
            ],
        }


def kitti_drift(
    reference: ArrayLike,
    estimate: ArrayLike,
    *,
    lengths: ArrayLike = KITTI_LENGTHS,
    step: int = KITTI_STEP,
) -> KittiDrift:
    """KITTI drift of ``estimate`` against ``reference`` (the devkit's definition).

    Parameters
    ----------
    reference, estimate : array_like, shape (N, 7)
        Matched SE(3) poses ``[x, y, z, qx, qy, qz, qw]`` (frame ``k`` of both is pose ``k``).
    lengths : array_like of float
        Segment lengths ``L`` [m], each > 0 (default: 100, 200, ..., 800).
    step : int
        Start frames ``0, step, 2·step, ...`` (default 10), ≥ 1.

    Returns
    -------
    KittiDrift
        With no segment at all (a path shorter than every length) the means are NaN and
        ``segments`` is 0; callers say so.
    """
    g = np.asarray(reference, dtype=np.float64)
    p = np.asarray(estimate, dtype=np.float64)
    if g.ndim != 2 or g.shape[1] != 7 or g.shape != p.shape:
        raise InputError(
            f"KITTI drift needs two matched (N, 7) SE(3) pose arrays, got {g.shape} and {p.shape}"
        )
    lens = np.asarray(lengths, dtype=np.float64).ravel()
    if lens.size == 0 or not np.all(np.isfinite(lens) & (lens > 0)):
        raise InputError(f"segment lengths must be positive numbers, got {lens.tolist()}")
    if int(step) != step or step < 1:
        raise InputError(f"step must be a positive integer, got {step!r}")
    n = g.shape[0]
    dist = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(g[:, :3], axis=0), axis=1))))
    first = np.arange(0, n, int(step))
    # last frame: the first k with dist[k] > dist[first] + L (searchsorted "right" is strict)
    f = np.repeat(first, lens.size)
    length = np.tile(lens, first.size)
    last = np.searchsorted(dist, dist[f] + length, side="right")
    ok = last < n
    f, last, length = f[ok], last[ok], length[ok]
    d_gt = se3.between(g[f], g[last])
    d_est = se3.between(p[f], p[last])
    err = se3.between(d_est, d_gt)  # (P_f⁻¹ P_l)⁻¹ (G_f⁻¹ G_l)
    t_err = np.linalg.norm(err[:, :3], axis=1) / length
    r_err = se3.rotation_angle(err[:, 3:]) / length
    per = []
    for L in lens:  # one row per length (≤ a few): the segments are vectorised above
        sel = length == L
        k = int(np.count_nonzero(sel))
        tp = float(100.0 * t_err[sel].mean()) if k else float("nan")
        rd = float(np.degrees(r_err[sel].mean())) if k else float("nan")
        per.append(SegmentLength(float(L), k, tp, rd))
    have = [s for s in per if s.count]
    nan = float("nan")
    return KittiDrift(
        translation_percent=float(100.0 * t_err.mean()) if t_err.size else nan,
        rotation_deg_per_m=float(np.degrees(r_err.mean())) if r_err.size else nan,
        translation_percent_by_length=(
            float(np.mean([s.translation_percent for s in have])) if have else nan
        ),
        rotation_deg_per_m_by_length=(
            float(np.mean([s.rotation_deg_per_m for s in have])) if have else nan
        ),
        per_length=tuple(per),
        segments=int(f.size),
        first_frame=f.astype(np.int64),
        last_frame=last.astype(np.int64),
        segment_length=length,
        translation=t_err,
        rotation=r_err,
    )
