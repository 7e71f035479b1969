"""Integer ids: read from a float column (:func:`integer_ids`) and looked up (:func:`rows_of`).

Landmark maps, pose graphs, bundles and importers all name things by integer ids and need
the row holding each id that another table refers to. :func:`rows_of` is that lookup,
vectorised (a stable ``argsort`` when the ids are not already sorted, then one
``searchsorted``); a missing id gets row −1, so the caller can raise its own
:class:`~relation_metric.errors.InputError` at the referring line (see
:func:`first_missing`) or keep the mask.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relation_metric.arrays import PathLike
from relation_metric.errors import InputError

__all__ = [
    "integer_ids",
    "rows_of",
    "first_missing",
    "first_repeat",
    "refuse_repeated_ids",
    "refuse_self_loops",
]

_MAX_EXACT_ID = 2.0**53  # from it on a double no longer holds every integer (2**53 + 1 rounds)


def integer_ids(
    values: ArrayLike,
    lines: Sequence[int] | NDArray[np.int64] | Callable[[int], int] | None,
    path: PathLike | None,
    column: str,
) -> NDArray[np.int64]:
    """``values`` as int64 ids; a non-integer (or out-of-range) value raises at its line.

    Parameters
    ----------
    values : array_like, shape (N,)
        Ids as read from a text file (floats); an integer array is taken as it is.
    lines : sequence of int or callable, optional
        ``lines[k]`` (or ``lines(k)``) is the 1-based file line of value ``k``.
    path : str or PathLike, optional
        The file, for the message.
    column : str
        The column's name: ``column 'landmark': expected an integer id, got 2.5``.

    Returns
    -------
    ndarray of int64, shape (N,)
        NaN entries (empty ``empty_ok`` cells) become 0 (the caller masks them).
    """
    raw = np.asarray(values)
    if raw.dtype.kind in "iub":
        return raw.astype(np.int64)
    v = raw.astype(np.float64)
    finite = np.isfinite(v)
    bad = np.flatnonzero(finite & ((v != np.round(v)) | (np.abs(v) >= _MAX_EXACT_ID)))
    if bad.size:
        k = int(bad[0])
        line = None if lines is None else int(lines(k) if callable(lines) else lines[k])
        beyond = ""
        if v[k] == np.round(v[k]):
            # 2**53 itself may be 2**53 + 1 rounded: refuse it rather than change an id
            beyond = (
                " below 2**53 in magnitude (this reader holds ids as float64, which rounds "
                "larger ones: 2**53 + 1 would become 2**53)"
            )
        raise InputError(
            f"column '{column}': expected an integer id{beyond}, got {float(v[k]):.17g}",
            path=path,
            line=line,
        )
    return np.where(finite, v, 0).astype(np.int64)


def rows_of(ids: ArrayLike, wanted: ArrayLike) -> NDArray[np.int64]:
    """Row of ``ids`` holding each of ``wanted``; −1 where the id is not in ``ids``.

    Parameters
    ----------
    ids : array_like, shape (N,)
        The id column (any order; with repeated ids the first row holding one is returned).
    wanted : array_like, any shape
        Ids to look up.

    Returns
    -------
    ndarray of int64, the shape of ``wanted``
        ``rows[k]`` with ``ids[rows[k]] == wanted[k]``, or −1.

    Examples
    --------
    >>> rows_of([7, 3, 9], [9, 4, 7]).tolist()
    [2, -1, 0]
    """
    ids = np.asarray(ids)
    wanted = np.asarray(wanted)
    if ids.ndim != 1:
        raise ValueError(f"ids must be one column (N,), got shape {ids.shape}")
    if ids.size == 0:
        return np.full(wanted.shape, -1, dtype=np.int64)
    order = None
    keys = ids
    if not bool(np.all(ids[1:] >= ids[:-1])):
        order = np.argsort(ids, kind="stable")
        keys = ids[order]
    pos = np.minimum(np.searchsorted(keys, wanted), keys.size - 1)
    found = keys[pos] == wanted
    rows = pos if order is None else order[pos]
    return np.where(found, rows, -1).astype(np.int64)


def first_missing(rows: NDArray[np.int64]) -> int | None:
    """Flat index of the first −1 in ``rows`` (the first unknown id), or ``None``."""
    missing = np.flatnonzero(np.asarray(rows).ravel() < 0)
    return int(missing[0]) if missing.size else None


def first_repeat(
    ids: NDArray[np.int64], *, tiebreak: NDArray[np.int64] | None = None
) -> tuple[int, int] | None:
    """The first repeated id: ``(earlier, later)`` positions of its first two occurrences.

    "First" is the smallest repeated id; of its occurrences the earliest two in ``tiebreak``
    order (e.g. line numbers), or in array order without it. ``None`` if all ids differ.
    """
    order = np.argsort(ids, kind="stable") if tiebreak is None else np.lexsort((tiebreak, ids))
    dup = np.flatnonzero(np.diff(ids[order]) == 0)
    if not dup.size:
        return None
    return int(order[dup[0]]), int(order[dup[0] + 1])


def refuse_repeated_ids(
    ids: NDArray[np.int64],
    lines: NDArray[np.int64],
    path: PathLike | None,
    what: str,
) -> None:
    """Raise at the second definition of the first repeated id of ``ids`` (``lines[k]`` is
    the file line of ``ids[k]``): ``vertex id 5 is defined twice (first on line 2)``. An id
    defined twice would silently keep one of its two values."""
    repeat = first_repeat(ids, tiebreak=lines)
    if repeat is not None:
        first, k = repeat
        raise InputError(
            f"{what} {int(ids[k])} is defined twice (first on line {int(lines[first])})",
            path=path,
            line=int(lines[k]),
        )


def refuse_self_loops(
    ends: ArrayLike,
    lines: Sequence[int] | NDArray[np.int64],
    path: PathLike | None,
    record: str,
) -> None:
    """Raise at the first edge of ``ends`` (E, 2) from a vertex to itself, naming the
    ``record`` keyword and its file line (``lines[k]``): a self-loop constrains nothing but
    its own measurement, which a solve would fit as zero motion."""
    e = np.asarray(ends)
    loop = np.flatnonzero(e[:, 0] == e[:, 1]) if e.size else np.empty(0, np.int64)
    if loop.size:
        k = int(loop[0])
        raise InputError(
            f"{record} from vertex {int(e[k, 0])} to itself ({loop.size} such edge(s)); "
            "expected an edge between two different poses (a self-loop constrains nothing "
            "but its own measurement, which the solve would fit as zero motion)",
            path=path,
            line=int(lines[k]),
        )
