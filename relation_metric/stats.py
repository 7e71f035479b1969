"""Summary statistics of error samples (no plotting, no I/O)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "Summary",
    "ErrorStats",
    "summarize",
    "summarize_with_squares",
    "evo_statistics",
    "STAT_NAMES",
    "EVO_STAT_NAMES",
]

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


@dataclass(frozen=True)
class ErrorStats:
    """Statistics of one error part (translation, rotation, ...): of the absolute errors
    ``|e|`` (``abs``) and of their squares ``e²`` (``sqr``), as the metricEvaluator prints
    them without and with ``-q``.

    Attributes
    ----------
    abs : Summary
        Of ``|e|``.
    sqr : Summary
        Of ``e²`` (its ``mean`` is the part's share of Kümmerle et al.'s ε).
    """

    abs: Summary
    sqr: Summary

    def as_dict(self) -> dict[str, dict[str, float | int | None]]:
        """The JSON form ``{"abs": {...}, "sqr": {...}}`` (NaN written as ``None``)."""
        return {"abs": self.abs.as_dict(), "sqr": self.sqr.as_dict()}


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


def summarize_with_squares(values: ArrayLike) -> tuple[Summary, Summary]:
    """``(summarize(v), summarize(v * v))`` of non-negative errors ``v``, bit for bit, faster.

    One ``np.partition`` serves both medians and the extremes of ``v²`` are those of ``v``
    squared: rounding ``x ↦ fl(x²)`` keeps the order of non-negative numbers, so the order
    statistics of ``v²`` are the squares of those of ``v``. ``v²`` is computed once (it is
    also the abs part's ``rmse``). Values that are not all finite and non-negative take the
    two plain :func:`summarize` calls.

    Parameters
    ----------
    values : array_like, shape (N,)

    Returns
    -------
    abs, sqr : Summary
    """
    v = np.asarray(values, dtype=np.float64).ravel()
    sq = v * v
    n = int(v.size)
    lo, hi = (v.min(), v.max()) if n else (np.nan, np.nan)
    if not (lo >= 0.0 and hi < np.inf):
        return summarize(v), summarize(sq)
    k = n // 2
    kth = [k - 1, k] if n % 2 == 0 else [k]
    middle = np.partition(v, [*kth, -1])[kth[0] : k + 1]  # np.median's own partition
    nan = float("nan")
    abs_part = Summary(
        mean=float(v.mean()),
        std=float(v.std(ddof=1)) if n > 1 else nan,
        min=float(lo),
        max=float(hi),
        median=float(np.mean(middle)),
        rmse=float(np.sqrt(np.mean(sq))),
        count=n,
    )
    sqr_part = Summary(
        mean=float(sq.mean()),
        std=float(sq.std(ddof=1)) if n > 1 else nan,
        min=float(lo * lo),
        max=float(hi * hi),
        median=float(np.mean(middle * middle)),
        rmse=float(np.sqrt(np.mean(sq * sq))),
        count=n,
    )
    return abs_part, sqr_part


#: The statistics evo computes of an error array, in evo's order (``StatisticsType``).
EVO_STAT_NAMES = ("rmse", "mean", "median", "std", "min", "max", "sse")


def evo_statistics(values: ArrayLike) -> dict[str, float]:
    """The statistics of an error array as evo computes them (``PE.get_all_statistics``).

    ``rmse = sqrt(mean(e²))``, ``sse = Σ e²`` and ``std`` the *population* standard
    deviation (``ddof=0``, numpy's default, which evo uses), unlike :class:`Summary`'s
    sample ``std``; keys in evo's order (:data:`EVO_STAT_NAMES`). Needs at least one value.
    """
    e = np.asarray(values, dtype=np.float64).ravel()
    if e.size == 0:
        raise ValueError("evo's statistics need at least one error value")
    sq = e**2
    return {
        "rmse": float(np.sqrt(np.mean(sq))),
        "mean": float(np.mean(e)),
        "median": float(np.median(e)),
        "std": float(np.std(e)),
        "min": float(np.min(e)),
        "max": float(np.max(e)),
        "sse": float(np.sum(sq)),
    }
