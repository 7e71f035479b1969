"""The landmark CSV (``landmark,x,y[,cxx,cxy,cyy]``): one reader, one writer.

Used for a SLAM result bundle's ``map.csv`` and ``landmarks_groundtruth.csv``, the maps of
``map-compare`` and the ``landmarks.csv`` of ``solve``, so that the same file gets the same
verdict everywhere. Rules (on top of :func:`slamrel.formats.text.read_csv_table`):

* the covariance columns ``cxx,cxy,cyy`` come all three or none; a row leaves all three
  empty (unknown covariance, NaN) or gives all three;
* the landmarks pass :func:`relation_metric.landmarks.check_landmarks` (integer, unique ids;
  finite positions; symmetric positive semi-definite covariances), at their lines.

The writer uses ``%d`` for ids and :data:`~slamrel.formats.text.NUMBER_FORMAT` (``%.17g``,
an exact round trip) for numbers; unknown (NaN) covariances are written as empty cells.
"""

from __future__ import annotations

import os
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relation_metric.errors import InputError
from relation_metric.landmarks import check_landmarks
from slamrel.formats.text import (
    NUMBER_FORMAT,
    PathLike,
    SourceText,
    read_csv_id_column,
    read_csv_table,
    read_source,
    write_csv_table,
)

__all__ = ["LandmarkTable", "read_landmark_csv", "write_landmark_csv"]

_COV = ("cxx", "cxy", "cyy")


class LandmarkTable(NamedTuple):
    """A landmark CSV as arrays.

    Attributes
    ----------
    ids : ndarray of int, shape (M,)
    xy : ndarray, shape (M, 2)
    cov : ndarray, shape (M, 2, 2), or None
        None when the file has no covariance columns; NaN blocks where a row left them empty.
    lines : ndarray of int, shape (M,)
        The 1-based line of each landmark.
    """

    ids: NDArray[np.int64]
    xy: NDArray[np.float64]
    cov: NDArray[np.float64] | None
    lines: NDArray[np.int64]


def read_landmark_csv(
    path: PathLike,
    *,
    id_columns: tuple[str, ...] = ("landmark",),
    covariance: bool = True,
    source: SourceText | None = None,
    describe: str = "a landmark CSV",
) -> LandmarkTable:
    """Read and check a landmark CSV (see the module docstring).

    Parameters
    ----------
    path : str or PathLike
    id_columns : tuple of str
        Accepted names of the id column (the first present one is read).
    covariance : bool
        Read the ``cxx,cxy,cyy`` columns when present (else they are ignored).
    source : SourceText, optional
        Already-read text of ``path``.
    describe : str
        What the file is, for messages.
    """
    optional = _COV if covariance else ()
    src = read_source(path) if source is None else source
    table = read_csv_table(
        path,
        required=(id_columns, "x", "y"),
        optional=optional,
        empty_ok=_COV,
        describe=describe,
        source=src,
    )
    name = src.path
    cols, lines = table
    id_name = next(c for c in id_columns if c in cols)
    # the ids as written (int64 from the text, never through float64: 2**53 + 1 stays itself)
    cols[id_name] = read_csv_id_column(src, id_name, lines)[0]  # type: ignore[assignment]
    xy = np.column_stack((cols["x"], cols["y"]))
    present = [c for c in _COV if c in cols]
    cov = None
    if present and len(present) != 3:
        raise InputError(
            f"covariance columns: expected all of cxx,cxy,cyy or none, got {','.join(present)}",
            path=name,
        )
    if present:
        cxx, cxy, cyy = (cols[c] for c in _COV)
        given = ~np.isnan(np.column_stack((cxx, cxy, cyy)))
        partial = np.flatnonzero(given.any(axis=1) & ~given.all(axis=1))
        if partial.size:
            raise InputError(
                "cxx, cxy, cyy: expected all three or none (an unknown covariance)",
                path=name,
                line=int(lines[partial[0]]),
            )
        cov = np.empty((xy.shape[0], 2, 2))
        cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 0], cov[:, 1, 1] = cxx, cxy, cxy, cyy
    ids = check_landmarks(
        cols[id_name], xy, cov, path=os.fspath(name), lines=lines, id_column=id_name
    )
    return LandmarkTable(ids, xy, cov, lines)


def write_landmark_csv(
    path: PathLike,
    ids: ArrayLike,
    xy: ArrayLike,
    cov: ArrayLike | None = None,
) -> None:
    """Write a landmark CSV atomically (ids ``%d``, numbers ``NUMBER_FORMAT``: exact round trip).

    Parameters
    ----------
    ids : array_like of int, shape (M,)
    xy : array_like, shape (M, 2)
    cov : array_like, shape (M, 2, 2), optional
        Written as ``cxx,cxy,cyy``; NaN (unknown) blocks as empty cells.
    """
    i = np.asarray(ids)
    p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    header = ["landmark", "x", "y"]
    columns = [i, p[:, 0], p[:, 1]]
    if cov is not None:
        c = np.asarray(cov, dtype=np.float64).reshape(-1, 2, 2)
        header += list(_COV)
        columns += [c[:, 0, 0], c[:, 0, 1], c[:, 1, 1]]
    write_csv_table(path, header, columns, ["%d"] + [NUMBER_FORMAT] * (len(header) - 1))
