"""Evaluation results as files: JSON, the per-relation CSV (writer and reader), evo zips.

All outputs are written atomically (temporary file + rename); none is written over an input.
The per-relation CSV is the one result slamrel reads again (``slamrel compare``): its writer
and its reader live here side by side, so that the two agree on every column.
"""

from __future__ import annotations

import io
import json
import zipfile
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relation_metric.errors import InputError
from relation_metric.evaluate import Evaluation
from relation_metric.stats import evo_statistics
from slamrel.formats.text import (
    NUMBER_FORMAT,
    PathLike,
    read_csv_table,
    read_csv_text_column,
    read_source,
    write_bytes_atomic,
    write_text_atomic,
)

__all__ = [
    "write_json",
    "write_per_relation_csv",
    "PerRelationTable",
    "read_per_relation_csv",
    "write_evo_zip",
    "write_evo_ape_zip",
    "write_evo_result",
    "evo_stats",
    "EvoDelta",
    "evo_delta",
    "evo_title",
]


def write_json(path: PathLike, data: dict[str, Any]) -> None:
    """Write ``data`` as indented JSON (NaN is not allowed: use ``None``)."""
    write_text_atomic(path, json.dumps(data, indent=2, allow_nan=False) + "\n")


def write_per_relation_csv(
    path: PathLike,
    evaluation: Evaluation,
    *,
    degrees: bool = False,
    relation_sets: ArrayLike | None = None,
) -> None:
    """One row per relation: ``t1,t2,i,j,trans_error,rot_error,valid,via_odometry[,set]``.

    ``i``/``j`` are the estimate pose indices associated with the two ends (−1 when
    unassociated); errors of unassociated relations are empty. Numbers as
    :data:`~slamrel.formats.text.NUMBER_FORMAT` (exact round trip).

    Parameters
    ----------
    path : str or PathLike
    evaluation : Evaluation
    degrees : bool
        Rotation errors in degrees (column ``rot_error_deg``; else ``rot_error_rad``).
    relation_sets : array_like of str, shape (M,), optional
        The relation set each relation belongs to (e.g. ``consecutive``, ``loops``), written
        as a last column ``set``; ``slamrel compare`` then tests each set on its own. Names
        must be non-empty, without commas, line breaks or surrounding blanks.

    Raises
    ------
    InputError
        ``relation_sets`` of another length than the relations, or a name it cannot write.
    """
    ev = evaluation
    a = ev.association
    n = len(ev.relations)
    sets = None if relation_sets is None else np.asarray(relation_sets, dtype=np.str_)
    if sets is not None:
        _check_set_names(sets, n)
    rot = np.degrees(ev.errors.rotation) if degrees else ev.errors.rotation
    head = f"t1,t2,i,j,trans_error,rot_error_{'deg' if degrees else 'rad'},valid,via_odometry"
    head += ",set\n" if sets is not None else "\n"
    if n == 0:
        write_text_atomic(path, head)
        return
    cols = [
        np.char.mod(NUMBER_FORMAT, ev.relations.first),
        np.char.mod(NUMBER_FORMAT, ev.relations.second),
        a.index_first.astype(str),
        a.index_second.astype(str),
        np.where(a.valid, np.char.mod(NUMBER_FORMAT, np.nan_to_num(ev.errors.translation)), ""),
        np.where(a.valid, np.char.mod(NUMBER_FORMAT, np.nan_to_num(rot)), ""),
        a.valid.astype(np.int8).astype(str),
        a.via_odometry.astype(np.int8).astype(str),
    ]
    if sets is not None:
        cols.append(sets)
    rows = cols[0]
    for c in cols[1:]:
        rows = np.char.add(np.char.add(rows, ","), c)
    write_text_atomic(path, head + "\n".join(rows.tolist()) + "\n")


def _check_set_names(sets: np.ndarray, n: int) -> None:
    if sets.shape != (n,):
        raise InputError(f"relation_sets must name one set per relation ({n}), got {sets.shape}")
    for name in np.unique(sets).tolist():
        bad = (
            not name
            or name != name.strip()
            or "," in name
            or any(not ch.isprintable() for ch in name)
        )
        if bad:
            raise InputError(
                f"relation set name {name!r}: expected a non-empty name without commas, line "
                "breaks or surrounding blanks"
            )


class PerRelationTable(NamedTuple):
    """A per-relation CSV (:func:`write_per_relation_csv`) as arrays, one row per relation.

    Attributes
    ----------
    t1, t2 : ndarray, shape (M,)
        The times of the relation's two ends (seconds).
    translation, rotation : ndarray, shape (M,)
        The errors (metres; radians or degrees, see ``rotation_unit``); NaN where a cell is
        empty (only an invalid relation may leave them empty).
    rotation_unit : str
        ``"rad"`` (column ``rot_error_rad``) or ``"deg"`` (``rot_error_deg``).
    valid : ndarray of bool, shape (M,)
        Whether the relation was associated and scored.
    relation_set : ndarray of str, shape (M,), or None
        The ``set`` column (``consecutive``, ``loops``, ...); None when the file has none.
    lines : ndarray of int, shape (M,)
        The 1-based line of each relation (for messages about a row).
    """

    t1: NDArray[np.float64]
    t2: NDArray[np.float64]
    translation: NDArray[np.float64]
    rotation: NDArray[np.float64]
    rotation_unit: str
    valid: NDArray[np.bool_]
    relation_set: NDArray[np.str_] | None
    lines: NDArray[np.int64]


_ROTATION_COLUMNS = ("rot_error_rad", "rot_error_deg")


def read_per_relation_csv(path: PathLike) -> PerRelationTable:
    """Read and check a per-relation CSV of ``slamrel evaluate --per-relation``.

    The columns read are ``t1``, ``t2``, ``trans_error``, ``rot_error_rad`` or
    ``rot_error_deg``, ``valid`` and, when present, ``set`` (the estimate indices ``i``,
    ``j`` and ``via_odometry`` are for people and are not read). Number cells as
    :func:`~slamrel.formats.text.read_csv_table` reads them; the errors of an invalid
    relation may be empty.

    Raises
    ------
    InputError
        What :func:`~slamrel.formats.text.read_csv_table` refuses (a missing column, a cell
        that is not a number), a ``valid`` other than 0 or 1, an empty ``set`` cell, or a
        valid relation without an error value; at the file and line.
    """
    src = read_source(path)
    c, lines = read_csv_table(
        path,
        required=("t1", "t2", "trans_error", _ROTATION_COLUMNS, "valid"),
        empty_ok=("trans_error", *_ROTATION_COLUMNS),
        describe="the per-relation CSV of slamrel evaluate",
        source=src,
    )
    set_column = read_csv_text_column(src, "set")
    rot_col = next(n for n in _ROTATION_COLUMNS if n in c)
    valid = c["valid"]
    bad = np.flatnonzero((valid != 0) & (valid != 1))
    if bad.size:
        raise InputError(
            f"column 'valid': expected 0 or 1, got {float(valid[bad[0]]):g}",
            path=path,
            line=int(lines[bad[0]]),
        )
    if set_column is not None:
        unnamed = np.flatnonzero(set_column == "")
        if unnamed.size:
            raise InputError(
                "column 'set': an empty cell; expected the name of the relation set",
                path=path,
                line=int(lines[unnamed[0]]),
            )
    keep = valid == 1
    trans, rot = c["trans_error"], c[rot_col]
    empty = np.flatnonzero(np.isnan(trans[keep]) | np.isnan(rot[keep]))
    if empty.size:
        raise InputError(
            "a valid relation without an error value; expected numbers in trans_error and "
            f"{rot_col}",
            path=path,
            line=int(lines[keep][empty[0]]),
        )
    return PerRelationTable(
        c["t1"], c["t2"], trans, rot, rot_col.removeprefix("rot_error_"), keep, set_column, lines
    )


def evo_stats(errors: np.ndarray) -> dict[str, float]:
    """Statistics as evo computes them (population std, ``sse``):
    :func:`relation_metric.stats.evo_statistics`."""
    return evo_statistics(errors)


@dataclass(frozen=True)
class EvoDelta:
    """The RPE pairs of evo that slamrel's relations equal (see :func:`evo_delta`).

    ``delta`` in ``unit`` (``"frames"`` or ``"m"``), ``all_pairs`` evo's ``--all_pairs``.
    """

    delta: float
    unit: str
    all_pairs: bool = False


def evo_delta(
    *, sync: bool, strategy: str | None, step: int, distance: float, chained: bool, mode: str
) -> EvoDelta | None:
    """evo's RPE pairs equal to slamrel's relations, or None when evo has no such RPE.

    slamrel's relations are evo's RPE (``evo_rpe --pairs_from_reference``) when the poses are
    associated pose by pose first (``sync``), the error is the ``paper`` definition
    (``E = (Q_i⁻¹ Q_j)⁻¹ (P_i⁻¹ P_j)``) and the relations are ``consecutive`` with ``step`` D
    (``chained``: evo's consecutive pairs ``--delta D --delta_unit f``; not chained: every
    pose and the one D later, evo's ``--all_pairs``; D = 1 is both) or ``distance`` D metres,
    chained (``--delta D --delta_unit m``). The parity tests check these to 1e-9.
    """
    if not sync or mode != "paper":
        return None
    if strategy in (None, "consecutive"):
        return EvoDelta(float(step), "frames", all_pairs=not chained and step != 1)
    if strategy == "distance" and chained:
        return EvoDelta(float(distance), "m")
    return None


_EVO_RELATION = {
    "trans": ("translation part", "m"),
    "rot": ("rotation angle in radians", "rad"),
    "rot_deg": ("rotation angle in degrees", "deg"),
}
_EVO_ALIGN = {
    "none": "(not aligned)",
    "se3": "(with SE(3) Umeyama alignment)",
    "sim3": "(with Sim(3) Umeyama alignment)",
    "se2": "(with SE(2) Umeyama alignment)",
    "sim2": "(with Sim(2) Umeyama alignment)",
}


def evo_title(metric: str, part: str, *, delta: EvoDelta | None = None, align: str = "none") -> str:
    """The ``title`` evo writes in a result of the same computation (``evo_res`` compares them).

    ``metric`` ``"rpe"`` or ``"ape"``; ``part`` ``"trans"``, ``"rot"`` or ``"rot_deg"``.
    An RPE with ``delta`` (:func:`evo_delta`) reads as evo_rpe's ``RPE w.r.t. translation part
    (m)\nfor delta = 1 (frames) using consecutive pairs\n(not aligned)``; without (relations
    evo has no name for) as ``RE w.r.t. … (m)\nrelation metric (Kümmerle et al. 2009)``; an APE
    as evo_ape's ``APE w.r.t. … (m)\n(with SE(3) Umeyama alignment)``.
    """
    relation, unit = _EVO_RELATION[part]
    if metric == "ape":
        return f"APE w.r.t. {relation} ({unit})\n{_EVO_ALIGN[align]}"
    if delta is None:
        return f"RE w.r.t. {relation} ({unit})\nrelation metric (Kümmerle et al. 2009)"
    d = int(delta.delta) if delta.unit == "frames" else delta.delta
    pairs = "all pairs" if delta.all_pairs else "consecutive pairs"
    return (
        f"RPE w.r.t. {relation} ({unit})\nfor delta = {d} ({delta.unit}) using {pairs}"
        "\n(not aligned)"
    )


def write_evo_zip(
    path: PathLike,
    evaluation: Evaluation,
    *,
    part: str = "trans",
    est_name: str = "estimate",
    ref_name: str = "reference",
    degrees: bool = False,
    delta: EvoDelta | None = None,
) -> None:
    """Write an evo result zip of the relation errors (``info.json``, ``stats.json``, ...).

    ``evo_res`` can then tabulate and plot slamrel results beside evo's own. One zip holds
    one error array: ``part="trans"`` (m) or ``"rot"`` (rad, or deg with ``degrees``). The
    title is evo_rpe's for the same computation when there is one (``delta``, see
    :func:`evo_delta` and :func:`evo_title`), so that ``evo_res`` reads slamrel's zips beside
    evo's without ``--ignore_title``. ``timestamps`` are the second pose's of each relation
    (as evo's). Note evo's ``std`` is the population standard deviation, unlike slamrel's
    JSON (n − 1).
    """
    ev = evaluation
    valid = ev.valid
    if not valid.any():
        # evo_res cannot read a result without errors (its statistics of none are NaN)
        raise InputError(
            f"no scored relation ({len(ev.relations)} given, none associated): an evo result "
            "needs at least one error; no zip written",
            path=path,
        )
    if part == "trans":
        errors = ev.errors.translation[valid]
    elif part == "rot":
        errors = ev.errors.rotation[valid]
        if degrees:
            errors = np.degrees(errors)
    else:
        raise ValueError(f"part must be 'trans' or 'rot', got {part!r}")
    key = "rot_deg" if part == "rot" and degrees else part
    info = {
        "title": evo_title("rpe", key, delta=delta),
        "ref_name": ref_name,
        "est_name": est_name,
        "label": f"{'RPE' if delta else 'RE'} ({_EVO_RELATION[key][1]})",
        "relation_count": int(valid.sum()),
        "mode": ev.errors.mode,
        "generator": "slamrel",
    }
    t = ev.relations.second[valid]
    _write_evo_archive(path, info, errors, t, t - t.min())


def write_evo_ape_zip(
    path: PathLike,
    errors: ArrayLike,
    timestamps: ArrayLike,
    *,
    part: str = "trans",
    align: str = "none",
    est_name: str = "estimate",
    ref_name: str = "reference",
) -> None:
    """Write an evo result zip of absolute pose errors, as ``evo_ape --save_results`` does.

    ``errors`` (K,) per matched pose (m for ``part="trans"``, rad for ``"rot"``, deg for
    ``"rot_deg"``) after ``align`` (``none``/``se3``/``sim3``/``se2``/``sim2``), at the
    estimate's ``timestamps`` (K,); the title is evo_ape's (:func:`evo_title`).
    """
    e = np.asarray(errors, dtype=np.float64)
    t = np.asarray(timestamps, dtype=np.float64)
    if e.size == 0:
        raise InputError("no matched pose: an evo result needs at least one error", path=path)
    info = {
        "title": evo_title("ape", part, align=align),
        "ref_name": ref_name,
        "est_name": est_name,
        "label": f"APE ({_EVO_RELATION[part][1]})",
        "generator": "slamrel",
    }
    _write_evo_archive(path, info, e, t, t - t.min())


def write_evo_result(
    path: PathLike,
    info: dict[str, Any],
    errors: ArrayLike,
    timestamps: ArrayLike | None = None,
    seconds_from_start: ArrayLike | None = None,
) -> None:
    """Write an evo result zip with the given ``info`` (evo's ``title``, ``ref_name``,
    ``est_name``, ``label``), as ``evo_ape``/``evo_rpe --save_results`` do: what ``slamrel
    ape``/``rpe`` write. ``timestamps`` and ``seconds_from_start`` (K,) are the estimate's
    times of the errors (None: trajectories without times, as KITTI's; evo's zips then hold
    no time arrays either)."""
    e = np.asarray(errors, dtype=np.float64)
    if e.size == 0:
        raise InputError("no error value: an evo result needs at least one error", path=path)
    t = None if timestamps is None else np.asarray(timestamps, dtype=np.float64)
    s = None if seconds_from_start is None else np.asarray(seconds_from_start, dtype=np.float64)
    _write_evo_archive(path, info, e, t, s)


def _write_evo_archive(
    path: PathLike,
    info: dict[str, Any],
    errors: NDArray,
    timestamps: NDArray | None,
    seconds: NDArray | None,
) -> None:
    """The zip evo's ``file_interface.save_res_file`` writes: info, stats and the arrays."""
    arrays = {"error_array": errors}
    if timestamps is not None and seconds is not None:
        arrays.update(timestamps=timestamps, seconds_from_start=seconds)
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("info.json", json.dumps(info))
        archive.writestr("stats.json", json.dumps(evo_stats(errors)))
        for name, arr in arrays.items():
            npy = io.BytesIO()
            np.save(npy, np.asarray(arr, dtype=np.float64))
            archive.writestr(f"{name}.npy", npy.getvalue())
    write_bytes_atomic(path, buf.getvalue())
