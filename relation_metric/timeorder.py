"""The one time-order rule of slamrel: what happens when a timed input is not in time order.

Every reader of timed rows (trajectories, bundle logs, MRCLAM logs) applies it through
:func:`sort_by_time`; the rule depends on what the rows are for.

**Timed poses** (an estimate, the odometry that corrects far timestamps, a reference
trajectory) are a *set* of poses: the rows are stable-sorted by time whatever the file order,
and the rows that came out of order are counted (:class:`TimeOrder`: how many, the largest
step back in seconds, the file line of the first). Real SLAM result logs contain such steps
(scan-matcher output written slightly out of order); the C++ metricEvaluator scores them too.
``slamrel evaluate`` reports the count (summary and ``--json``); ``--strict`` refuses.

**Logs that drive a filter** (controls, odometry, measurements, the ground truth a bundle is
scored against; MRCLAM ``.dat`` files) are a *sequence*: a step back of at most
:data:`FILTER_TIME_TOLERANCE` seconds is stable-sorted and counted; a larger one means a
broken log and raises :class:`~relation_metric.errors.InputError` with the file, the line
and both times.

**Repeated times** in an *estimate* (or odometry) make the pose of that time a guess (the
nearest-time search took the first, so the score depended on the row order): two poses at one
time that differ are refused with both lines; exact repeats are dropped and counted
(:func:`repeated_times`, ``slamrel evaluate``'s ``estimate_repeated_times``); ``--strict``
refuses either. **Repeated times** in a *reference* trajectory would give zero-length
relations that score a perfect 0 and pull the mean down: poses sharing a timestamp with an
earlier pose are dropped (the first in the file is kept), counted and warned about
(:func:`first_of_each_time`); relations with ``t1 == t2`` in a ``.relations`` file
likewise (:func:`zero_length`).

All checks are vectorised (one ``np.maximum.accumulate`` / stable ``argsort`` per input).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relation_metric.errors import InputError

__all__ = [
    "FILTER_TIME_TOLERANCE",
    "TimeOrder",
    "TimeOrderWarning",
    "RepeatedTimeWarning",
    "steps_back",
    "sort_by_time",
    "check_in_order",
    "first_of_each_time",
    "zero_length",
    "RepeatedTimes",
    "repeated_times",
]

FILTER_TIME_TOLERANCE = 0.05
"""Largest step back in time [s] that a log driving a filter may take.

Such steps are put in time order and counted; larger ones are refused. 0.05 s is five
periods of MRCLAM's 100 Hz odometry and a fifth of its median measurement spacing (0.23 s);
MRCLAM dataset 7 itself has no step back in any of its 15 robot files.
"""

# Decimal times near 1e9 s carry ~2e-7 s of binary rounding: a step of exactly the tolerance
# as written in the file must not be refused because of it.
_ROUNDING = 1e-6

Lines = Callable[[int], int] | Sequence[int] | NDArray[np.integer[Any]] | None


class TimeOrderWarning(UserWarning):
    """Rows out of time order were put in time order (and counted)."""


class RepeatedTimeWarning(UserWarning):
    """Reference poses or relations with repeated times were dropped (and counted)."""


@dataclass(frozen=True)
class TimeOrder:
    """How far the rows of one input were from time order.

    Attributes
    ----------
    out_of_order : int
        Rows whose time is earlier than the time of a row before them in the file.
    max_step_back : float
        Largest such difference [s] (0 when in order).
    first_line : int or None
        File line of the first out-of-order row (None when in order or unknown).
    """

    out_of_order: int = 0
    max_step_back: float = 0.0
    first_line: int | None = None

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready: ``{"count", "max_step_back_s", "first_line"}``."""
        return {
            "count": self.out_of_order,
            "max_step_back_s": self.max_step_back,
            "first_line": self.first_line,
        }

    def describe(self, what: str = "row") -> str:
        """One line, e.g. ``"3 poses out of time order (largest step back 0.012000 s, ...)"``."""
        if not self.out_of_order:
            return f"all {what}s in time order"
        where = "" if self.first_line is None else f", first at line {self.first_line}"
        plural = "" if self.out_of_order == 1 else "s"
        return (
            f"{self.out_of_order} {what}{plural} out of time order (largest step back "
            f"{_seconds(self.max_step_back)} s{where})"
        )


def _seconds(t: float) -> str:
    """A time for a message: 6 decimals (microseconds), or 6 significant digits from 1e15 s
    (where the decimals are no longer held; 1e300 s would print 301 digits)."""
    return f"{t:.6f}" if abs(t) < 1e15 else f"{t:.6g}"


def _line(lines: Lines, k: int) -> int | None:
    if lines is None:
        return None
    if callable(lines):
        return int(lines(k))
    return int(lines[k])


def steps_back(t: ArrayLike) -> NDArray[np.float64]:
    """How far each time lies before the latest earlier time, shape (N,), 0 when in order.

    ``back[k] = max(0, max(t[:k]) − t[k])``.
    """
    t = np.asarray(t, dtype=np.float64)
    back = np.zeros(t.shape[0])
    if t.shape[0] > 1:
        latest = np.maximum.accumulate(t)
        back[1:] = np.maximum(latest[:-1] - t[1:], 0.0)
    return back


def sort_by_time(
    t: ArrayLike,
    *,
    tolerance: float | None = None,
    lines: Lines = None,
    path: str | os.PathLike[str] | None = None,
    what: str = "row",
) -> tuple[NDArray[np.intp], TimeOrder]:
    """The time order of rows under the time-order rule (see the module docstring).

    Parameters
    ----------
    t : array_like, shape (N,)
        Times in file order (finite).
    tolerance : float, optional
        ``None`` for timed poses (any order is sorted); a number of seconds for logs that
        drive a filter (:data:`FILTER_TIME_TOLERANCE`): a larger step back raises.
    lines : callable or sequence of int, optional
        File line of row ``k`` (``lines(k)`` or ``lines[k]``), for messages and the report.
    path : str or PathLike, optional
        The file, for messages.
    what : str
        What a row is, for messages (``"pose"``, ``"control"``, ...).

    Returns
    -------
    order : ndarray of intp, shape (N,)
        Stable sorting permutation (rows with equal times keep their file order).
    report : TimeOrder

    Raises
    ------
    InputError
        With ``tolerance``: a step back larger than it (file, line and both times).
    """
    t = np.asarray(t, dtype=np.float64)
    n = t.shape[0]
    back = steps_back(t)
    late = np.flatnonzero(back > 0.0)
    if late.size == 0:
        return np.arange(n), TimeOrder()
    if tolerance is not None:
        over = np.flatnonzero(back > tolerance + _ROUNDING)
        if over.size:
            k = int(over[0])
            j = int(np.argmax(t[:k]))
            earlier = _line(lines, j)
            at = f" (line {earlier})" if earlier is not None else f" ({what} {j})"
            raise InputError(
                f"time goes backwards by {_seconds(float(back[k]))} s: {what} at t = "
                f"{_seconds(float(t[k]))} s after t = {_seconds(float(t[j]))} s{at}; steps back "
                f"of up to {tolerance:g} s are put in time order and counted, larger ones are "
                "refused (expected times in order)",
                path=path,
                line=_line(lines, k),
            )
    order = np.argsort(t, kind="stable")
    return order, TimeOrder(int(late.size), float(back.max()), _line(lines, int(late[0])))


def check_in_order(t: ArrayLike, *, path: str | os.PathLike[str] | None = None) -> None:
    """Raise when times decrease anywhere (the contract of an in-memory trajectory)."""
    t = np.asarray(t, dtype=np.float64)
    if t.shape[0] < 2:
        return
    back = np.flatnonzero(np.diff(t) < 0)
    if back.size:
        k = int(back[0])
        raise InputError(
            f"time goes backwards at pose {k + 1}: t = {_seconds(float(t[k + 1]))} s after "
            f"t = {_seconds(float(t[k]))} s; expected non-decreasing timestamps (read files with "
            "read_trajectory, which puts the poses in time order)",
            path=path,
        )


def first_of_each_time(t: ArrayLike) -> NDArray[np.bool_]:
    """Mask of the rows to keep from times in time order: the first of each repeated time.

    Parameters
    ----------
    t : array_like, shape (N,)
        Non-decreasing times.

    Returns
    -------
    ndarray of bool, shape (N,)
        False for every row whose time equals the previous row's.
    """
    t = np.asarray(t, dtype=np.float64)
    keep = np.ones(t.shape[0], dtype=bool)
    if t.shape[0] > 1:
        keep[1:] = t[1:] != t[:-1]
    return keep


def zero_length(first: ArrayLike, second: ArrayLike) -> NDArray[np.bool_]:
    """Mask of relations whose two ends carry the same time (``t1 == t2``), shape (M,)."""
    return np.asarray(first, dtype=np.float64) == np.asarray(second, dtype=np.float64)


@dataclass(frozen=True)
class RepeatedTimes:
    """Rows of a time-ordered input whose time equals the previous row's.

    Attributes
    ----------
    count : int
        Rows repeating an earlier row's time.
    differing : int
        Of those, rows whose values differ from the previous row's (two poses for one time).
    first_line : int or None
        File line of the first repeating row (a differing one when there is one).
    earlier_line : int or None
        File line of the row it repeats.
    time : float
        Its time (NaN when there is none).
    """

    count: int = 0
    differing: int = 0
    first_line: int | None = None
    earlier_line: int | None = None
    time: float = float("nan")

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready: ``{"count", "differing", "first_line"}``."""
        return {"count": self.count, "differing": self.differing, "first_line": self.first_line}


def repeated_times(
    t: ArrayLike, values: ArrayLike, lines: Lines = None
) -> tuple[NDArray[np.bool_], RepeatedTimes]:
    """Rows that repeat the previous row's time, in time-ordered ``t`` (shape (N,)).

    ``values`` (shape (N, K)) are compared with the previous row's to tell exact repeats from
    two different rows for one time; ``lines`` gives the file line of (time-ordered) row
    ``k``. Returns the mask of repeating rows (the first of each time is not one) and the
    :class:`RepeatedTimes` report.
    """
    t = np.asarray(t, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64).reshape(t.shape[0], -1)
    repeat = np.zeros(t.shape[0], dtype=bool)
    if t.shape[0] < 2:
        return repeat, RepeatedTimes()
    repeat[1:] = t[1:] == t[:-1]
    if not repeat.any():
        return repeat, RepeatedTimes()
    differ = np.zeros_like(repeat)
    differ[1:] = repeat[1:] & (v[1:] != v[:-1]).any(axis=1)
    where = np.flatnonzero(differ if differ.any() else repeat)
    k = int(where[0])
    return repeat, RepeatedTimes(
        int(repeat.sum()), int(differ.sum()), _line(lines, k), _line(lines, k - 1), float(t[k])
    )
