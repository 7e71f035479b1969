"""Which reference landmarks a sensor could ever have seen from a trajectory (no I/O).

A SLAM map can only hold the landmarks its run observed. A reference landmark that never
came within the sensor's reach of the true trajectory is *unobserved*: counting it as
*missed* (and charging it the full cut-off ``c`` in OSPA/GOSPA) scores the world, not the map.

The sensor's **reach** is a range ``r_max`` [m] and optionally a field of view ``φ`` [rad]
(the full opening angle, centred on the heading; ``None``: all around). A landmark ``l`` is
*within reach* of the trajectory ``x_k = [x, y, θ]`` when for some pose ``k``

    ‖l − p_k‖ ≤ r_max   and   |wrap(atan2(l_y − y_k, l_x − x_k) − θ_k)| ≤ φ / 2,

``p_k = [x_k, y_k]``. :func:`within_reach` evaluates it over all poses × landmarks,
vectorised, in chunks of at most :data:`CHUNK` pairs (a 60 Hz ground truth of an hour and a
thousand landmarks would not fit in memory at once).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relation_metric import se2
from relation_metric.errors import InputError

__all__ = ["CHUNK", "REACH_SOURCES", "SensorReach", "within_reach"]

#: Largest number of pose × landmark pairs evaluated at once.
CHUNK = 4_000_000

#: Where a :class:`SensorReach` came from: declared by the bundle's sensor model, or the
#: largest range the bundle's measurements hold (the sensor's field of view then unknown:
#: all around).
REACH_SOURCES = ("declared", "largest measured range")


@dataclass(frozen=True)
class SensorReach:
    """How far (and, optionally, in which field of view) a range-bearing sensor sees.

    Attributes
    ----------
    max_range : float
        ``r_max`` [m], > 0.
    fov : float or None
        Full opening angle ``φ`` [rad] in ``(0, 2π]``, centred on the heading; ``None``:
        all around.
    source : str
        One of :data:`REACH_SOURCES`.
    """

    max_range: float
    fov: float | None = None
    source: str = "declared"

    def __post_init__(self) -> None:
        if not (np.isfinite(self.max_range) and self.max_range > 0):
            raise InputError(f"sensor reach: expected a positive range, got {self.max_range}")
        if self.fov is not None and not (0 < self.fov <= 2 * np.pi):
            raise InputError(f"sensor reach: expected a field of view in (0, 2π], got {self.fov}")
        if self.source not in REACH_SOURCES:
            raise InputError(f"sensor reach: unknown source {self.source!r}")

    @property
    def description(self) -> str:
        """E.g. ``"range 5 m (largest measured range), all around"``."""
        fov = "all around" if self.fov is None else f"field of view {np.degrees(self.fov):.4g}°"
        return f"range {self.max_range:.4g} m ({self.source}), {fov}"

    def as_dict(self) -> dict[str, object]:
        return {
            "max_range": float(self.max_range),
            "fov": None if self.fov is None else float(self.fov),
            "source": self.source,
        }


def within_reach(
    poses: ArrayLike, landmarks: ArrayLike, reach: SensorReach, *, chunk: int = CHUNK
) -> NDArray[np.bool_]:
    """Whether each landmark was within ``reach`` of at least one pose (module docstring).

    Parameters
    ----------
    poses : array_like, shape (N, 3)
        ``[x, y, θ]`` of the (true) trajectory.
    landmarks : array_like, shape (L, 2)
    reach : SensorReach
    chunk : int
        At most this many pose × landmark pairs at once (poses are taken in blocks of
        ``max(1, chunk // L)``).

    Returns
    -------
    ndarray of bool, shape (L,)
    """
    x = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    lm = np.asarray(landmarks, dtype=np.float64).reshape(-1, 2)
    seen = np.zeros(lm.shape[0], dtype=bool)
    if x.shape[0] == 0 or lm.shape[0] == 0:
        return seen
    r2 = reach.max_range**2
    step = max(1, int(chunk) // lm.shape[0])
    for start in range(0, x.shape[0], step):
        todo = ~seen
        if not todo.any():
            break
        p = x[start : start + step]
        d = lm[None, todo, :] - p[:, None, :2]  # (n, l, 2)
        ok = d[..., 0] ** 2 + d[..., 1] ** 2 <= r2
        if reach.fov is not None:
            bearing = se2.wrap_angle(np.arctan2(d[..., 1], d[..., 0]) - p[:, None, 2])
            ok &= np.abs(bearing) <= reach.fov / 2
        seen[np.flatnonzero(todo)[ok.any(axis=0)]] = True
    return seen
