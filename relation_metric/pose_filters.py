"""evo's pose thinning before an APE/RPE: ``--downsample N`` and ``--motion_filter D A``.

Both return the indices of the poses kept, in order (evo applies them to reference and
estimate alike, before the time association):

- :func:`downsample_ids` — evo's ``PosePath3D.downsample``: ``N`` evenly spaced poses,
  ``linspace(0, n − 1, N)`` truncated to integers; all poses when there are at most ``N``.
- :func:`motion_filter_ids` — evo's ``filters.filter_by_motion``: pose 0, then each pose whose
  travelled path since the last kept pose is at least ``distance`` [m], or whose rotation
  angle from the last kept pose is at least ``angle`` [rad].
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from relation_metric import se3
from relation_metric.errors import InputError
from relation_metric.trajectory import Trajectory

__all__ = ["downsample_ids", "motion_filter_ids"]

#: The first window of poses :func:`motion_filter_ids` searches for a rotation; it doubles.
_FIRST_WINDOW = 64


def downsample_ids(n: int, max_poses: int) -> NDArray[np.int64]:
    """At most ``max_poses`` (≥ 1) evenly spaced indices of ``n`` poses, shape (min(n, N),)."""
    if max_poses < 1:
        raise InputError(f"can't downsample to less than one pose, got {max_poses}")
    if n <= max_poses:
        return np.arange(n, dtype=np.int64)
    return np.linspace(0, n - 1, max_poses, dtype=int).astype(np.int64)


def motion_filter_ids(trajectory: Trajectory, distance: float, angle: float) -> NDArray[np.int64]:
    """The poses evo's motion filter keeps (module doc): indices, shape (K,), from 0.

    ``trajectory`` is SE(3) (poses ``x y z qx qy qz qw``); ``distance`` ≥ 0 [m] and ``angle``
    ≥ 0 [rad]. One step per kept pose: the first pose at least ``distance`` further along the
    path (a search on the cumulative path, evo's test ``s_i − s_p ≥ distance`` exactly), or
    before it the first pose rotated at least ``angle`` from the kept pose ``p`` (searched in
    doubling windows, vectorised).
    """
    n = len(trajectory)
    if n < 2:
        raise InputError("the motion filter needs at least two poses")
    if distance < 0.0 or angle < 0.0:
        raise InputError(f"motion filter thresholds must be >= 0, got {distance}, {angle}")
    s = trajectory.path_length()
    q = trajectory.poses[:, 3:]
    kept = [0]
    p = 0
    while p < n - 1:
        by_path = _first_beyond(s, p, distance)
        by_angle = _first_rotated(q, p, by_path, angle)
        p = min(by_path, by_angle)
        if p >= n:
            break
        kept.append(p)
    return np.asarray(kept, dtype=np.int64)


def _first_beyond(s: NDArray[np.float64], p: int, distance: float) -> int:
    """The first index i > p with ``s[i] − s[p] ≥ distance`` (``len(s)``: none)."""
    n = s.size
    i = max(int(np.searchsorted(s, s[p] + distance, side="left")), p + 1)
    while i < n and s[i] - s[p] < distance:  # rounding of s[p] + distance: a step at most
        i += 1
    while i - 1 > p and s[i - 1] - s[p] >= distance:
        i -= 1
    return i


def _first_rotated(q: NDArray[np.float64], p: int, stop: int, angle: float) -> int:
    """The first index i in (p, stop) rotated at least ``angle`` from pose p (else ``stop``)."""
    start, width = p + 1, _FIRST_WINDOW
    conj = se3.quat_conjugate(q[p])
    while start < stop:
        end = min(stop, start + width)
        theta = se3.rotation_angle(se3.quat_multiply(conj, q[start:end]))
        hit = np.flatnonzero(theta >= angle)
        if hit.size:
            return start + int(hit[0])
        start, width = end, 2 * width
    return stop
