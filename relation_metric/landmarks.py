"""The one validation of a landmark set: ids, positions and 2 × 2 covariances.

Every place that takes landmarks — the landmark CSV reader, the other map readers (MRCLAM
``.dat``, g2o ``VERTEX_XY``), the :class:`landmark_graph.maps.LandmarkMap` record and the
:class:`recovery.bundle.Bundle` record (its map and its landmark ground truth) — calls
:func:`check_landmarks`, so that the same landmarks get the same verdict and the same message
everywhere. From a file, ``path`` and ``lines`` name the file and the landmark's line; built
in memory, the message names the landmark (or its row).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relation_metric.arrays import PathLike
from relation_metric.checks import check_covariances
from relation_metric.errors import InputError
from relation_metric.ids import first_repeat, integer_ids
from relation_metric.trajectory import check_coordinates

__all__ = ["check_landmarks"]

Lines = Sequence[int] | NDArray[np.int64] | Callable[[int], int]


def check_landmarks(
    ids: ArrayLike,
    xy: ArrayLike,
    cov: ArrayLike | None = None,
    *,
    path: PathLike | None = None,
    lines: Lines | None = None,
    id_column: str = "landmark",
    allow_unknown: bool = True,
) -> NDArray[np.int64]:
    """Check M landmarks and return their ids as int64; the first defect raises.

    Rules, in this order:

    1. shapes: ``ids`` (M,), ``xy`` (M, 2), ``cov`` (M, 2, 2);
    2. every id is an integer of at most 2⁵³ in magnitude
       (:func:`relation_metric.ids.integer_ids`; ``column '<id_column>': expected an integer
       id``);
    3. every position is finite and within :data:`relation_metric.trajectory.MAX_COORDINATE`;
    4. ids are unique (the smallest repeated id is named, at its second row:
       ``duplicate landmark id 7 (first on line 3); expected unique ids``);
    5. every covariance is symmetric positive semi-definite
       (:func:`relation_metric.checks.check_covariances`, ``landmark 7: covariance: ...``);
       with ``allow_unknown`` an all-NaN block (a covariance the file left empty) passes.

    Parameters
    ----------
    ids : array_like, shape (M,)
    xy : array_like, shape (M, 2)
    cov : array_like, shape (M, 2, 2), optional
    path : str or PathLike, optional
        The file the landmarks came from, for messages.
    lines : sequence of int or callable, optional
        The 1-based file line of each landmark (``lines[k]`` or ``lines(k)``).
    id_column : str
        The id column's name in the file, for messages.
    allow_unknown : bool
        Accept all-NaN covariance blocks (unknown covariances).

    Returns
    -------
    ndarray of int64, shape (M,)
    """
    raw_ids = np.asarray(ids)
    p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    m = p.shape[0]
    if raw_ids.shape != (m,):
        raise InputError(f"ids must have shape ({m},), got {raw_ids.shape}", path=path)

    line_of = _line_function(lines)

    def line(k: int) -> int | None:
        return None if line_of is None else line_of(k)

    if raw_ids.dtype.kind == "f":
        nan = np.flatnonzero(~np.isfinite(raw_ids))
        if nan.size:
            k = int(nan[0])
            raise InputError(
                f"column '{id_column}': expected an integer id, got {float(raw_ids[k]):.17g}",
                path=path,
                line=line(k),
            )
    out = integer_ids(raw_ids, lines, path, id_column)
    bad = np.flatnonzero(~np.isfinite(p).all(axis=1))
    if bad.size:
        k = int(bad[0])
        raise InputError(
            f"landmark {int(out[k])} has a non-finite position {p[k].tolist()}; expected "
            "finite coordinates",
            path=path,
            line=line(k),
        )
    check_coordinates(
        p,
        what="landmark row" if lines is None else "landmark",
        path=None if path is None else str(path),
        line_of=line_of,
    )
    repeat = first_repeat(out)
    if repeat is not None:
        first, k = repeat
        where = "" if lines is None else f" (first on line {line(first)})"
        raise InputError(
            f"duplicate landmark id {int(out[k])}{where}; expected unique ids",
            path=path,
            line=line(k),
        )
    if cov is not None:
        c = np.asarray(cov, dtype=np.float64)
        if c.shape != (m, 2, 2):
            raise InputError(f"cov must have shape ({m}, 2, 2), got {c.shape}", path=path)
        check_covariances(
            c,
            path=path,
            lines=lines,
            what=lambda k: f"landmark {int(out[k])}: covariance",
            allow_unknown=allow_unknown,
        )
    return out


def _line_function(lines: Lines | None) -> Callable[[int], int] | None:
    """Row → 1-based file line, from a sequence or a callable (``None`` stays ``None``)."""
    if lines is None:
        return None
    if callable(lines):
        fn = lines
        return lambda k: int(fn(k))
    seq = lines
    return lambda k: int(seq[k])
