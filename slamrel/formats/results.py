"""Writers for evaluation results: JSON, per-relation CSV, evo result zip.

All outputs are written atomically (temporary file + rename); none is written over an input.
"""

from __future__ import annotations

import io
import json
import zipfile
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from relation_metric.errors import InputError
from relation_metric.evaluate import Evaluation
from slamrel.formats.text import NUMBER_FORMAT, PathLike, write_bytes_atomic, write_text_atomic

__all__ = ["write_json", "write_per_relation_csv", "write_evo_zip", "evo_stats"]


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


def evo_stats(errors: np.ndarray) -> dict[str, float]:
    """Statistics as evo computes them (population std, ``sse``)."""
    e = np.asarray(errors, dtype=np.float64)
    return {
        "rmse": float(np.sqrt(np.mean(e**2))),
        "mean": float(np.mean(e)),
        "median": float(np.median(e)),
        "std": float(np.std(e)),
        "min": float(np.min(e)),
        "max": float(np.max(e)),
        "sse": float(np.sum(e**2)),
    }


def write_evo_zip(
    path: PathLike,
    evaluation: Evaluation,
    *,
    part: str = "trans",
    est_name: str = "estimate",
    ref_name: str = "reference",
    degrees: bool = False,
) -> None:
    """Write an evo result zip (``info.json``, ``stats.json``, ``error_array.npy``, …).

    ``evo_res`` can then tabulate and plot slamrel results beside evo's own. One zip holds
    one error array: ``part="trans"`` (m) or ``"rot"`` (rad, or deg with ``degrees``).
    Note evo's ``std`` is the population standard deviation, unlike slamrel's JSON (n − 1).
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
        label = "RE (m)"
        title = "relation error, translation part (Kümmerle et al. 2009)"
    elif part == "rot":
        errors = ev.errors.rotation[valid]
        if degrees:
            errors = np.degrees(errors)
        label = "RE (deg)" if degrees else "RE (rad)"
        title = "relation error, rotation part (Kümmerle et al. 2009)"
    else:
        raise ValueError(f"part must be 'trans' or 'rot', got {part!r}")
    info = {
        "title": title,
        "ref_name": ref_name,
        "est_name": est_name,
        "label": label,
        "pose_relation": "translation part" if part == "trans" else "rotation part",
        "relation_delta_unit": "relations",
        "relation_count": int(valid.sum()),
        "mode": ev.errors.mode,
        "generator": "slamrel",
    }
    arrays = {
        "error_array": errors,
        "timestamps": ev.relations.second[valid],
        "seconds_from_start": ev.relations.second[valid]
        - (ev.relations.second[valid].min() if valid.any() else 0.0),
    }
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("info.json", json.dumps(info))
        archive.writestr("stats.json", json.dumps(evo_stats(errors) if errors.size else {}))
        for name, arr in arrays.items():
            npy = io.BytesIO()
            np.save(npy, np.asarray(arr, dtype=np.float64))
            archive.writestr(f"{name}.npy", npy.getvalue())
    write_bytes_atomic(path, buf.getvalue())
