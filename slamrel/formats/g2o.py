"""g2o text files of planar graphs: ``VERTEX_SE2``, ``VERTEX_XY``, ``EDGE_SE2``, ``EDGE_SE2_XY``.

``VERTEX_SE2 id x y θ``; ``VERTEX_XY id x y``;
``EDGE_SE2 i j dx dy dθ I11 I12 I13 I22 I23 I33`` (measurement ``x_i⁻¹ ∘ x_j`` and the upper
triangle of its information matrix, row-first); ``EDGE_SE2_XY i l x y I11 I12 I22`` (landmark
``l`` in the frame of pose ``i``).

The one g2o reader and writer of slamrel. :func:`read_g2o_records` reads and checks the
records (used by the graph reader here, the trajectory reader's ``g2o`` format and the
landmark-map reader's ``VERTEX_XY`` maps); :func:`format_g2o_records` writes them (used by
:func:`write_g2o_graph`, ``write_trajectory(format="g2o")`` and ``write_map(format="g2o")``).
The record rules are the same for all: exactly the record's fields, finite numbers, integer
ids (vertex ids and edge ends), vertex ids unique across the vertex kinds read. The graph
reader refuses any other record (``FIX``, 3-D types, …) naming its line: nothing is silently
used or dropped; the trajectory and map readers skip and count the records they do not use.
An ``EDGE_SE2`` from a vertex to itself (a self-loop) is refused with its line (so is a TORO
``EDGE2``, :mod:`slamrel.formats.toro`).
Numbers are written with :data:`~slamrel.formats.text.NUMBER_FORMAT` (exact round trip).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relation_metric.checks import MAX_INFORMATION, check_covariances
from relation_metric.errors import InputError
from relation_metric.ids import (
    first_missing,
    refuse_repeated_ids,
    refuse_self_loops,
    rows_of,
)
from relation_metric.trajectory import check_coordinates
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

if TYPE_CHECKING:
    from slamrel.backends.graph import PoseGraph

__all__ = [
    "G2O_RECORDS",
    "read_g2o_records",
    "format_g2o_records",
    "read_g2o_graph",
    "write_g2o_graph",
]

G2O_RECORDS: dict[str, tuple[str, ...]] = {
    "VERTEX_SE2": ("id", "x", "y", "theta"),
    "VERTEX_XY": ("id", "x", "y"),
    "EDGE_SE2": ("i", "j", "dx", "dy", "dtheta", "I11", "I12", "I13", "I22", "I23", "I33"),
    "EDGE_SE2_XY": ("i", "l", "x", "y", "I11", "I12", "I22"),
}
"""The planar g2o records: their field names after the keyword."""

# Leading id columns of each record (vertex id; edge ends), written as integers.
_ID_COLUMNS = {"VERTEX_SE2": 1, "VERTEX_XY": 1, "EDGE_SE2": 2, "EDGE_SE2_XY": 2}


def read_g2o_records(
    path: PathLike,
    kinds: Sequence[str] = tuple(G2O_RECORDS),
    *,
    skipped: Counter[str] | None = None,
    source: SourceText | None = None,
    ids: dict[str, NDArray[np.int64]] | None = None,
) -> Records:
    """The records of ``kinds`` of a planar g2o file, each checked (see the module docstring).

    Parameters
    ----------
    path : str or PathLike
    kinds : sequence of str
        Record names of :data:`G2O_RECORDS` to read.
    skipped : Counter, optional
        Other records are skipped and counted here by name; without it they are an error.
    source : SourceText, optional
        Already-read text of ``path``.
    ids : dict, optional
        Filled with record name → its id columns as exact int64, shape (K, 1) for vertices
        and (K, 2) for edges. Ids of any size in int64 are read exactly as written (GTSAM's
        symbol keys, ``'l' << 56 | j``, are near 7.8e18): in the returned values an id of
        magnitude ≥ 2**53 is only the nearest double, so use these.

    Returns
    -------
    dict of record name → (values (K, fields), line numbers (K,))
        In file order; ids as (integer-valued) floats.

    Raises
    ------
    InputError
        At the first bad record: wrong number of fields (``VERTEX_XY: expected 4 fields
        (VERTEX_XY id x y), got 3``), a field that is not a finite number (``VERTEX_SE2
        theta: ...``), an id that is not an integer (``column 'VERTEX_XY id': ...``), a
        vertex id defined twice (``vertex id 5 is defined twice (first on line 2)``, at the
        second), an unknown record (without ``skipped``).
    """
    src = read_source(path) if source is None else source
    fields = {k: len(G2O_RECORDS[k]) + 1 for k in kinds}
    recs = read_keyword_records(path, fields, names=G2O_RECORDS, skipped=skipped, source=src)
    vertex_ids, id_lines = [], []
    for kind in kinds:
        vals, lines = recs[kind]
        one = _ID_COLUMNS[kind] == 1
        what = [f"{kind} id"] if one else [f"{kind} vertex 1", f"{kind} vertex 2"]
        cols = np.stack(
            [exact_record_ids(vals[:, c], lines, src, c + 1, w) for c, w in enumerate(what)],
            axis=1,
        ).reshape(-1, len(what))
        if ids is not None:
            ids[kind] = cols
        if one:
            vertex_ids.append(cols[:, 0])
            id_lines.append(lines)
    if vertex_ids:
        refuse_repeated_ids(
            np.concatenate(vertex_ids), np.concatenate(id_lines), src.path, "vertex id"
        )
    return recs


def format_g2o_records(kind: str, ids: ArrayLike, values: ArrayLike) -> str:
    """Lines ``KIND id… v…`` of one record kind: ids as integers, values as ``NUMBER_FORMAT``.

    Parameters
    ----------
    kind : str
        A record name of :data:`G2O_RECORDS`.
    ids : array_like of int, shape (K,) (vertices) or (K, 2) (edges: the two ends)
    values : array_like, shape (K, fields − ids)
    """
    n_id = _ID_COLUMNS[kind]
    v = np.asarray(values, dtype=np.float64)
    n = v.shape[0]
    if n == 0:
        return ""
    i = np.asarray(ids, dtype=np.int64).reshape(n, n_id)
    if v.shape != (n, len(G2O_RECORDS[kind]) - n_id):
        raise ValueError(f"{kind}: expected {len(G2O_RECORDS[kind]) - n_id} values a record")
    # ids stay Python ints (exact beyond 2**53), values Python floats: one formatting pass
    cells = np.column_stack((i.astype(object), v.astype(object)))
    line = kind + " %d" * n_id + (" " + NUMBER_FORMAT) * v.shape[1] + "\n"
    return line * n % tuple(cells.ravel().tolist())


def _upper_to_full(upper: NDArray[np.float64], size: int) -> NDArray[np.float64]:
    iu = np.triu_indices(size)
    m = np.zeros((upper.shape[0], size, size))
    m[:, iu[0], iu[1]] = upper
    return m + np.swapaxes(np.triu(m, 1), 1, 2)


def read_g2o_graph(
    path: PathLike, *, source: SourceText | None = None
) -> tuple[PoseGraph, NDArray[np.int64], NDArray[np.int64]]:
    """Read a planar g2o graph (``source``: the already-read text of ``path``).

    Returns
    -------
    graph : PoseGraph
        Vertices as the initial guess; poses and landmarks in increasing id order.
    pose_ids, landmark_ids : ndarray of int
        The file's vertex ids of the graph's poses and landmarks.
    """
    from slamrel.backends.graph import PoseGraph

    exact: dict[str, NDArray[np.int64]] = {}
    recs = read_g2o_records(path, source=source, ids=exact)
    name = str(path)
    lines = {k: v[1] for k, v in recs.items()}
    vse2 = recs["VERTEX_SE2"][0]
    vxy = recs["VERTEX_XY"][0]
    if vse2.shape[0] == 0:
        raise InputError("no VERTEX_SE2 records", path=path)
    pose_ids = exact["VERTEX_SE2"][:, 0]
    lm_ids = exact["VERTEX_XY"][:, 0]
    for vals, kind, what in ((vse2, "VERTEX_SE2", "pose"), (vxy, "VERTEX_XY", "landmark")):
        check_coordinates(vals[:, 1:3], what=what, path=name, line_of=lines[kind].__getitem__)
    for kind, size, start in (("EDGE_SE2", 3, 5), ("EDGE_SE2_XY", 2, 4)):
        vals, ln = recs[kind]
        check_covariances(
            _upper_to_full(vals[:, start:], size),
            path=path,
            lines=ln,
            what=f"{kind} information matrix",
            max_abs=MAX_INFORMATION,
        )
    po = np.argsort(pose_ids)
    lo = np.argsort(lm_ids)
    pose_ids, lm_ids = pose_ids[po], lm_ids[lo]

    def index(
        ids: NDArray[np.int64], w: NDArray[np.int64], kind: str, what: str
    ) -> NDArray[np.int64]:
        pos = rows_of(ids, w)
        k = first_missing(pos)
        if k is not None:
            raise InputError(
                f"{kind} refers to unknown {what} vertex {int(w[k])}",
                path=path,
                line=int(lines[kind][k]),
            )
        return pos

    e = recs["EDGE_SE2"][0]
    f2 = recs["EDGE_SE2_XY"][0]
    ee, ef = exact["EDGE_SE2"], exact["EDGE_SE2_XY"]
    refuse_self_loops(ee, lines["EDGE_SE2"], path, "EDGE_SE2")
    graph = PoseGraph(
        poses=vse2[po, 1:4],
        landmarks=vxy[lo, 1:3],
        pp_i=index(pose_ids, ee[:, 0], "EDGE_SE2", "pose"),
        pp_j=index(pose_ids, ee[:, 1], "EDGE_SE2", "pose"),
        pp_z=e[:, 2:5],
        pp_info=_upper_to_full(e[:, 5:11], 3),
        pl_k=index(pose_ids, ef[:, 0], "EDGE_SE2_XY", "pose"),
        pl_l=index(lm_ids, ef[:, 1], "EDGE_SE2_XY", "landmark"),
        pl_z=f2[:, 2:4],
        pl_info=_upper_to_full(f2[:, 4:7], 2),
    )
    return graph, pose_ids, lm_ids


def write_g2o_graph(
    path: PathLike,
    graph: PoseGraph,
    *,
    poses: NDArray[np.float64] | None = None,
    landmarks: NDArray[np.float64] | None = None,
    pose_ids: ArrayLike | None = None,
    landmark_ids: ArrayLike | None = None,
) -> None:
    """Write ``graph`` (vertices: ``poses``/``landmarks`` if given, else its initial guess).

    Vertex ids are ``pose_ids`` and ``landmark_ids`` when given (e.g. the ids of the file the
    graph came from, so that maps written from it keep the landmark names); otherwise poses
    get ``0..N−1`` and landmarks ``N..N+L−1``. The ids must be distinct integers.
    """
    p = graph.poses if poses is None else np.asarray(poses)
    lm = graph.landmarks if landmarks is None else np.asarray(landmarks)
    n = p.shape[0]
    pid = np.arange(n) if pose_ids is None else np.asarray(pose_ids, dtype=np.int64)
    lid = n + np.arange(lm.shape[0]) if landmark_ids is None else np.asarray(landmark_ids, np.int64)
    if pid.shape != (n,) or lid.shape != (lm.shape[0],):
        raise InputError(
            f"need {n} pose ids and {lm.shape[0]} landmark ids, got {pid.shape} and {lid.shape}"
        )
    every = np.concatenate((pid, lid))
    if np.unique(every).size != every.size:
        raise InputError("vertex ids must be distinct (poses and landmarks share one id space)")
    iu3 = np.triu_indices(3)
    iu2 = np.triu_indices(2)
    parts = [format_g2o_records("VERTEX_SE2", pid, p), format_g2o_records("VERTEX_XY", lid, lm)]
    parts.append(
        format_g2o_records(
            "EDGE_SE2",
            np.column_stack((pid[graph.pp_i], pid[graph.pp_j])),
            np.column_stack((graph.pp_z, graph.pp_info[:, iu3[0], iu3[1]])),
        )
    )
    parts.append(
        format_g2o_records(
            "EDGE_SE2_XY",
            np.column_stack((pid[graph.pl_k], lid[graph.pl_l])),
            np.column_stack((graph.pl_z, graph.pl_info[:, iu2[0], iu2[1]])),
        )
    )
    write_text_atomic(path, "".join(parts))
