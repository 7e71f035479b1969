"""Summary statistics of error samples (no plotting, no I/O)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["Summary", "summarize", "STAT_NAMES"]

STAT_NAMES = ("mean", "std", "min", "max", "median", "rmse", "count")


@dataclass(frozen=True)
class Summary:
    """Statistics of N error values.

    ``std`` is the sample standard deviation (``n − 1`` in the denominator, as the Freiburg
    metricEvaluator prints it); ``rmse = sqrt(mean(e²))``. With no values every statistic is
    NaN and ``count`` is 0; with one value ``std`` is NaN.
    """

    mean: float
    std: float
    min: float
    max: float
    median: float
    rmse: float
    count: int

    def as_dict(self, *, json_safe: bool = True) -> dict[str, float | int | None]:
        """The statistics by name; NaN becomes ``None`` when ``json_safe``."""
        out: dict[str, float | int | None] = dict(asdict(self))
        if json_safe:
            for key, value in out.items():
                if isinstance(value, float) and not math.isfinite(value):
                    out[key] = None
        return out


def summarize(values: ArrayLike) -> Summary:
    """Statistics of a 1-D array of errors.

    Parameters
    ----------
    values : array_like, shape (N,)

    Returns
    -------
    Summary
    """
    v = np.asarray(values, dtype=np.float64).ravel()
    n = int(v.size)
    if n == 0:
        nan = float("nan")
        return Summary(nan, nan, nan, nan, nan, nan, 0)
    mean = float(v.mean())
    std = float(v.std(ddof=1)) if n > 1 else float("nan")
    return Summary(
        mean=mean,
        std=std,
        min=float(v.min()),
        max=float(v.max()),
        median=float(np.median(v)),
        rmse=float(np.sqrt(np.mean(v * v))),
        count=n,
    )
