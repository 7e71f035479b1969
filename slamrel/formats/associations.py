"""Landmark association files (``estimated,reference`` CSV): read and write."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from landmark_graph.landmark_association import Association, _finish
from landmark_graph.maps import LandmarkMap
from relation_metric.errors import InputError
from relation_metric.ids import first_missing, first_repeat, rows_of
from slamrel.formats.text import (
    PathLike,
    read_csv_id_column,
    read_csv_table,
    read_source,
    write_text_atomic,
)

__all__ = ["read_association_csv", "write_association_csv"]


def read_association_csv(path: PathLike, est: LandmarkMap, ref: LandmarkMap) -> Association:
    """``estimate,reference`` id pairs (header line required); unknown ids are errors."""
    src = read_source(path)
    table = read_csv_table(
        path, required=("estimate", "reference"), describe="a landmark association", source=src
    )
    name = src.path
    lines = table.lines
    # ids as written: int64 from the text, never through float64
    a = read_csv_id_column(src, "estimate", lines)[0]
    b = read_csv_id_column(src, "reference", lines)[0]
    er = _rows_of(est.ids, a, lines, name, "estimated")
    rr = _rows_of(ref.ids, b, lines, name, "reference")
    for rows, ids, what in ((er, a, "estimated"), (rr, b, "reference")):
        repeat = first_repeat(rows)
        if repeat is not None:
            first, k = repeat
            raise InputError(
                f"{what} landmark {int(ids[k])} is associated twice (first on line "
                f"{int(lines[first])})",
                path=name,
                line=int(lines[k]),
            )
    return _finish(est, ref, er, rr)


def _rows_of(
    ids: NDArray[np.int64],
    wanted: NDArray[np.int64],
    lines: NDArray[np.int64],
    path: str,
    what: str,
) -> NDArray[np.int64]:
    """Rows of ``ids`` holding each of ``wanted``; an unknown id raises at its line."""
    rows = rows_of(ids, wanted)
    k = first_missing(rows)
    if k is not None:
        raise InputError(
            f"unknown {what} landmark id {int(wanted[k])}", path=path, line=int(lines[k])
        )
    return rows


def write_association_csv(
    path: PathLike, assoc: Association, est: LandmarkMap, ref: LandmarkMap
) -> None:
    """Write the matched pairs as ``estimate,reference`` ids (what
    :func:`read_association_csv` reads), atomically; missed and spurious landmarks are listed
    in ``#`` comment lines so that a user can edit them into pairs."""
    missed = " ".join(map(str, ref.ids[assoc.missed].tolist()))
    spurious = " ".join(map(str, est.ids[assoc.spurious].tolist()))
    head = f"# missed reference ids: {missed}\n# spurious estimate ids: {spurious}\n"
    head += "estimate,reference\n"
    pairs = np.column_stack((est.ids[assoc.estimate_rows], ref.ids[assoc.reference_rows]))
    write_text_atomic(path, head + ("%d,%d\n" * pairs.shape[0]) % tuple(pairs.ravel().tolist()))
