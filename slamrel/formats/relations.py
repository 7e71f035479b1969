"""The Freiburg ``.relations`` format: ``t1 t2 x y z roll pitch yaw`` per line."""

from __future__ import annotations

from typing import Any

import numpy as np

from relation_metric.errors import InputError
from relation_metric.groups import SE3
from relation_metric.relations import RelationSet
from slamrel.formats.text import NUMBER_FORMAT, PathLike, read_numeric_table, write_text_atomic

_REL_COLUMNS = ("t1", "t2", "x", "y", "z", "roll", "pitch", "yaw")

__all__ = ["read_relations", "write_relations"]


def read_relations(path: PathLike, *, report: dict[str, Any] | None = None) -> RelationSet:
    """Read a Freiburg ``.relations`` file: ``t1 t2 x y z roll pitch yaw`` per line.

    ``#`` lines are comments; runs of blanks separate fields; ``t2 < t1`` is allowed.
    The planar part ``[x, y, yaw]`` becomes ``delta``; ``[z, roll, pitch]`` is kept in
    ``out_of_plane``; :meth:`RelationSet.lifted` makes 6-DoF relations of them (the CLI and
    :func:`~relation_metric.evaluate.evaluate` do so when any of them is not zero).

    Lines that repeat an earlier line's eight numbers exactly are found (the Freiburg files
    hold a few: aces 9, fr079 4, mit-csail 1): all rows are returned, and ``report`` (when
    given) receives ``"duplicates"``, a bool mask of the repeating rows (the first of each
    is not one), and ``"duplicate_lines"``, the file lines ``(earlier, repeat)`` of the first
    repeat (None when there is none). What to do with them is the caller's choice
    (``slamrel evaluate`` drops them, counted, except in the metricevaluator mode, whose C++
    tool counts them twice).
    """
    values, lines = read_numeric_table(
        path, columns=_REL_COLUMNS, describe="a Freiburg .relations file"
    )
    if report is not None:
        report["duplicates"], report["duplicate_lines"] = _repeated_rows(values, lines)
    return RelationSet(
        values[:, 0],
        values[:, 1],
        values[:, [2, 3, 7]],
        key="time",
        out_of_plane=values[:, [4, 5, 6]],
    )


def _repeated_rows(values: np.ndarray, lines: Any) -> tuple[np.ndarray, tuple[int, int] | None]:
    """Mask of rows equal to an earlier row, and the lines of the first such pair."""
    n = values.shape[0]
    repeat = np.zeros(n, dtype=bool)
    if n < 2:
        return repeat, None
    order = np.lexsort(values.T[::-1])  # equal rows adjacent, in file order (stable)
    same = (values[order[1:]] == values[order[:-1]]).all(axis=1)
    repeat[order[1:][same]] = True
    if not same.any():
        return repeat, None
    later = int(np.flatnonzero(repeat)[0])
    pos = int(np.flatnonzero(order == later)[0])
    first = pos
    while first > 0 and same[first - 1]:
        first -= 1
    return repeat, (int(lines(int(order[first]))), int(lines(later)))


def write_relations(path: PathLike, relations: RelationSet) -> None:
    """Write a Freiburg ``.relations`` file atomically (numbers as ``NUMBER_FORMAT``).

    17 significant digits (:data:`~slamrel.formats.text.NUMBER_FORMAT`): times and motions
    read back bit for bit, so relations generated from a trajectory name its timestamps
    exactly.
    """
    if relations.key != "time":
        raise InputError("only time-stamped relations can be written as .relations", path=path)
    if relations.group is SE3:
        p = SE3.parameters(relations.delta)
        delta, oop = p[:, [0, 1, 5]], p[:, 2:5]
    else:
        delta = relations.delta
        given = relations.out_of_plane
        oop = np.zeros((len(relations), 3)) if given is None else given
    rows = np.column_stack((relations.first, relations.second, delta[:, :2], oop, delta[:, 2]))
    fmt = " ".join([NUMBER_FORMAT] * 8) + "\n"
    text = "# t1 t2 x y z roll pitch yaw\n"
    if rows.shape[0]:
        text += fmt * rows.shape[0] % tuple(rows.ravel().tolist())
    write_text_atomic(path, text)
