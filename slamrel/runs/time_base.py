"""The report's one time axis: seconds since the run's start."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from recovery.bundle import Bundle

__all__ = ["TimeBase"]


@dataclass(frozen=True)
class TimeBase:
    """The report's one time axis: seconds since the run's start (every timeline, interval
    and stretch of the page is given on it).

    Attributes
    ----------
    t0, t1 : float
        Start and end of the run's log (first and last control, or odometry, time) [s, on
        the log's own clock, e.g. Unix time].
    """

    t0: float
    t1: float

    @property
    def duration(self) -> float:
        """``t1 − t0`` [s]."""
        return self.t1 - self.t0

    def since_start(self, t: ArrayLike) -> NDArray[np.float64]:
        """Times ``t`` [s, the log's clock] as seconds since the run's start."""
        return np.asarray(t, dtype=np.float64) - self.t0

    @classmethod
    def of(cls, bundle: Bundle) -> TimeBase:
        """The span of the bundle's log (``controls.csv``, else ``odometry.csv``)."""
        if bundle.controls is not None:
            t = bundle.controls[:, 0]
        else:
            assert bundle.odometry is not None  # a bundle has one or the other (Bundle checks)
            t = bundle.odometry.timestamps
        return cls(float(t[0]), float(t[-1]))

    def as_dict(self) -> dict[str, Any]:
        return {"t0": self.t0, "t1": self.t1, "duration": self.duration,
                "unit": "s since the run's start (t0 on the log's clock)"}  # fmt: skip
