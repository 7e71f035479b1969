"""Id lookup: the row of each wanted id in an id column (one home for every table).

Landmark maps, pose graphs, bundles and importers all name things by integer ids and need
the row holding each id that another table refers to. :func:`rows_of` is that lookup,
vectorised (a stable ``argsort`` when the ids are not already sorted, then one
``searchsorted``); a missing id gets row −1, so the caller can raise its own
:class:`~relation_metric.errors.InputError` at the referring line (see
:func:`first_missing`) or keep the mask.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["rows_of", "first_missing"]


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
