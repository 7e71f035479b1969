"""TORO's 2-D graph files: ``VERTEX2`` and ``EDGE2``.

``VERTEX2 id x y θ``; ``EDGE2 i j dx dy dθ I_xx I_xy I_yy I_θθ I_xθ I_yθ`` — the
measurement ``x_i⁻¹ ∘ x_j`` as in g2o's ``EDGE_SE2``, but with the information entries in
TORO's own order (``xx xy yy θθ xθ yθ``; g2o's is the row-first upper triangle
``xx xy xθ yy yθ θθ``). The older spellings ``VERTEX`` and ``EDGE`` of the same records are
read too. TORO files hold pose graphs only: writing a graph with landmark factors is an
error, and so is any other record (named with its line).

The record rules are the g2o reader's (:mod:`slamrel.formats.g2o`), from the same shared
functions: ids exact integers within int64 (``VERTEX2 3.5`` is refused, not read as vertex
3; an id beyond 2**53 is re-read from its text, never rounded onto another vertex),
vertex ids unique, every edge end a known vertex and no self-loop, coordinates within
:data:`~relation_metric.trajectory.MAX_COORDINATE`, information matrices symmetric positive
semi-definite — each refused with its file and line.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relation_metric.checks import MAX_INFORMATION, check_covariances
from relation_metric.errors import InputError
from relation_metric.ids import first_missing, refuse_repeated_ids, refuse_self_loops, rows_of
from relation_metric.trajectory import check_coordinates
from slamrel.backends.graph import PoseGraph
from slamrel.formats.text import (
    NUMBER_FORMAT,
    PathLike,
    Records,
    SourceText,
    exact_record_ids,
    read_keyword_records,
    read_source,
    write_text_atomic,
)

__all__ = ["is_toro", "read_toro_graph", "write_toro_graph", "TORO_INFO_ORDER"]

_FIELDS = {"VERTEX2": 5, "EDGE2": 12, "VERTEX": 5, "EDGE": 12}
# (row, column) of each information entry in TORO's order: xx xy yy θθ xθ yθ
TORO_INFO_ORDER = ((0, 0), (0, 1), (1, 1), (2, 2), (0, 2), (1, 2))
_ROWS = np.array([rc[0] for rc in TORO_INFO_ORDER])
_COLS = np.array([rc[1] for rc in TORO_INFO_ORDER])


def is_toro(source: SourceText) -> bool:
    """Whether ``source`` is a TORO graph: its first data line is a ``VERTEX2``/``VERTEX``
    record, or an ``EDGE2``/``EDGE`` record in a file that has ``VERTEX2``/``VERTEX`` records
    (an ``EDGE2`` file without vertices is iSAM text: :func:`slamrel.formats.isam.is_isam`)."""
    for _, text in source.data_lines():
        first = text.split(None, 1)[0]
        if first in ("VERTEX2", "VERTEX"):
            return True
        if first in ("EDGE2", "EDGE"):
            return any(ln.split(None, 1)[:1] in (["VERTEX2"], ["VERTEX"]) for ln in source.lines)
        return False
    return False


def read_toro_graph(path: PathLike) -> tuple[PoseGraph, NDArray[np.int64]]:
    """Read a TORO 2-D graph.

    Returns
    -------
    graph : PoseGraph
        Vertices (increasing id order) as the initial guess; no landmarks.
    pose_ids : ndarray of int, shape (N,)
        The file's vertex ids of the graph's poses.
    """
    src = read_source(path)
    recs = read_keyword_records(path, _FIELDS, source=src)
    vert, vert_lines, ids = _records(recs, src, ("VERTEX2", "VERTEX"), ("id",))
    edge, edge_lines, ends = _records(recs, src, ("EDGE2", "EDGE"), ("vertex 1", "vertex 2"))
    if vert.shape[0] == 0:
        raise InputError("no VERTEX2 records", path=path)
    refuse_repeated_ids(ids[:, 0], vert_lines, src.path, "vertex id")
    check_coordinates(vert[:, 1:3], what="pose", path=src.path, line_of=vert_lines.__getitem__)
    order = np.argsort(ids[:, 0])
    ids = ids[order, 0]
    pos = rows_of(ids, ends)
    k = first_missing(pos)
    if k is not None:
        raise InputError(
            f"EDGE2 refers to unknown vertex {int(ends.ravel()[k])}",
            path=path,
            line=int(edge_lines[k // 2]),
        )
    refuse_self_loops(ends, edge_lines, path, "EDGE2")
    info = np.zeros((edge.shape[0], 3, 3))
    info[:, _ROWS, _COLS] = edge[:, 5:11]
    info[:, _COLS, _ROWS] = edge[:, 5:11]
    check_covariances(
        info,
        path=path,
        lines=edge_lines,
        what="EDGE2 information matrix",
        max_abs=MAX_INFORMATION,
    )
    graph = PoseGraph(
        poses=vert[order, 1:4],
        landmarks=np.empty((0, 2)),
        pp_i=pos[:, 0],
        pp_j=pos[:, 1],
        pp_z=edge[:, 2:5],
        pp_info=info,
    )
    return graph, ids


def _records(
    recs: Records, src: SourceText, kinds: tuple[str, str], id_fields: tuple[str, ...]
) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64]]:
    """The records of both spellings ``kinds`` of one record: values, file lines and the
    leading ``id_fields`` as exact int64 ids (shape (K, len(id_fields)))."""
    values, lines, ids = [], [], []
    for kind in kinds:
        vals, ln = recs[kind]
        values.append(vals)
        lines.append(ln)
        ids.append(
            np.stack(
                [
                    exact_record_ids(vals[:, c], ln, src, c + 1, f"{kind} {name}")
                    for c, name in enumerate(id_fields)
                ],
                axis=1,
            ).reshape(-1, len(id_fields))
        )
    width = _FIELDS[kinds[0]] - 1
    return (
        np.concatenate(values).reshape(-1, width),
        np.concatenate(lines),
        np.concatenate(ids).reshape(-1, len(id_fields)),
    )


def write_toro_graph(
    path: PathLike,
    graph: PoseGraph,
    *,
    poses: ArrayLike | None = None,
    pose_ids: ArrayLike | None = None,
) -> None:
    """Write a pose graph as TORO ``VERTEX2``/``EDGE2`` records (atomically, ``NUMBER_FORMAT``).

    Parameters
    ----------
    path : str or PathLike
    graph : PoseGraph
        Pose–pose factors only.
    poses : array_like, shape (N, 3), optional
        Vertex values (default: the graph's initial guess).
    pose_ids : array_like of int, shape (N,), optional
        Vertex ids (default ``0 … N−1``); distinct.
    """
    if graph.pl_k.size:
        raise InputError("TORO files hold pose graphs only; this graph has landmark factors")
    p = graph.poses if poses is None else np.asarray(poses, dtype=np.float64)
    n = graph.n_poses
    pid = np.arange(n) if pose_ids is None else np.asarray(pose_ids, dtype=np.int64)
    if p.shape != (n, 3) or pid.shape != (n,):
        raise InputError(f"need ({n}, 3) poses and {n} ids, got {p.shape} and {pid.shape}")
    if np.unique(pid).size != n:
        raise InputError("vertex ids must be distinct")
    num = " " + NUMBER_FORMAT
    parts = [
        ("VERTEX2 %d" + num * 3 + "\n") * n % tuple(np.column_stack((pid, p)).ravel().tolist())
    ]
    if graph.pp_i.size:
        rows = np.column_stack(
            (pid[graph.pp_i], pid[graph.pp_j], graph.pp_z, graph.pp_info[:, _ROWS, _COLS])
        )
        parts.append(
            ("EDGE2 %d %d" + num * 9 + "\n") * rows.shape[0] % tuple(rows.ravel().tolist())
        )
    write_text_atomic(path, "".join(parts))
