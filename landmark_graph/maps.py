"""Landmark maps and their file formats.

Formats: the SLAM result bundle's ``map.csv`` (``landmark,x,y[,cxx,cxy,cyy]``) and
``landmarks_groundtruth.csv`` (``landmark,x,y``); MRCLAM ``Landmark_Groundtruth.dat``
(``subject x y σx σy``, ``#`` headers, tabs and spaces); g2o ``VERTEX_XY id x y`` (other g2o
records are skipped and counted). Readers are strict: NaN coordinates, duplicate ids and an
empty map are errors naming the file (and line).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relation_metric.errors import InputError
from relation_metric.textio import (
    PathLike,
    parse_float,
    read_numeric_table,
    read_source,
    write_text_atomic,
)
from relation_metric.trajectory import readonly

__all__ = ["LandmarkMap", "read_map", "write_map"]


@dataclass(frozen=True)
class LandmarkMap:
    """M landmarks ``w_p_l`` with integer ids and optional 2 × 2 covariances.

    Parameters
    ----------
    ids : array_like of int, shape (M,)
        Unique.
    xy : array_like, shape (M, 2)
        Finite positions.
    cov : array_like, shape (M, 2, 2), optional
    """

    ids: NDArray[np.int64]
    xy: NDArray[np.float64]
    cov: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        ids = np.asarray(self.ids)
        xy = np.asarray(self.xy, dtype=np.float64).reshape(-1, 2)
        if ids.shape != (xy.shape[0],):
            raise InputError(f"ids must have shape ({xy.shape[0]},), got {ids.shape}")
        if np.any(ids != np.round(ids)):
            raise InputError("landmark ids must be integers")
        if not np.isfinite(xy).all():
            k = int(np.flatnonzero(~np.isfinite(xy).all(axis=1))[0])
            raise InputError(f"landmark {int(ids[k])} has a non-finite position {xy[k].tolist()}")
        uniq, counts = np.unique(ids, return_counts=True)
        if (counts > 1).any():
            raise InputError(f"duplicate landmark id {int(uniq[counts > 1][0])}")
        object.__setattr__(self, "ids", readonly(ids, np.int64))
        object.__setattr__(self, "xy", readonly(xy))
        if self.cov is not None:
            cov = np.asarray(self.cov, dtype=np.float64)
            if cov.shape != (xy.shape[0], 2, 2):
                raise InputError(f"cov must have shape ({xy.shape[0]}, 2, 2), got {cov.shape}")
            object.__setattr__(self, "cov", readonly(cov))

    def __len__(self) -> int:
        return int(self.ids.shape[0])

    def subset(self, index: ArrayLike) -> LandmarkMap:
        """The landmarks at ``index`` (rows)."""
        k = np.asarray(index)
        return LandmarkMap(self.ids[k], self.xy[k], None if self.cov is None else self.cov[k])


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
        cov = np.zeros((values.shape[0], 2, 2))
        cov[:, 0, 0] = values[:, 3] ** 2
        cov[:, 1, 1] = values[:, 4] ** 2
    return _build(values[:, 0], values[:, 1:3], cov, src.path, lines)


def _build(ids, xy, cov, path, line_of) -> LandmarkMap:  # type: ignore[no-untyped-def]
    ids = np.asarray(ids)
    bad = np.flatnonzero(ids != np.round(ids))
    if bad.size:
        raise InputError(
            "landmark id must be an integer", path=path, line=int(line_of(int(bad[0])))
        )
    uniq, first, counts = np.unique(ids, return_index=True, return_counts=True)
    if (counts > 1).any():
        dup = uniq[counts > 1][0]
        k = int(np.flatnonzero(ids == dup)[1])
        raise InputError(f"duplicate landmark id {int(dup)}", path=path, line=int(line_of(k)))
    return LandmarkMap(ids.astype(np.int64), xy, cov)


def _read_csv_map(src) -> LandmarkMap:  # type: ignore[no-untyped-def]
    rows = list(src.data_lines())
    header = [h.strip().lower() for h in rows[0][1].split(",")]
    name = header[0]
    for need in (name, "x", "y"):
        if need not in header:
            raise InputError(f"CSV header lacks '{need}'", path=src.path, line=rows[0][0])
    has_cov = all(c in header for c in ("cxx", "cxy", "cyy"))
    idx = [header.index(c) for c in (name, "x", "y")]
    cidx = [header.index(c) for c in ("cxx", "cxy", "cyy")] if has_cov else []
    ids, xy, cov, lines = [], [], [], []
    for number, text in rows[1:]:
        f = [v.strip() for v in text.split(",")]
        if len(f) != len(header):
            if src.is_last_line(number):
                src.warn_truncated(number, f"expected {len(header)} fields")
                break
            raise InputError(
                f"expected {len(header)} fields, got {len(f)}", path=src.path, line=number
            )
        vals = [
            parse_float(f[i], source=src, line=number, what=c)
            for i, c in zip(idx, (name, "x", "y"))
        ]
        ids.append(vals[0])
        xy.append(vals[1:])
        if has_cov:
            if all(f[i] == "" for i in cidx):
                cov.append([np.nan] * 3)
            else:
                cov.append(
                    [
                        parse_float(f[i], source=src, line=number, what=c)
                        for i, c in zip(cidx, ("cxx", "cxy", "cyy"))
                    ]
                )
        lines.append(number)
    c = None
    if has_cov and cov and np.isfinite(np.asarray(cov)).all():
        a = np.asarray(cov)
        c = np.stack(
            (np.column_stack((a[:, 0], a[:, 1])), np.column_stack((a[:, 1], a[:, 2]))), axis=1
        )
    return _build(np.asarray(ids), np.asarray(xy).reshape(-1, 2), c, src.path, lambda k: lines[k])


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


def write_map(path: PathLike, m: LandmarkMap) -> None:
    """Write ``landmark,x,y[,cxx,cxy,cyy]`` CSV atomically."""
    if m.cov is None:
        rows = np.column_stack((m.ids, m.xy))
        text = "landmark,x,y\n" + ("%d,%.9f,%.9f\n" * len(m)) % tuple(rows.ravel().tolist())
    else:
        rows = np.column_stack((m.ids, m.xy, m.cov[:, 0, 0], m.cov[:, 0, 1], m.cov[:, 1, 1]))
        text = "landmark,x,y,cxx,cxy,cyy\n" + ("%d" + ",%.9g" * 5 + "\n") * len(m) % tuple(
            rows.ravel().tolist()
        )
    write_text_atomic(Path(path), text)
