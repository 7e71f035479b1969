"""The Freiburg ``.relations`` format: ``t1 t2 x y z roll pitch yaw`` per line."""

from __future__ import annotations

import numpy as np

from relation_metric.errors import InputError
from relation_metric.groups import SE3
from relation_metric.relations import RelationSet
from slamrel.formats.text import NUMBER_FORMAT, PathLike, read_numeric_table, write_text_atomic

_REL_COLUMNS = ("t1", "t2", "x", "y", "z", "roll", "pitch", "yaw")

__all__ = ["read_relations", "write_relations"]


def read_relations(path: PathLike) -> RelationSet:
    """Read a Freiburg ``.relations`` file: ``t1 t2 x y z roll pitch yaw`` per line.

    ``#`` lines are comments; runs of blanks separate fields; ``t2 < t1`` is allowed.
    The planar part ``[x, y, yaw]`` becomes ``delta``; ``[z, roll, pitch]`` is kept in
    ``out_of_plane``; :meth:`RelationSet.lifted` makes 6-DoF relations of them (the CLI and
    :func:`~relation_metric.evaluate.evaluate` do so when any of them is not zero).
    """
    values, _ = read_numeric_table(
        path, columns=_REL_COLUMNS, describe="a Freiburg .relations file"
    )
    return RelationSet(
        values[:, 0],
        values[:, 1],
        values[:, [2, 3, 7]],
        key="time",
        out_of_plane=values[:, [4, 5, 6]],
    )


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
