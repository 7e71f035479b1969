"""Landmark map files (landmark CSV, g2o ``VERTEX_XY``, MRCLAM landmarks): read and write.

Read into and written from :class:`landmark_graph.maps.LandmarkMap`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from landmark_graph.maps import LandmarkMap
from relation_metric.checks import check_covariances
from relation_metric.errors import InputError
from relation_metric.trajectory import check_coordinates
from slamrel.formats.landmark_csv import read_landmark_csv, write_landmark_csv
from slamrel.formats.text import (
    PathLike,
    parse_float,
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
    return _build(values[:, 0], values[:, 1:3], cov, src.path, lines)


def _build(ids, xy, cov, path, line_of) -> LandmarkMap:  # type: ignore[no-untyped-def]
    ids = np.asarray(ids)
    check_coordinates(np.asarray(xy), what="landmark", path=path, line_of=line_of)
    bad = np.flatnonzero((ids != np.round(ids)) | (np.abs(ids) > 2.0**53))
    if bad.size:
        raise InputError(
            "landmark id must be an integer", path=path, line=int(line_of(int(bad[0])))
        )
    uniq, first, counts = np.unique(ids, return_index=True, return_counts=True)
    if (counts > 1).any():
        dup = uniq[counts > 1][0]
        k = int(np.flatnonzero(ids == dup)[1])
        before = int(line_of(int(first[uniq == dup][0])))
        raise InputError(
            f"duplicate landmark id {int(dup)} (first on line {before})",
            path=path,
            line=int(line_of(k)),
        )
    if cov is not None:
        check_covariances(
            cov,
            path=path,
            lines=line_of,
            what=lambda k: f"landmark {int(ids[k])}: covariance",
            allow_unknown=True,
        )
    return LandmarkMap(ids.astype(np.int64), xy, cov)


def _read_csv_map(src) -> LandmarkMap:  # type: ignore[no-untyped-def]
    t = read_landmark_csv(
        src.path, id_columns=("landmark", "id", "subject"), source=src, describe="a landmark map"
    )
    cov = t.cov
    if cov is not None and np.isnan(cov).all():
        cov = None  # no landmark has a covariance
    return LandmarkMap(t.ids, t.xy, cov)


def _read_g2o_map(src) -> LandmarkMap:  # type: ignore[no-untyped-def]
    ids, xy, lines = [], [], []
    for number, text in src.data_lines():
        f = text.split()
        if f[0] != "VERTEX_XY":
            continue
        if len(f) != 4:
            raise InputError(
                f"VERTEX_XY: expected 4 fields, got {len(f)}", path=src.path, line=number
            )
        vals = [
            parse_float(t, source=src, line=number, what=w) for t, w in zip(f[1:], ("id", "x", "y"))
        ]
        ids.append(vals[0])
        xy.append(vals[1:])
        lines.append(number)
    return _build(
        np.asarray(ids), np.asarray(xy).reshape(-1, 2), None, src.path, lambda k: lines[k]
    )


MAP_FORMATS = ("csv", "g2o", "mrclam")


def write_map(path: PathLike, m: LandmarkMap, *, format: str = "csv") -> None:
    """Write ``m`` atomically in one of :data:`MAP_FORMATS`.

    * ``csv``: ``landmark,x,y[,cxx,cxy,cyy]`` (the bundle's ``map.csv``; without covariances
      also its ``landmarks_groundtruth.csv``); unknown (NaN) covariances are left empty;
    * ``g2o``: ``VERTEX_XY id x y`` lines (covariances are not part of the record);
    * ``mrclam``: ``subject x y σx σy`` with a ``#`` header; needs diagonal covariances (or
      none: σ written as 0).

    Numbers are written with 17 significant digits (exact round trip).
    """
    n = len(m)
    if format == "csv":
        write_landmark_csv(path, m.ids, m.xy, m.cov)
        return
    if format == "g2o":
        text = ("VERTEX_XY %d %.17g %.17g\n" * n) % _flat(m.ids, m.xy)
    elif format == "mrclam":
        sd = np.zeros((n, 2))
        if m.cov is not None:
            if np.any(m.cov[:, 0, 1] != 0) or np.any(m.cov[:, 1, 0] != 0):
                raise InputError("the MRCLAM format holds only diagonal covariances", path=path)
            sd = np.sqrt(np.column_stack((m.cov[:, 0, 0], m.cov[:, 1, 1])))
        text = "# Subject #    x [m]    y [m]    x std-dev [m]    y std-dev [m]\n" + (
            "%d\t%.17g\t%.17g\t%.17g\t%.17g\n" * n
        ) % _flat(m.ids, m.xy, sd)
    else:
        raise InputError(f"unknown map format {format!r}, expected one of {MAP_FORMATS}")
    write_text_atomic(Path(path), text)


def _flat(ids: NDArray[np.int64], *cols: NDArray[np.float64]) -> tuple[object, ...]:
    """Row-major values of ``ids`` and ``cols`` for %-formatting (ids stay Python ints)."""
    rows = np.column_stack((ids.astype(object), *(np.asarray(c, dtype=object) for c in cols)))
    return tuple(rows.ravel().tolist())
