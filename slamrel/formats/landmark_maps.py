"""Landmark map files: read into and written from :class:`landmark_graph.maps.LandmarkMap`.

Formats: the SLAM result bundle's ``map.csv`` (``landmark,x,y[cxx,cxy,cyy]``) and
``landmarks_groundtruth.csv`` (``landmark,x,y``); MRCLAM ``Landmark_Groundtruth.dat``
(``subject x y σx σy``, ``#`` headers, tabs and spaces); g2o ``VERTEX_XY id x y`` (other g2o
records are skipped). Readers are strict: NaN coordinates, duplicate ids, a covariance that is
not symmetric positive semi-definite and an empty map are errors naming the file (and line).
Writers (:func:`write_map`) speak the same formats, with 17 significant digits, so that a
written map reads back bit for bit.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from landmark_graph.maps import LandmarkMap
from relation_metric.errors import InputError
from relation_metric.landmarks import Lines, check_landmarks
from slamrel.formats.g2o import format_g2o_records, read_g2o_records
from slamrel.formats.landmark_csv import read_landmark_csv, write_landmark_csv
from slamrel.formats.text import (
    NUMBER_FORMAT,
    PathLike,
    SourceText,
    read_numeric_table,
    read_source,
    write_text_atomic,
)

__all__ = ["MAP_FORMATS", "read_map", "write_map"]


def _check_nonempty(m: LandmarkMap, path: PathLike) -> LandmarkMap:
    if len(m) == 0:
        raise InputError("empty map: expected at least one landmark", path=path)
    return m


def read_map(path: PathLike) -> LandmarkMap:
    """Read a landmark map; the format is recognised from the content."""
    src = read_source(path)
    first = next(src.data_lines(), (0, ""))[1]
    head = first.split(",")[0].strip().lower()
    if "," in first and head in ("landmark", "id", "subject"):
        return _check_nonempty(_read_csv_map(src), src.path)
    if first.startswith(("VERTEX", "EDGE", "FIX")):
        return _check_nonempty(_read_g2o_map(src), src.path)
    if not first:
        raise InputError("empty map: expected at least one landmark", path=src.path)
    ncol = len(first.split())
    if ncol not in (3, 5):
        raise InputError(
            "cannot recognise the map format: expected a CSV with a landmark,x,y header, "
            "g2o VERTEX_XY lines, or 'id x y' / MRCLAM 'subject x y sx sy' columns",
            path=src.path,
        )
    cols = ("subject", "x", "y", "sx", "sy")[:ncol] if ncol == 5 else ("id", "x", "y")
    values, lines = read_numeric_table(path, columns=cols, describe="a landmark map", source=src)
    cov = None
    if ncol == 5:
        sd = values[:, 3:5]
        bad = np.flatnonzero((sd < 0).any(axis=1) | (sd > 1e150).any(axis=1))
        if bad.size:
            k = int(bad[0])
            raise InputError(
                f"standard deviations {float(sd[k, 0]):g}, {float(sd[k, 1]):g}: expected "
                "non-negative numbers (metres)",
                path=src.path,
                line=int(lines(k)),
            )
        cov = np.zeros((values.shape[0], 2, 2))
        cov[:, 0, 0] = sd[:, 0] ** 2
        cov[:, 1, 1] = sd[:, 1] ** 2
    return _build(values[:, 0], values[:, 1:3], cov, src.path, lines, cols[0])


def _build(
    ids: NDArray[np.float64] | NDArray[np.int64],
    xy: NDArray[np.float64],
    cov: NDArray[np.float64] | None,
    path: str,
    line_of: Lines,
    id_column: str,
) -> LandmarkMap:
    """The map of a file's rows, checked at their lines (:func:`check_landmarks`)."""
    checked = check_landmarks(ids, xy, cov, path=path, lines=line_of, id_column=id_column)
    return LandmarkMap(checked, xy, cov)


def _read_csv_map(src: SourceText) -> LandmarkMap:
    t = read_landmark_csv(
        src.path, id_columns=("landmark", "id", "subject"), source=src, describe="a landmark map"
    )
    cov = t.cov
    if cov is not None and np.isnan(cov).all():
        cov = None  # no landmark has a covariance
    return LandmarkMap(t.ids, t.xy, cov)


def _read_g2o_map(src: SourceText) -> LandmarkMap:
    """``VERTEX_XY`` records (:func:`slamrel.formats.g2o.read_g2o_records`); others skipped."""
    ids: dict[str, NDArray[np.int64]] = {}
    recs = read_g2o_records(src.path, ("VERTEX_XY",), skipped=Counter(), source=src, ids=ids)
    values, lines = recs["VERTEX_XY"]
    return _build(ids["VERTEX_XY"][:, 0], values[:, 1:3], None, src.path, lines, "VERTEX_XY id")


MAP_FORMATS = ("csv", "g2o", "mrclam")


def write_map(path: PathLike, m: LandmarkMap, *, format: str = "csv") -> None:
    """Write ``m`` atomically in one of :data:`MAP_FORMATS`.

    * ``csv``: ``landmark,x,y[,cxx,cxy,cyy]`` (the bundle's ``map.csv``; without covariances
      also its ``landmarks_groundtruth.csv``); unknown (NaN) covariances are left empty;
    * ``g2o``: ``VERTEX_XY id x y`` lines (covariances are not part of the record);
    * ``mrclam``: ``subject x y σx σy`` with a ``#`` header; needs diagonal covariances (or
      none: σ written as 0).

    Numbers are written with :data:`~slamrel.formats.text.NUMBER_FORMAT` (exact round trip).
    """
    n = len(m)
    if format == "csv":
        write_landmark_csv(path, m.ids, m.xy, m.cov)
        return
    if format == "g2o":
        text = format_g2o_records("VERTEX_XY", m.ids, m.xy)
    elif format == "mrclam":
        sd = np.zeros((n, 2))
        if m.cov is not None:
            if np.any(m.cov[:, 0, 1] != 0) or np.any(m.cov[:, 1, 0] != 0):
                raise InputError("the MRCLAM format holds only diagonal covariances", path=path)
            sd = np.sqrt(np.column_stack((m.cov[:, 0, 0], m.cov[:, 1, 1])))
        text = "# Subject #    x [m]    y [m]    x std-dev [m]    y std-dev [m]\n" + (
            ("%d" + f"\t{NUMBER_FORMAT}" * 4 + "\n") * n
        ) % _flat(m.ids, m.xy, sd)
    else:
        raise InputError(f"unknown map format {format!r}, expected one of {MAP_FORMATS}")
    write_text_atomic(Path(path), text)


def _flat(ids: NDArray[np.int64], *cols: NDArray[np.float64]) -> tuple[object, ...]:
    """Row-major values of ``ids`` and ``cols`` for %-formatting (ids stay Python ints)."""
    rows = np.column_stack((ids.astype(object), *(np.asarray(c, dtype=object) for c in cols)))
    return tuple(rows.ravel().tolist())
