"""TORO's 2-D graph files: ``VERTEX2`` and ``EDGE2``.

``VERTEX2 id x y θ``; ``EDGE2 i j dx dy dθ I_xx I_xy I_yy I_θθ I_xθ I_yθ`` — the
measurement ``x_i⁻¹ ∘ x_j`` as in g2o's ``EDGE_SE2``, but with the information entries in
TORO's own order (``xx xy yy θθ xθ yθ``; g2o's is the row-first upper triangle
``xx xy xθ yy yθ θθ``). The older spellings ``VERTEX`` and ``EDGE`` of the same records are
read too. TORO files hold pose graphs only: writing a graph with landmark factors is an
error, and so is any other record (named with its line).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relation_metric.errors import InputError
from relation_metric.ids import refuse_self_loops, rows_of
from slamrel.backends.graph import PoseGraph
from slamrel.formats.text import (
    NUMBER_FORMAT,
    PathLike,
    SourceText,
    read_keyword_records,
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
    recs = read_keyword_records(path, _FIELDS)
    vert = np.concatenate((recs["VERTEX2"][0], recs["VERTEX"][0])).reshape(-1, 4)
    edge = np.concatenate((recs["EDGE2"][0], recs["EDGE"][0])).reshape(-1, 11)
    edge_lines = np.concatenate((recs["EDGE2"][1], recs["EDGE"][1]))
    if vert.shape[0] == 0:
        raise InputError("no VERTEX2 records", path=path)
    ids = vert[:, 0].astype(np.int64)
    uniq, counts = np.unique(ids, return_counts=True)
    if (counts > 1).any():
        raise InputError(f"vertex id {int(uniq[counts > 1][0])} is defined twice", path=path)
    order = np.argsort(ids)
    ids = ids[order]
    ends = edge[:, :2].astype(np.int64)
    pos = rows_of(ids, ends)
    ok = pos >= 0
    if not ok.all():
        k = int(np.flatnonzero(~ok.all(axis=1))[0])
        bad = int(ends[k][~ok[k]][0])
        raise InputError(
            f"EDGE2 refers to unknown vertex {bad}", path=path, line=int(edge_lines[k])
        )
    refuse_self_loops(ends, edge_lines, path, "EDGE2")
    info = np.zeros((edge.shape[0], 3, 3))
    info[:, _ROWS, _COLS] = edge[:, 5:11]
    info[:, _COLS, _ROWS] = edge[:, 5:11]
    graph = PoseGraph(
        poses=vert[order, 1:4],
        landmarks=np.empty((0, 2)),
        pp_i=pos[:, 0],
        pp_j=pos[:, 1],
        pp_z=edge[:, 2:5],
        pp_info=info,
    )
    return graph, ids


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
