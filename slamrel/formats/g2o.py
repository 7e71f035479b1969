"""g2o text files of planar graphs: ``VERTEX_SE2``, ``VERTEX_XY``, ``EDGE_SE2``, ``EDGE_SE2_XY``.

``VERTEX_SE2 id x y θ``; ``VERTEX_XY id x y``;
``EDGE_SE2 i j dx dy dθ I11 I12 I13 I22 I23 I33`` (measurement ``x_i⁻¹ ∘ x_j`` and the upper
triangle of its information matrix, row-first); ``EDGE_SE2_XY i l x y I11 I12 I22`` (landmark
``l`` in the frame of pose ``i``). Any other record (``FIX``, 3-D types, …) is an error
naming its line: nothing is silently used or dropped.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relation_metric.checks import check_covariances
from relation_metric.errors import InputError
from relation_metric.ids import first_missing, rows_of
from slamrel.backends.least_squares import PoseGraph
from slamrel.formats.landmark_csv import integer_ids
from slamrel.formats.text import PathLike, read_keyword_records, write_text_atomic

__all__ = ["read_g2o_graph", "write_g2o_graph"]

_FIELDS = {"VERTEX_SE2": 5, "VERTEX_XY": 4, "EDGE_SE2": 12, "EDGE_SE2_XY": 8}


def _upper_to_full(upper: NDArray[np.float64], size: int) -> NDArray[np.float64]:
    iu = np.triu_indices(size)
    m = np.zeros((upper.shape[0], size, size))
    m[:, iu[0], iu[1]] = upper
    return m + np.swapaxes(np.triu(m, 1), 1, 2)


def read_g2o_graph(path: PathLike) -> tuple[PoseGraph, NDArray[np.int64], NDArray[np.int64]]:
    """Read a planar g2o graph.

    Returns
    -------
    graph : PoseGraph
        Vertices as the initial guess; poses and landmarks in increasing id order.
    pose_ids, landmark_ids : ndarray of int
        The file's vertex ids of the graph's poses and landmarks.
    """
    recs = read_keyword_records(path, _FIELDS)
    lines = {k: v[1] for k, v in recs.items()}
    vse2 = recs["VERTEX_SE2"][0]
    vxy = recs["VERTEX_XY"][0]
    if vse2.shape[0] == 0:
        raise InputError("no VERTEX_SE2 records", path=path)
    pose_ids = integer_ids(vse2[:, 0], lines["VERTEX_SE2"], path, "VERTEX_SE2 id")
    lm_ids = integer_ids(vxy[:, 0], lines["VERTEX_XY"], path, "VERTEX_XY id")
    all_ids = np.concatenate((pose_ids, lm_ids))
    all_lines = np.concatenate((lines["VERTEX_SE2"], lines["VERTEX_XY"]))
    order = np.lexsort((all_lines, all_ids))
    dup = np.flatnonzero(np.diff(all_ids[order]) == 0)
    if dup.size:
        first, k = int(order[dup[0]]), int(order[dup[0] + 1])
        raise InputError(
            f"vertex id {int(all_ids[k])} is defined twice (first on line {int(all_lines[first])})",
            path=path,
            line=int(all_lines[k]),
        )
    for kind, size, start in (("EDGE_SE2", 3, 5), ("EDGE_SE2_XY", 2, 4)):
        vals, ln = recs[kind]
        for col in (0, 1):
            integer_ids(vals[:, col], ln, path, f"{kind} vertex {col + 1}")
        check_covariances(
            _upper_to_full(vals[:, start:], size),
            path=path,
            lines=ln,
            what=f"{kind} information matrix",
        )
    po = np.argsort(pose_ids)
    lo = np.argsort(lm_ids)
    pose_ids, lm_ids = pose_ids[po], lm_ids[lo]

    def index(
        ids: NDArray[np.int64], wanted: NDArray[np.float64], kind: str, what: str
    ) -> NDArray[np.int64]:
        w = wanted.astype(np.int64)
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
    graph = PoseGraph(
        poses=vse2[po, 1:4],
        landmarks=vxy[lo, 1:3],
        pp_i=index(pose_ids, e[:, 0], "EDGE_SE2", "pose"),
        pp_j=index(pose_ids, e[:, 1], "EDGE_SE2", "pose"),
        pp_z=e[:, 2:5],
        pp_info=_upper_to_full(e[:, 5:11], 3),
        pl_k=index(pose_ids, f2[:, 0], "EDGE_SE2_XY", "pose"),
        pl_l=index(lm_ids, f2[:, 1], "EDGE_SE2_XY", "landmark"),
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
    parts = []
    if n:
        rows = np.column_stack((pid, p))
        parts.append(("VERTEX_SE2 %d %.9g %.9g %.9g\n" * n) % tuple(rows.ravel().tolist()))
    if lm.shape[0]:
        rows = np.column_stack((lid, lm))
        parts.append(("VERTEX_XY %d %.9g %.9g\n" * lm.shape[0]) % tuple(rows.ravel().tolist()))
    if graph.pp_i.size:
        rows = np.column_stack(
            (pid[graph.pp_i], pid[graph.pp_j], graph.pp_z, graph.pp_info[:, iu3[0], iu3[1]])
        )
        parts.append(
            ("EDGE_SE2 %d %d" + " %.9g" * 9 + "\n") * rows.shape[0] % tuple(rows.ravel().tolist())
        )
    if graph.pl_k.size:
        rows = np.column_stack(
            (pid[graph.pl_k], lid[graph.pl_l], graph.pl_z, graph.pl_info[:, iu2[0], iu2[1]])
        )
        parts.append(
            ("EDGE_SE2_XY %d %d" + " %.9g" * 5 + "\n")
            * rows.shape[0]
            % tuple(rows.ravel().tolist())
        )
    write_text_atomic(path, "".join(parts))
