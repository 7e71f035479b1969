"""The SLAM result bundle on disk (format ``slamrel-bundle/1``, docs/bundle.md): read and write.

A bundle is a directory of comma-separated files (one header line, ``#`` comment lines) and a
JSON manifest ``bundle.json``. The reader is strict: a missing required file or column, a
non-finite number, times that go back more than ``FILTER_TIME_TOLERANCE`` (0.05 s; smaller
steps back are put in time order and counted in ``Bundle.reordered``), an unknown model type,
a measurement whose landmark is not in ``map.csv`` (unless ``skip_unknown_landmarks``, which
counts them), and a covariance that is not symmetric positive semi-definite each raise
:class:`~relation_metric.errors.InputError` naming the file, the line and what was expected.

Measurement times within ``SNAP_TOLERANCE`` (1e-6 s) of a control/odometry time are set to
that time (``Bundle.snapped``), and measurements outside the log's span are warned about
(``TimeOrderWarning``, once each, with file and line); an anisotropic world-frame
``pose_noise`` gives a ``MotionModelWarning``.

Landmark ids are integers. Manifest defaults: ``initial_pose`` ``[0, 0, 0]``,
``initial_covariance`` ``1e-9 I``, ``description`` empty, ``map_source`` not stated;
velocity model ``integration`` ``"arc"``, ``control_stamp`` ``"start"``.
"""

from __future__ import annotations

import io
import json
import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import replace
from functools import partial
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from recovery.bundle import INITIALISATIONS, TIME_UNITS, Bundle
from recovery.constants import MAP_SOURCES, MAX_SIGMA, MAX_VARIANCE, MIN_SENSOR_SIGMA
from recovery.models import (
    CONTROL_STAMPS,
    INTEGRATIONS,
    MOTION_TYPES,
    POSE_NOISE_FRAMES,
    SENSOR_NOISE_SOURCES,
    SIGMA_NAMES,
    MotionModel,
    MotionModelWarning,
    MotionPersisting,
    PersistingError,
    SensorModel,
    checked_outlier_share,
    world_noise_is_rotation_invariant,
)
from recovery.steps import SNAP_TOLERANCE, snap_times
from relation_metric.arrays import Array, PathLike
from relation_metric.checks import check_covariances, check_joint_covariance
from relation_metric.errors import InputError
from relation_metric.timeorder import FILTER_TIME_TOLERANCE, TimeOrderWarning, sort_by_time
from relation_metric.trajectory import MAX_COORDINATE, Trajectory, check_coordinates
from slamrel.constants import BUNDLE_FORMAT as FORMAT
from slamrel.formats.landmark_csv import read_landmark_csv, write_landmark_csv
from slamrel.formats.text import (
    format_csv_table,
    loads_json,
    read_csv_id_column,
    read_csv_table,
    read_source,
    read_text,
    write_bytes_atomic,
    write_csv_table,
    write_text_atomic,
)
from slamrel.formats.trajectories import CSV_HEADER, read_trajectory, write_trajectory
from slamrel.outputs import staged_directory

__all__ = [
    "ONLINE_COVARIANCE_COLUMNS",
    "InvalidMeasurementWarning",
    "OnlineCovarianceWarning",
    "OnlineEstimate",
    "read_bundle",
    "read_online",
    "write_bundle",
    "write_measurements",
    "write_online",
]

#: The optional covariance columns of ``online.csv``: the upper triangle of the pose's 3 × 3
#: covariance, rows and columns ``[x, y, θ]`` (``t`` for θ).
ONLINE_COVARIANCE_COLUMNS = ("cxx", "cxy", "cxt", "cyy", "cyt", "ctt")


def _shown(value: Any) -> str:
    """A JSON value for a message (as JSON, shortened; odd characters as ``<U+XXXX>``)."""
    text = f"'{value}'" if isinstance(value, str) else json.dumps(value, ensure_ascii=False)
    text = text if len(text) <= 60 else text[:60] + "..."
    return "".join(c if c.isprintable() else f"<U+{ord(c):04X}>" for c in text)


#: The keys of ``motion_model.persisting`` (:class:`~recovery.models.MotionPersisting`).
MOTION_PERSISTING_KEYS = ("sigma_scale", "time_constant_scale", "sigma_turn", "time_constant_turn")


def _line_of_key(text: str, key: str, after: str | None = None) -> int | None:
    """The line of ``"key"`` in ``text`` (its first occurrence, or its first after the key
    ``after``: ``persisting`` is a key of both models), None when absent."""
    start = 0
    if after is not None:
        start = max(text.find(f'"{after}"'), 0)
    pos = text.find(f'"{key}"', start)
    return None if pos < 0 else text.count("\n", 0, pos) + 1


#: The keys each object of ``bundle.json`` may hold (docs/bundle.md); keys starting with
#: ``x_`` are a writer's own and ignored. Any other key is refused, named, with the nearest
#: known key: a misspelt ``initial_pos`` must not fall back to the default silently.
_MANIFEST_KEYS = {
    "": (
        "format",
        "motion_model",
        "sensor_model",
        "initial_pose",
        "initial_covariance",
        "description",
        "time",
        "initialisation",
        "map_source",
    ),
    "motion_model": (
        "type",
        "integration",
        "control_stamp",
        "alpha",
        "pose_noise",
        "step_covariance",
        "persisting",
        *sorted({n for names in SIGMA_NAMES.values() for n in names}),
    ),
    "motion_model.persisting": MOTION_PERSISTING_KEYS,
    "motion_model.pose_noise": ("frame", "covariance"),
    "motion_model.step_covariance": ("frame",),
    "sensor_model": (
        "type",
        "sigma_range",
        "sigma_bearing",
        "max_range",
        "fov",
        "mount",
        "noise",
        "persisting",
        "outlier_share",
    ),
    "sensor_model.persisting": (
        "sigma_range",
        "sigma_bearing",
        "time_constant_range",
        "time_constant_bearing",
        "common",
    ),
    "sensor_model.persisting.common": (
        "sigma_range",
        "sigma_bearing",
        "time_constant_range",
        "time_constant_bearing",
    ),
}


def _refuse_unknown_keys(doc: dict[str, Any], where: str, text: str, path: str) -> None:
    """Refuse a key of ``doc`` (the object ``where``) that the format does not define."""
    import difflib

    known = _MANIFEST_KEYS[where]
    for key in doc:
        if key in known or (isinstance(key, str) and key.startswith("x_")):
            continue
        near = difflib.get_close_matches(str(key), known, n=1, cutoff=0.6)
        hint = f"; did you mean {near[0]!r}?" if near else ""
        inside = f" in {where}" if where else ""
        raise InputError(
            f"unknown key {_shown(key)}{inside}{hint} (expected some of {', '.join(known)}; "
            "a writer's own keys start with x_)",
            path=path,
            line=_line_of_key(text, str(key)),
        )


def _number(
    value: Any,
    *,
    what: str,
    path: str,
    line: int | None,
    minimum: float | None = 0.0,
    maximum: float | None = None,
) -> float:
    shown = _shown(value)
    if isinstance(value, int) and not isinstance(value, bool):  # JSON integers are exact
        value = float(value) if abs(value) < 2**1024 else math.inf  # beyond float64: inf
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise InputError(f"{what}: expected a finite number, got {shown}", path=path, line=line)
    if minimum is not None and value < minimum:
        raise InputError(
            f"{what}: expected a number >= {minimum}, got {shown}", path=path, line=line
        )
    if maximum is not None and abs(value) > maximum:
        raise InputError(
            f"{what}: expected a magnitude of at most {maximum:.0e} (squares and products of "
            f"it must stay inside float64), got {shown}",
            path=path,
            line=line,
        )
    return float(value)


def _numbers(
    value: Any,
    n: int,
    *,
    what: str,
    path: str,
    line: int | None,
    minimum: float | None,
    maximum: float | None = None,
) -> tuple[float, ...]:
    if not isinstance(value, list) or len(value) != n:
        raise InputError(
            f"{what}: expected a list of {n} numbers, got {_shown(value)}", path=path, line=line
        )
    return tuple(
        _number(v, what=what, path=path, line=line, minimum=minimum, maximum=maximum) for v in value
    )


def _check_psd(cov: Array, *, what: str, path: str, line: int | None) -> None:
    check_covariances(cov[None], path=path, lines=None if line is None else [line], what=what)


def _parse_motion(spec: Any, text: str, path: str) -> MotionModel:
    model = _parse_motion_noise(spec, text, path)
    if "persisting" not in spec:
        return model
    persisting = _parse_motion_persisting(spec["persisting"], text, path)
    try:
        return replace(model, persisting=persisting)
    except InputError as exc:  # e.g. stated for the odometry model
        raise InputError(
            str(exc), path=path, line=_line_of_key(text, "persisting", after="motion_model")
        ) from None


def _parse_motion_persisting(spec: Any, text: str, path: str) -> MotionPersisting:
    """``motion_model.persisting``: σ ≥ 0 and τ > 0 of the speed-scale and turn-per-metre
    Gauss–Markov errors (docs/bundle.md), each refused at its line."""
    where = "motion_model.persisting"
    line = _line_of_key(text, "persisting", after="motion_model")
    if not isinstance(spec, dict):
        raise InputError(f"{where}: expected an object", path=path, line=line)
    _refuse_unknown_keys(spec, where, text, path)
    vals = {}
    for n in MOTION_PERSISTING_KEYS:
        if n not in spec:
            raise InputError(f"{where}: missing {n}", path=path, line=line)
        at = _line_of_key(text, n)
        vals[n] = _number(spec[n], what=f"{where}.{n}", path=path, line=at, maximum=MAX_SIGMA)
        if n.startswith("time_constant") and not vals[n] > 0:
            raise InputError(
                f"{where}.{n}: expected a positive number of seconds, got {vals[n]}",
                path=path,
                line=at,
            )
    return MotionPersisting(**vals)


def _parse_motion_noise(spec: Any, text: str, path: str) -> MotionModel:
    line = _line_of_key(text, "motion_model")
    if not isinstance(spec, dict):
        raise InputError("motion_model: expected an object", path=path, line=line)
    _refuse_unknown_keys(spec, "motion_model", text, path)
    kind = spec.get("type")
    if kind not in MOTION_TYPES:
        raise InputError(
            f"motion_model: unknown type {_shown(kind)}; expected one of {', '.join(MOTION_TYPES)}",
            path=path,
            line=_line_of_key(text, "type") if kind is not None else line,
        )
    integration, stamp = _motion_options(spec, kind, text, path)
    names = SIGMA_NAMES[kind]
    forms = [
        form
        for form, given in (
            (", ".join(names), any(n in spec for n in names)),
            ("alpha", "alpha" in spec),
            ("pose_noise", "pose_noise" in spec),
            ("step_covariance", "step_covariance" in spec),
        )
        if given
    ]
    if len(forms) > 1:
        raise InputError(
            f"motion_model: give either {' or '.join(forms)}, not both",
            path=path,
            line=line,
        )
    if "step_covariance" in spec:
        return MotionModel(
            kind,
            step_covariance_frame=_parse_step_covariance(spec["step_covariance"], text, path),
            integration=integration,
            control_stamp=stamp,
        )
    if "pose_noise" in spec:
        frame, cov = _parse_pose_noise(spec["pose_noise"], text, path)
        return MotionModel(
            kind,
            pose_noise_frame=frame,
            pose_noise=cov,
            integration=integration,
            control_stamp=stamp,
        )
    if "alpha" in spec:
        alpha = _numbers(
            spec["alpha"],
            4,
            what="motion_model.alpha",
            path=path,
            line=_line_of_key(text, "alpha"),
            minimum=0.0,
            maximum=MAX_SIGMA,
        )
        return MotionModel(kind, alpha=alpha, integration=integration, control_stamp=stamp)
    missing = [n for n in names if n not in spec]
    if missing:
        raise InputError(
            f"motion_model ({kind}): missing {', '.join(missing)}; "
            f"expected {', '.join(names)}, alpha or pose_noise",
            path=path,
            line=line,
        )
    sigma = tuple(
        _number(
            spec[n],
            what=f"motion_model.{n}",
            path=path,
            line=_line_of_key(text, n),
            maximum=MAX_SIGMA,
        )
        for n in names
    )
    return MotionModel(kind, sigma=sigma, integration=integration, control_stamp=stamp)


def _motion_options(spec: dict[str, Any], kind: str, text: str, path: str) -> tuple[str, str]:
    """``integration`` and ``control_stamp`` (velocity model only; defaults when absent)."""
    out = {"integration": "arc", "control_stamp": "start"}
    for key, allowed in (("integration", INTEGRATIONS), ("control_stamp", CONTROL_STAMPS)):
        if key not in spec:
            continue
        where = _line_of_key(text, key)
        if kind != "velocity":
            raise InputError(
                f"motion_model.{key}: applies to the velocity model only; expected no {key} "
                f"for the {kind} model",
                path=path,
                line=where,
            )
        value = spec[key]
        if value not in allowed or not isinstance(value, str):
            raise InputError(
                f"motion_model.{key}: unknown value {_shown(value)}; expected one of "
                f"{', '.join(allowed)}",
                path=path,
                line=where,
            )
        out[key] = value
    return out["integration"], out["control_stamp"]


def _parse_step_covariance(spec: Any, text: str, path: str) -> str:
    """``step_covariance``: ``{"frame": "body" | "world"}`` (the values: step_covariance.csv)."""
    line = _line_of_key(text, "step_covariance")
    if not isinstance(spec, dict) or "frame" not in spec:
        raise InputError(
            "motion_model.step_covariance: expected an object with frame (body or world)",
            path=path,
            line=line,
        )
    _refuse_unknown_keys(spec, "motion_model.step_covariance", text, path)
    return _noise_frame(spec["frame"], "motion_model.step_covariance", path, line)


def _noise_frame(frame: Any, where: str, path: str, line: int | None) -> str:
    """``frame`` of a ``where`` object: one of :data:`POSE_NOISE_FRAMES`, else refused."""
    if not isinstance(frame, str) or frame not in POSE_NOISE_FRAMES:
        raise InputError(
            f"{where}.frame: unknown value {_shown(frame)}; expected one of "
            f"{', '.join(POSE_NOISE_FRAMES)}",
            path=path,
            line=line,
        )
    return frame


#: The columns of ``step_covariance.csv``: the time of the log row, then the upper triangle
#: of its 3 × 3 covariance (as ``online.csv``'s).
STEP_COVARIANCE_COLUMNS = ("t", "cxx", "cxy", "cxt", "cyy", "cyt", "ctt")


def _upper_to_full(cols: dict[str, Array]) -> Array:
    """(N, 3, 3) symmetric matrices from the columns ``cxx, cxy, cxt, cyy, cyt, ctt``."""
    cxx, cxy, cxt, cyy, cyt, ctt = (cols[c] for c in ONLINE_COVARIANCE_COLUMNS)
    return np.stack(
        (
            np.column_stack((cxx, cxy, cxt)),
            np.column_stack((cxy, cyy, cyt)),
            np.column_stack((cxt, cyt, ctt)),
        ),
        axis=1,
    )


def _read_step_covariances(root: Path, log_t: Array, log_name: str) -> Array:
    """``step_covariance.csv``: one covariance per row of the motion log, at the same times."""
    p = root / "step_covariance.csv"
    cols, lines = _read_csv(p, required=STEP_COVARIANCE_COLUMNS)
    cols, lines, _ = _time_ordered(cols, lines, p, "step covariance")
    t = cols["t"]
    if t.shape != log_t.shape or not np.array_equal(t, log_t):
        n = min(t.shape[0], log_t.shape[0])
        diff = np.flatnonzero(t[:n] != log_t[:n])
        k = int(diff[0]) if diff.size else n
        got = f"t = {float(t[k])!r}" if k < t.shape[0] else "no row"
        want = f"t = {float(log_t[k])!r}" if k < log_t.shape[0] else "no row"
        raise InputError(
            f"expected one row per row of {log_name}, at its times ({log_t.shape[0]} rows); "
            f"row {k + 1} has {got}, {log_name} {want}",
            path=p,
            line=int(lines[k]) if k < lines.shape[0] else None,
        )
    cov = _upper_to_full(cols)
    entry = np.abs(cov).max(axis=(1, 2))
    _refuse_first(
        entry > MAX_VARIANCE,
        lambda k: (
            f"step covariance: an entry of {float(entry[k]):.6g} is beyond "
            f"{MAX_VARIANCE:.0e} (the largest variance a motion model accepts: products of "
            "covariances must stay inside float64)"
        ),
        p,
        lines,
    )
    check_covariances(cov, path=str(p), lines=lines, what="step covariance")
    return cov


def _parse_pose_noise(spec: Any, text: str, path: str) -> tuple[str, tuple[tuple[float, ...], ...]]:
    """``pose_noise``: its ``frame`` and its 3 × 3 symmetric PSD ``covariance``."""
    line = _line_of_key(text, "pose_noise")
    if not isinstance(spec, dict):
        raise InputError(
            "motion_model.pose_noise: expected an object with frame and covariance",
            path=path,
            line=line,
        )
    _refuse_unknown_keys(spec, "motion_model.pose_noise", text, path)
    for key in ("frame", "covariance"):
        if key not in spec:
            raise InputError(f"motion_model.pose_noise: missing {key}", path=path, line=line)
    where = _line_of_key(text, "frame") or line
    frame = _noise_frame(spec["frame"], "motion_model.pose_noise", path, where)
    what = "motion_model.pose_noise.covariance"
    where = _line_of_key(text, "covariance") or line
    cov = spec["covariance"]
    if not isinstance(cov, list) or len(cov) != 3:
        raise InputError(f"{what}: expected a 3 x 3 list of lists", path=path, line=where)
    rows = tuple(
        _numbers(r, 3, what=what, path=path, line=where, minimum=None, maximum=MAX_VARIANCE)
        for r in cov
    )
    mat = np.array(rows)
    _check_psd(mat, what=what, path=path, line=where)
    if frame == "world" and not world_noise_is_rotation_invariant(mat):
        warnings.warn(
            f"{path}:{where}: {what}: a world-frame covariance that is not isotropic in x-y "
            "with zero x-theta and y-theta terms; the recovery turns it into the robot frame "
            "with the dead-reckoning heading of each step, an approximation where the "
            "filter's heading differs (docs/bundle.md, Motion models)",
            MotionModelWarning,
            stacklevel=4,
        )
    return frame, rows


def _parse_sensor(spec: Any, text: str, path: str) -> SensorModel:
    line = _line_of_key(text, "sensor_model")
    if not isinstance(spec, dict):
        raise InputError("sensor_model: expected an object", path=path, line=line)
    _refuse_unknown_keys(spec, "sensor_model", text, path)
    if spec.get("type") != "range_bearing":
        raise InputError(
            f"sensor_model: unknown type {_shown(spec.get('type'))}; expected range_bearing",
            path=path,
            line=line,
        )
    vals = []
    for n in ("sigma_range", "sigma_bearing"):
        if n not in spec:
            raise InputError(f"sensor_model: missing {n}", path=path, line=line)
        v = _number(
            spec[n],
            what=f"sensor_model.{n}",
            path=path,
            line=_line_of_key(text, n),
            maximum=MAX_SIGMA,
        )
        if v <= 0:
            raise InputError(
                f"sensor_model.{n}: expected a positive number, got {v}",
                path=path,
                line=_line_of_key(text, n),
            )
        if v < MIN_SENSOR_SIGMA:
            raise InputError(
                f"sensor_model.{n}: {v:g} is below {MIN_SENSOR_SIGMA:g}: its variance "
                f"{v:g}² is not a float64 number (it rounds to {v * v:g}, the noise-free "
                "sensor that 0 states, whose measurements would weigh infinitely); expected a "
                f"standard deviation of at least {MIN_SENSOR_SIGMA:g}",
                path=path,
                line=_line_of_key(text, n),
            )
        vals.append(v)
    reach: dict[str, float] = {}
    for n in ("max_range", "fov"):  # optional: the sensor's reach, when the writer knows it
        if n in spec:
            where = _line_of_key(text, n)
            reach[n] = _number(spec[n], what=f"sensor_model.{n}", path=path, line=where)
            if not 0 < reach[n] <= (2 * math.pi if n == "fov" else math.inf):
                bound = "a positive number" if n == "max_range" else "an angle in (0, 2π]"
                raise InputError(
                    f"sensor_model.{n}: expected {bound}, got {reach[n]}", path=path, line=where
                )
    mount = None
    if "mount" in spec:  # the sensor's pose in the robot frame
        mount = _numbers(
            spec["mount"],
            3,
            what="sensor_model.mount",
            path=path,
            line=_line_of_key(text, "mount"),
            minimum=None,
            maximum=MAX_SIGMA,
        )
    noise = spec.get("noise", "assumed")
    if noise not in SENSOR_NOISE_SOURCES or not isinstance(noise, str):
        raise InputError(
            f"sensor_model.noise: unknown value {_shown(noise)}; expected one of "
            f"{', '.join(SENSOR_NOISE_SOURCES)}",
            path=path,
            line=_line_of_key(text, "noise"),
        )
    persisting = None
    if "persisting" in spec:  # a Gauss–Markov bias per landmark track (recovery.persisting)
        persisting = _parse_persisting(spec["persisting"], text, path)
    share = None
    if "outlier_share" in spec:  # gross errors the σ do not describe (the verdict's map–log)
        where = _line_of_key(text, "outlier_share")
        share = _number(spec["outlier_share"], what="sensor_model.outlier_share", path=path,
                        line=where)  # fmt: skip
        try:
            checked_outlier_share(share)
        except InputError as exc:
            raise InputError(str(exc), path=path, line=where) from None
    return SensorModel(
        vals[0],
        vals[1],
        max_range=reach.get("max_range"),
        fov=reach.get("fov"),
        mount=mount,  # type: ignore[arg-type]
        noise=noise,
        persisting=persisting,
        outlier_share=share,
    )


def _parse_persisting(
    spec: Any, text: str, path: str, where: str = "sensor_model.persisting"
) -> PersistingError:
    """``sensor_model.persisting``: four positive numbers and an optional ``common`` object
    of the same four (docs/bundle.md)."""
    line = _line_of_key(text, where.rsplit(".", 1)[1], after="sensor_model")
    if not isinstance(spec, dict):
        raise InputError(f"{where}: expected an object", path=path, line=line)
    _refuse_unknown_keys(spec, where, text, path)
    common = None
    if "common" in spec and where == "sensor_model.persisting":
        common = _parse_persisting(spec["common"], text, path, where + ".common")
    vals = {}
    for n in PERSISTING_KEYS:
        if n not in spec:
            raise InputError(f"{where}: missing {n}", path=path, line=line)
        vals[n] = _number(
            spec[n],
            what=f"{where}.{n}",
            path=path,
            line=_line_of_key(text, n),
            maximum=MAX_SIGMA,
        )
        if not vals[n] > 0:
            raise InputError(
                f"{where}.{n}: expected a positive number, got {vals[n]}",
                path=path,
                line=_line_of_key(text, n),
            )
    try:
        return PersistingError(**vals, common=common)
    except InputError as exc:
        raise InputError(str(exc), path=path, line=line) from None


PERSISTING_KEYS = ("sigma_range", "sigma_bearing", "time_constant_range", "time_constant_bearing")


def _read_manifest(path: Path) -> dict[str, Any]:
    name = str(path)
    text = read_text(path)
    try:
        doc: Any = loads_json(text, path=name)
    except json.JSONDecodeError as exc:
        raise InputError(f"not valid JSON: {exc.msg}", path=name, line=exc.lineno) from None
    except RecursionError:
        raise InputError("JSON nested too deeply; expected a bundle manifest", path=name) from None
    if not isinstance(doc, dict):
        raise InputError("expected a JSON object", path=name, line=1)
    if doc.get("format") != FORMAT:
        raise InputError(
            f"format: expected {FORMAT!r}, got {_shown(doc.get('format'))}",
            path=name,
            line=_line_of_key(text, "format"),
        )
    _refuse_unknown_keys(doc, "", text, name)
    for key in ("motion_model", "sensor_model"):
        if key not in doc:
            raise InputError(f"missing {key}", path=name)
    out: dict[str, Any] = {
        "motion": _parse_motion(doc["motion_model"], text, name),
        "sensor": _parse_sensor(doc["sensor_model"], text, name),
        "description": str(doc.get("description", "")),
    }
    for key, allowed in (("time", TIME_UNITS), ("initialisation", INITIALISATIONS)):
        if key in doc:
            if not isinstance(doc[key], str) or doc[key] not in allowed:
                raise InputError(
                    f"{key}: unknown value {_shown(doc[key])}; expected one of "
                    f"{', '.join(allowed)}",
                    path=name,
                    line=_line_of_key(text, key),
                )
            out[key] = doc[key]
    source = doc.get("map_source")
    if source is not None:  # where the map came from (docs/bundle.md); absent: not stated
        if source not in MAP_SOURCES:
            raise InputError(
                f"map_source: expected one of {', '.join(map(repr, MAP_SOURCES))}, got "
                f"{_shown(source)}",
                path=name,
                line=_line_of_key(text, "map_source"),
            )
        out["map_source"] = source
    pose = doc.get("initial_pose", [0.0, 0.0, 0.0])
    out["initial_pose"] = np.array(
        _numbers(
            pose,
            3,
            what="initial_pose",
            path=name,
            line=_line_of_key(text, "initial_pose"),
            minimum=None,
        )
    )
    _check_initial_pose(out["initial_pose"], name, _line_of_key(text, "initial_pose"))
    cov = doc.get("initial_covariance")
    if cov is None:
        out["initial_covariance"] = 1e-9 * np.eye(3)
    else:
        line = _line_of_key(text, "initial_covariance")
        if not isinstance(cov, list) or len(cov) != 3:
            raise InputError(
                "initial_covariance: expected a 3 x 3 list of lists", path=name, line=line
            )
        rows = [
            _numbers(
                r,
                3,
                what="initial_covariance",
                path=name,
                line=line,
                minimum=None,
                maximum=MAX_VARIANCE,
            )
            for r in cov
        ]
        mat = np.array(rows)
        _check_psd(mat, what="initial_covariance", path=name, line=line)
        out["initial_covariance"] = mat
    return out


def _check_initial_pose(pose: Array, path: str, line: int | None) -> None:
    """``initial_pose`` ``[x, y, θ]``: a position within ``MAX_COORDINATE`` (as every other
    position slamrel reads) and a heading within it too (an angle of 1e31 rad is no heading)."""
    big = np.flatnonzero(np.abs(pose) > MAX_COORDINATE)
    if big.size:
        k = int(big[0])
        raise InputError(
            f"initial_pose: {'x y θ'.split()[k]} = {float(pose[k]):.6g} is beyond "
            f"{MAX_COORDINATE:.0e} (m, or rad for θ); expected a pose in the map frame",
            path=path,
            line=line,
        )


def _check_controls(
    cols: dict[str, Array], lines: NDArray[np.int64], path: Path, control_stamp: str
) -> None:
    """``controls.csv`` in time order: the times span some time, and speeds, yaw rates, the
    path ``Σ |v_k| Δt_k`` and the turn ``Σ |ω_k| Δt_k`` of the held rows stay within
    ``MAX_COORDINATE`` (m, rad), as every position slamrel reads: beyond it, the squares
    and products of the dead-reckoned poses leave float64.

    The first offending row is named by its line (``lines`` (K,), in time order).
    """
    t, v, w = cols["t"], cols["v"], cols["omega"]
    if t.shape[0] >= 2 and t[-1] == t[0]:
        raise InputError(
            f"all {t.shape[0]} control rows have t = {float(t[0])!r}: the controls span no "
            "time; expected increasing times (the last row ends the run)",
            path=path,
            line=int(lines[-1]),
        )
    dt = np.diff(t)
    held = slice(1, None) if control_stamp == "end" else slice(None, -1)
    hrow = np.arange(t.shape[0])[held]
    for name, x, unit, what in (("v", v, "m", "path"), ("omega", w, "rad", "turn")):
        big = np.abs(x) > MAX_COORDINATE
        with np.errstate(over="ignore"):
            run = np.cumsum(np.abs(x[held]) * dt)
        far = np.zeros_like(big)
        far[hrow] = ~(run <= MAX_COORDINATE)
        _refuse_first(big | far, partial(_control_beyond, name, x, unit, what), path, lines)


def _control_beyond(name: str, x: Array, unit: str, what: str, k: int) -> str:
    """The message of :func:`_check_controls` about row ``k`` of column ``name`` (``x``)."""
    beyond = (
        f"beyond {MAX_COORDINATE:.0e} {unit}/s"
        if abs(x[k]) > MAX_COORDINATE
        else f"the controls' {what} up to this row is beyond {MAX_COORDINATE:.0e} {unit}"
    )
    return (
        f"{name} = {float(x[k]):.6g}: {beyond} (their squares and products must stay inside "
        f"float64); expected {'speeds in m/s' if name == 'v' else 'yaw rates in rad/s'}"
    )


def _read_csv(
    path: Path,
    *,
    required: Sequence[str],
    optional: Sequence[str] = (),
    empty_ok: Sequence[str] = (),
) -> tuple[dict[str, Array], NDArray[np.int64]]:
    """Columns by name (empty cells of ``empty_ok`` columns are NaN) and each row's line."""
    if not path.is_file():
        raise InputError(f"missing required file; expected columns {','.join(required)}", path=path)
    return read_csv_table(path, required=required, optional=optional, empty_ok=empty_ok)


def _read_csv_with_ids(
    path: Path,
    *,
    required: Sequence[str],
    id_column: str,
    empty_ok: Sequence[str] = (),
    optional: Sequence[str] = (),
) -> tuple[dict[str, Any], NDArray[np.int64]]:
    """:func:`_read_csv` with ``id_column`` (may be empty) read as exact int64 ids.

    The ids come from the text (:func:`~slamrel.formats.text.read_csv_id_column`), never
    through float64; ``cols[id_column + "#"]`` says which cells are not empty.
    """
    if not path.is_file():
        raise InputError(f"missing required file; expected columns {','.join(required)}", path=path)
    src = read_source(path)
    cols, lines = read_csv_table(
        path,
        required=required,
        optional=optional,
        empty_ok=(id_column,),
        nonfinite_ok=empty_ok,
        source=src,
    )
    ids, present = read_csv_id_column(src, id_column, lines, empty_ok=True)
    out: dict[str, Any] = {**cols, id_column: ids, id_column + "#": present}
    return out, lines


def _time_ordered(
    cols: dict[str, Array], lines: NDArray[np.int64], path: Path, what: str
) -> tuple[dict[str, Array], NDArray[np.int64], int]:
    """The rows of a log in time order under the filter-log rule (``relation_metric.timeorder``).

    Steps back of at most ``FILTER_TIME_TOLERANCE`` are stable-sorted, counted (returned)
    and warned about; a larger one raises :class:`InputError` with the line and both times.
    """
    order, report = sort_by_time(
        cols["t"], tolerance=FILTER_TIME_TOLERANCE, lines=lines, path=path, what=what
    )
    if not report.out_of_order:
        return cols, lines, 0
    warnings.warn(
        f"{path}: {report.describe(what)}; put in time order", TimeOrderWarning, stacklevel=3
    )
    return {k: v[order] for k, v in cols.items()}, lines[order], report.out_of_order


def _load_matrix(path: Path, n: int, *, what: str) -> Array:
    """A float ``.npy`` matrix of shape (n, n), with a clear :class:`InputError` otherwise.

    The header is checked before the data is read; pickled objects are never loaded.
    """
    expected = f"expected a NumPy .npy file with a float array of shape ({n}, {n}) {what}"
    fmt = np.lib.format
    try:
        with open(path, "rb") as handle:
            version = fmt.read_magic(handle)
            if version == (1, 0):
                shape, _, dtype = fmt.read_array_header_1_0(handle)
            else:
                shape, _, dtype = fmt.read_array_header_2_0(handle)
    except Exception:  # noqa: BLE001 - any malformed header: say what was expected
        raise InputError(f"not a readable .npy file; {expected}", path=path) from None
    if dtype.hasobject:
        raise InputError(f"holds Python objects (pickled; never loaded); {expected}", path=path)
    if dtype.kind not in "fi" or dtype.fields is not None:
        got = "a structured array" if dtype.fields is not None else dtype.name
        raise InputError(f"expected real float64, got {got}; {expected}", path=path)
    if tuple(shape) != (n, n):
        shown = " x ".join(str(d) for d in shape) or "a scalar"
        raise InputError(f"holds an array of shape {shown}; {expected}", path=path)
    try:
        arr = np.load(path, allow_pickle=False)
    except Exception:  # noqa: BLE001 - a cut-off or corrupt body
        raise InputError(f"cannot read the array (cut off?); {expected}", path=path) from None
    return np.asarray(arr, dtype=np.float64)


def read_bundle(
    directory: PathLike,
    *,
    skip_unknown_landmarks: bool = False,
    skip_invalid_measurements: bool = False,
) -> Bundle:
    """Read and validate a SLAM result bundle.

    Parsing only: each file is read (with its own line-precise checks: columns, numbers,
    time order, ids, landmark covariances), then the :class:`Bundle` constructor checks
    the whole (shapes, ranges, known landmarks, covariances) and names the file and line.

    Parameters
    ----------
    directory : str or PathLike
        The bundle directory.
    skip_unknown_landmarks : bool
        Drop (and count in ``Bundle.skipped_unknown``) measurements whose landmark is not in
        ``map.csv`` instead of raising.
    skip_invalid_measurements : bool
        Drop (and count in ``Bundle.skipped_invalid``, with an
        :class:`InvalidMeasurementWarning` naming the first line) measurements with a range
        ≤ 0 or a non-finite or empty range or bearing instead of raising.

    Returns
    -------
    Bundle

    Raises
    ------
    InputError
        For every defect listed in ``docs/bundle.md``, naming file, line and what was expected.
    """
    root = Path(directory)
    if not root.is_dir():
        raise InputError("not a directory; expected a SLAM result bundle", path=root)
    manifest = root / "bundle.json"
    if not manifest.is_file():
        raise InputError("missing required file bundle.json", path=manifest)
    meta = _read_manifest(manifest)
    reordered: dict[str, int] = {}
    log = _read_motion_log(root, meta["motion"], reordered)
    map_fields = _read_map(root)
    wrapped: dict[str, int] = {}
    meas = _read_measurements(root, reordered, wrapped, skip_invalid_measurements)
    skipped_invalid = meas.pop("skipped_invalid")
    skipped = 0
    if skip_unknown_landmarks:
        unknown = meas["measurement_associated"] & ~np.isin(
            meas["measurement_landmarks"], map_fields["map_ids"]
        )
        skipped = int(unknown.sum())
        meas = {k: v[~unknown] for k, v in meas.items()}
    log_name = "controls.csv" if meta["motion"].type == "velocity" else "odometry.csv"
    log_t = log["controls"][:, 0] if "controls" in log else log["odometry"].timestamps
    if meta["motion"].step_covariance_frame is not None:
        log["step_covariances"] = _read_step_covariances(root, log_t, log_name)
    if meta.get("time") == "steps":
        _check_steps((log_t, root / log_name, None), meas)
    snapped = 0
    if log_t.shape[0] >= 2:  # else the Bundle refuses the log (at least two rows)
        meas, snapped = _snap_measurements(meas, log_t, root / "measurements.csv", log_name)
        _warn_outside(meas, log_t, meta["motion"], root / "measurements.csv", log_name)
    return Bundle(
        **meta,
        **log,
        **map_fields,
        **meas,
        **_read_truth(root, reordered),
        skipped_unknown=skipped,
        path=str(root),
        reordered=reordered,
        snapped=snapped,
        wrapped_bearings=wrapped["measurements.csv"],
        skipped_invalid=skipped_invalid,
    )


def _refuse_first(bad: NDArray[Any], message: Callable[[int], str], path: Path, lines: Any) -> None:
    """:class:`InputError` at the first row where ``bad`` (J,) holds, if any: the message of
    its index, its line (``lines`` (J,), or None)."""
    hit = np.flatnonzero(bad)
    if hit.size:
        k = int(hit[0])
        raise InputError(message(k), path=path, line=None if lines is None else int(lines[k]))


def _not_a_step(t: Array, k: int) -> str:
    """The message of a ``t`` that is no step index (``"time": "steps"``)."""
    return (
        f"t = {float(t[k])!r}: expected a step index (an integer), as the manifest's "
        '"time": "steps" says'
    )


def _check_steps(log: tuple[Array, Path, None], meas: dict[str, Any]) -> None:
    """``"time": "steps"``: every time of the log and the measurements is a step index."""
    log_t, log_path, _ = log
    for t, path, lines in (
        (log_t, log_path, None),
        (
            meas["measurement_times"],
            log_path.parent / "measurements.csv",
            meas["measurement_lines"],
        ),
    ):
        _refuse_first(
            t != np.round(t),
            partial(_not_a_step, t),
            path,
            lines,
        )


def _snap_measurements(
    meas: dict[str, Any], log_t: Array, path: Path, log_name: str
) -> tuple[dict[str, Any], int]:
    """Measurement times within ``SNAP_TOLERANCE`` of a log time set to it, counted and warned.

    Times written with a few decimals (``0.3``) next to times computed in float
    (``0.30000000000000004``) would otherwise cut a control row into a piece of 10⁻¹⁷ s and
    the rest: a second pose on the recovery grid for every such measurement.
    """
    t, moved = snap_times(meas["measurement_times"], log_t)
    hit = np.flatnonzero(moved != 0.0)
    if not hit.size:
        return meas, 0
    first = int(hit[0])
    line = int(meas["measurement_lines"][first])
    warnings.warn(
        f"{path}:{line}: {hit.size} measurement time(s) within {SNAP_TOLERANCE:g} s of a "
        f"{log_name} time but not equal to it (largest difference "
        f"{float(np.abs(moved).max()):.3g} s; first t = {float(meas['measurement_times'][first])!r}"
        f" vs {float(t[first])!r}); snapped to that time, so that float noise does not split "
        "the recovery grid",
        TimeOrderWarning,
        stacklevel=3,
    )
    out = dict(meas, measurement_times=t)
    if (np.diff(t) < 0).any():  # two log times closer than 2 SNAP_TOLERANCE: keep time order
        order = np.argsort(t, kind="stable")
        out = {k: v[order] for k, v in out.items()}
    return out, int(hit.size)


def _warn_outside(
    meas: dict[str, Any], log_t: Array, motion: MotionModel, path: Path, log_name: str
) -> None:
    """Warn once about measurements before the first or after the last log row (never used)."""
    t = meas["measurement_times"]
    t0, t1 = float(log_t[0]), float(log_t[-1])
    out = np.flatnonzero((t < t0) | (t > t1))
    if not out.size:
        return
    first = int(out[0])
    after = int((t > t1).sum())
    why = []
    if after:
        why.append(
            f"{after} after the last row of {log_name}"
            + (
                ' (with control_stamp "start" the last row only closes the log: its v, omega '
                "are never used, so a log ends with a row at or after its last measurement)"
                if motion.type == "velocity" and motion.control_stamp == "start"
                else ""
            )
        )
    if out.size > after:
        why.append(
            f"{out.size - after} before its first row"
            + (
                ' (with control_stamp "end" the first row only opens the log: its v, omega '
                "are never used)"
                if motion.type == "velocity" and motion.control_stamp == "end"
                else ""
            )
        )
    warnings.warn(
        f"{path}:{int(meas['measurement_lines'][first])}: {out.size} measurement(s) outside the "
        f"span [{t0:.17g}, {t1:.17g}] s of {log_name}, first at t = {float(t[first])!r}: "
        f"{'; '.join(why)}; they are counted as outside and not used",
        TimeOrderWarning,
        stacklevel=3,
    )


def _read_motion_log(root: Path, motion: MotionModel, reordered: dict[str, int]) -> dict[str, Any]:
    """``controls`` (velocity model) or ``odometry`` (odometry model), in time order."""
    if motion.type == "velocity":
        p = root / "controls.csv"
        cols, lines = _read_csv(p, required=("t", "v", "omega"))
        cols, lines, reordered[p.name] = _time_ordered(cols, lines, p, "control")
        _check_controls(cols, lines, p, motion.control_stamp)
        return {"controls": np.column_stack((cols["t"], cols["v"], cols["omega"]))}
    p = root / "odometry.csv"
    if not p.is_file():
        raise InputError(f"missing required file; expected columns {CSV_HEADER}", path=p)
    odometry, reordered[p.name] = _read_pose_log(p, "odometry pose")
    t = odometry.timestamps
    if t.shape[0] >= 2 and t[-1] == t[0]:
        raise InputError(
            f"all {t.shape[0]} odometry rows have t = {float(t[0])!r}: the odometry spans no "
            "time; expected increasing times (the last row ends the run)",
            path=p,
        )
    return {"odometry": odometry}


def _read_pose_log(path: Path, what: str) -> tuple[Trajectory, int]:
    """A ``t,x,y,theta`` log (``odometry.csv``, ``groundtruth.csv``) under the filter-log rule.

    The one reader of that CSV (``read_trajectory(format="csv")``), with steps back of at
    most ``FILTER_TIME_TOLERANCE`` sorted, counted (returned) and warned about, larger ones an
    :class:`InputError` (``relation_metric.timeorder``).
    """
    loaded = read_trajectory(path, format="csv", max_step_back=FILTER_TIME_TOLERANCE, what=what)
    return loaded.trajectory, loaded.out_of_order


def _read_map(root: Path) -> dict[str, Any]:
    """``map.csv`` (ids, positions, marginals: zeros where none given) and the joint covariance."""
    p_map = root / "map.csv"
    if not p_map.is_file():
        raise InputError("missing required file; expected columns landmark,x,y", path=p_map)
    table = read_landmark_csv(p_map, describe="the bundle's map")
    m = table.ids.shape[0]
    marg = np.zeros((m, 2, 2)) if table.cov is None else np.nan_to_num(table.cov, nan=0.0)
    p_cov = root / "map_covariance.npy"
    cov = _load_matrix(p_cov, 2 * m, what=f"for {m} landmarks") if p_cov.exists() else None
    if cov is not None and table.cov is not None:
        _check_joint_order(cov, marg, table.ids, p_cov, p_map)
    return {"map_ids": table.ids, "map_xy": table.xy, "map_marginals": marg, "map_covariance": cov}


def _check_joint_order(
    cov: Array, marg: Array, ids: NDArray[np.int64], p_cov: Path, p_map: Path
) -> None:
    """The joint covariance's diagonal blocks must be ``map.csv``'s covariances, landmark by
    landmark, within a relative 1e-6 of the landmark's largest entry: a joint covariance in
    another landmark order than ``map.csv`` (which nothing else would notice) is refused."""
    check_joint_covariance(cov, path=p_cov, what="map covariance")  # its own defects first
    m = ids.shape[0]
    ar = np.arange(m)
    blocks = cov.reshape(m, 2, m, 2)[ar, :, ar, :]
    scale = np.maximum(np.abs(blocks).max(axis=(1, 2)), np.abs(marg).max(axis=(1, 2)))
    off = np.abs(blocks - marg).max(axis=(1, 2)) > 1e-6 * scale
    if not off.any():
        return
    k = int(np.flatnonzero(off)[0])
    raise InputError(
        f"its diagonal block {k} (rows {2 * k}, {2 * k + 1}) is not the covariance map.csv "
        f"gives landmark {int(ids[k])} (row {k + 1} of map.csv: cxx {marg[k, 0, 0]:.6g}, cyy "
        f"{marg[k, 1, 1]:.6g}; the block: {blocks[k, 0, 0]:.6g}, {blocks[k, 1, 1]:.6g}; "
        f"{int(off.sum())} of {m} landmarks differ); expected the joint covariance with its "
        f"landmarks in map.csv's order ({p_map.name})",
        path=p_cov,
    )


class BearingWrapWarning(UserWarning):
    """Bearings outside [−π, π) were wrapped into it (and counted)."""


def _wrapped_bearings(b: Array, lines: NDArray[np.int64], path: Path) -> tuple[Array, int]:
    """Bearings wrapped into ``[−π, π)``; how many were outside; beyond ``[−2π, 2π]`` refused.

    A bearing in ``[π, 2π]`` (a ``[0, 2π)`` convention) or ``[−2π, −π)`` names the same
    direction: wrapped, counted, warned about. A larger magnitude is no bearing in radians
    (degrees?) and is refused with its line.
    """
    far = np.flatnonzero(~(np.abs(b) <= 2 * math.pi))
    if far.size:
        k = int(far[0])
        raise InputError(
            f"bearing {float(b[k]):.9g}: expected an angle in radians in [-pi, pi) (values up "
            "to 2 pi in magnitude are wrapped); is it in degrees?",
            path=path,
            line=int(lines[k]),
        )
    out = ~((b >= -math.pi) & (b < math.pi))
    count = int(np.count_nonzero(out))
    if not count:
        return b, 0
    k = int(np.flatnonzero(out)[0])
    warnings.warn(
        f"{path}:{int(lines[k])}: {count} bearing(s) outside [-pi, pi) wrapped into it (first "
        f"{float(b[k]):.9g} rad)",
        BearingWrapWarning,
        stacklevel=4,
    )
    return np.where(out, np.mod(b + math.pi, 2 * math.pi) - math.pi, b), count


class InvalidMeasurementWarning(UserWarning):
    """Measurements with a range ≤ 0 or a non-finite range or bearing were skipped (counted)."""


#: The parameter that skips invalid measurements, named in the reader's error (the command
#: line says its own option for it).
SKIP_INVALID_OPTION = "skip_invalid_measurements=True"


def _drop_invalid(
    cols: dict[str, Any], lines: NDArray[np.int64], path: Path, skip: bool
) -> tuple[dict[str, Any], NDArray[np.int64], int]:
    """Rows with a range ≤ 0 or a non-finite (or empty) range or bearing: refused, or dropped.

    Without ``skip`` the first such row is an :class:`InputError` naming its line and the
    option; with it they are all dropped, counted (returned) and warned about once (the
    count, the first line, the first value).
    """
    r, b = cols["range"], cols["bearing"]
    bad = ~(np.isfinite(r) & np.isfinite(b) & (r > 0))
    count = int(np.count_nonzero(bad))
    if not count:
        return cols, lines, 0
    k = int(np.flatnonzero(bad)[0])
    bad_range = not (np.isfinite(r[k]) and r[k] > 0)
    what = f"range {float(r[k])!r}" if bad_range else f"bearing {float(b[k])!r}"
    if not skip:
        raise InputError(
            f"{what}: expected a positive range and a finite bearing ({count} such "
            f"measurement(s)); {SKIP_INVALID_OPTION} skips and counts them",
            path=path,
            line=int(lines[k]),
        )
    warnings.warn(
        f"{path}:{int(lines[k])}: {count} measurement(s) with a range <= 0 or a non-finite "
        f"range or bearing skipped (first: {what}); counted as skipped_invalid",
        InvalidMeasurementWarning,
        stacklevel=4,
    )
    keep = ~bad
    return {k2: v[keep] for k2, v in cols.items()}, lines[keep], count


def _read_measurements(
    root: Path, reordered: dict[str, int], wrapped: dict[str, int], skip_invalid: bool = False
) -> dict[str, Any]:
    """``measurements.csv`` in time order: the five ``measurement*`` fields of the bundle,
    and ``skipped_invalid`` (see :func:`_drop_invalid`)."""
    p = root / "measurements.csv"
    cols, lines = _read_csv_with_ids(
        p,
        required=("t", "range", "bearing", "landmark"),
        id_column="landmark",
        empty_ok=("range", "bearing"),
        optional=("processed",),
    )
    cols, lines, skipped = _drop_invalid(cols, lines, p, skip_invalid)
    cols, lines, reordered[p.name] = _time_ordered(cols, lines, p, "measurement")
    bearing, wrapped[p.name] = _wrapped_bearings(cols["bearing"], lines, p)
    out = {
        "measurement_times": cols["t"],
        "measurements": np.column_stack((cols["range"], bearing)),
        "measurement_landmarks": cols["landmark"].astype(np.int64),
        "measurement_associated": cols["landmark#"].astype(bool),
        "measurement_lines": lines,
    }
    unprocessed = _unprocessed(cols, lines, p)
    if unprocessed is not None:  # (every field here is a row array: filtered and sorted alike)
        out["measurement_unprocessed"] = unprocessed
    return out | {"skipped_invalid": skipped}


def _unprocessed(cols: dict[str, Any], lines: NDArray[np.int64], path: Path) -> Any:
    """The optional ``processed`` column (1: processed, the default; 0: a frame the filter
    never processed) as the unprocessed mask, ``None`` without the column."""
    if "processed" not in cols:
        return None
    v = cols["processed"]
    _refuse_first(
        (v != 0) & (v != 1),
        lambda k: (
            f"processed {float(v[k]):g}: expected 1 (the filter processed this frame) "
            "or 0 (it never processed it)"
        ),
        path,
        lines,
    )
    return v == 0


def _read_truth(root: Path, reordered: dict[str, int]) -> dict[str, Any]:
    """``groundtruth.csv`` and ``landmarks_groundtruth.csv`` when present (else None)."""
    out: dict[str, Any] = {"groundtruth": None, "landmarks_groundtruth": None}
    if (root / "groundtruth.csv").exists():
        out["groundtruth"], reordered["groundtruth.csv"] = _read_pose_log(
            root / "groundtruth.csv", "pose"
        )
    p_lgt = root / "landmarks_groundtruth.csv"
    if p_lgt.exists():
        table = read_landmark_csv(p_lgt, covariance=False, describe="landmark ground truth")
        out["landmarks_groundtruth"] = (table.ids, table.xy)
    return out


def write_bundle(
    directory: PathLike,
    bundle: Bundle,
    *,
    force: bool = True,
    extra: Callable[[Path], None] | None = None,
) -> None:
    """Write ``bundle`` as a bundle directory, replaced as a whole (round-trips exactly).

    The files are written into a hidden folder beside ``directory`` that is swapped in only
    when complete (:func:`slamrel.outputs.staged_directory`): no file of an earlier
    bundle survives (a stale ``groundtruth.csv`` or ``map_covariance.npy``), and an error or
    Ctrl-C leaves the previous folder exactly as it was.

    Parameters
    ----------
    directory : str or PathLike
    bundle : Bundle
    force : bool
        May an existing non-empty folder that slamrel wrote be replaced (default yes)? A
        folder slamrel did not write is never replaced (:class:`InputError`).
    extra : callable, optional
        Called with the staged folder to add more files (e.g. ``online.csv``) before the swap.
    """
    with staged_directory(directory, kind="bundle", force=force) as root:
        _write_bundle_files(root, bundle)
        if extra is not None:
            extra(root)


def _write_bundle_files(root: Path, bundle: Bundle) -> None:
    """Write the files of ``bundle`` into the (new, empty) folder ``root``."""
    meta = {
        "format": FORMAT,
        "motion_model": bundle.motion.as_dict(),
        "sensor_model": bundle.sensor.as_dict(),
        "initial_pose": [float(v) for v in bundle.initial_pose],
        "initial_covariance": [[float(v) for v in row] for row in bundle.initial_covariance],
        "description": bundle.description,
    }
    for key, default in (("time", "seconds"), ("initialisation", "updates")):
        if getattr(bundle, key) != default:  # written when stated (older bundles unchanged)
            meta[key] = getattr(bundle, key)
    if bundle.map_source is not None:  # only then: bundles that do not say keep their bytes
        meta["map_source"] = bundle.map_source
    write_text_atomic(root / "bundle.json", json.dumps(meta, indent=2) + "\n")
    if bundle.controls is not None:
        c = bundle.controls
        write_csv_table(root / "controls.csv", ["t", "v", "omega"], [c[:, 0], c[:, 1], c[:, 2]])
    if bundle.odometry is not None:
        write_trajectory(root / "odometry.csv", bundle.odometry, format="csv")
    if bundle.step_covariances is not None:
        c, lt = (
            bundle.step_covariances,
            (
                bundle.controls[:, 0] if bundle.controls is not None else bundle.odometry.timestamps  # type: ignore[union-attr]
            ),
        )
        write_csv_table(
            root / "step_covariance.csv",
            list(STEP_COVARIANCE_COLUMNS),
            [lt, c[:, 0, 0], c[:, 0, 1], c[:, 0, 2], c[:, 1, 1], c[:, 1, 2], c[:, 2, 2]],
        )
    write_measurements(
        root / "measurements.csv",
        bundle.measurement_times,
        bundle.measurements,
        bundle.measurement_landmarks,
        bundle.measurement_associated,
        bundle.measurement_unprocessed,
    )
    write_landmark_csv(root / "map.csv", bundle.map_ids, bundle.map_xy, bundle.map_marginals)
    if bundle.map_covariance is not None:
        buf = io.BytesIO()
        np.save(buf, np.asarray(bundle.map_covariance), allow_pickle=False)
        write_bytes_atomic(root / "map_covariance.npy", buf.getvalue())
    if bundle.groundtruth is not None:
        write_trajectory(root / "groundtruth.csv", bundle.groundtruth, format="csv")
    if bundle.landmarks_groundtruth is not None:
        write_landmark_csv(root / "landmarks_groundtruth.csv", *bundle.landmarks_groundtruth)


def write_measurements(
    path: PathLike,
    t: Array,
    z: Array,
    landmarks: NDArray[Any],
    associated: NDArray[Any],
    unprocessed: NDArray[Any] | None = None,
) -> None:
    """Write ``measurements.csv`` atomically: ``t,range,bearing`` (``%.17g``) for ``t`` (J,)
    and ``z`` (J, 2), and the ``landmark`` id (``%d``; empty where not ``associated``); with
    ``unprocessed`` (J,) holding a True, a ``processed`` column (0 where True)."""
    rows = format_csv_table(["t", "range", "bearing"], [t, z[:, 0], z[:, 1]]).splitlines()
    ids = np.where(associated, np.asarray(landmarks).astype(np.int64).astype(str), "")
    if unprocessed is not None and np.any(unprocessed):
        ids = np.char.add(ids, np.where(unprocessed, ",0", ",1"))
        head = "t,range,bearing,landmark,processed\n"
    else:
        head = "t,range,bearing,landmark\n"
    text = head + "".join(f"{r},{i}\n" for r, i in zip(rows[1:], ids))
    write_text_atomic(path, text)


class OnlineEstimate(NamedTuple):
    """A bundle's ``online.csv``: the SLAM filter's own pose estimate (validation only).

    Attributes
    ----------
    trajectory : Trajectory
        In time order, in the map frame.
    covariances : ndarray, shape (N, 3, 3), or None
        One per pose of ``trajectory`` (rows ``[x, y, θ]``); ``None`` when the file has no
        covariance columns.
    """

    trajectory: Trajectory
    covariances: Array | None


def read_online(path: PathLike) -> OnlineEstimate:
    """Read an ``online.csv`` (docs/bundle.md): ``t,x,y,theta[,cxx,cxy,cxt,cyy,cyt,ctt]``.

    The one reader of the file. Timed poses: sorted by time whatever the file order
    (counted and warned about, :class:`~relation_metric.timeorder.TimeOrderWarning`).
    The six covariance columns come all or none, every row gives all six, and each
    covariance must be symmetric positive semi-definite (:mod:`relation_metric.checks`).

    Raises
    ------
    InputError
        Naming the file and the line: the CSV rules of the bundle, a coordinate beyond
        10³⁰ m, some but not all covariance columns, an empty covariance cell, a covariance
        that is not symmetric positive semi-definite.
    """
    src = read_source(path)
    name = src.path
    cols, lines = read_csv_table(
        path,
        required=CSV_HEADER.split(","),
        optional=ONLINE_COVARIANCE_COLUMNS,
        empty_ok=ONLINE_COVARIANCE_COLUMNS,
        describe="the SLAM run's online estimate",
        source=src,
    )
    t = cols["t"]
    poses = np.column_stack((cols["x"], cols["y"], cols["theta"]))
    if t.shape[0] == 0:
        raise InputError("no poses found; expected rows t,x,y,theta", path=name)
    check_coordinates(poses[:, :2], what="online pose", path=name, line_of=lines.__getitem__)
    present = [c for c in ONLINE_COVARIANCE_COLUMNS if c in cols]
    cov = None
    if present and len(present) != len(ONLINE_COVARIANCE_COLUMNS):
        head = next(iter(src.data_lines()))[0]
        raise InputError(
            f"covariance columns: expected all of {','.join(ONLINE_COVARIANCE_COLUMNS)} or "
            f"none, got {','.join(present)}",
            path=name,
            line=head,
        )
    if present:
        six = np.column_stack([cols[c] for c in ONLINE_COVARIANCE_COLUMNS])
        empty = np.flatnonzero(np.isnan(six).any(1))
        if empty.size:
            raise InputError(
                f"{', '.join(ONLINE_COVARIANCE_COLUMNS)}: expected all six numbers, got an "
                "empty cell",
                path=name,
                line=int(lines[empty[0]]),
            )
        cov = _upper_to_full(cols)
        check_covariances(cov, path=name, lines=lines, what="online pose covariance")
        _warn_singular_online(cov, lines, name)
    order, report = sort_by_time(t, tolerance=None, lines=lines, path=name, what="online pose")
    if report.out_of_order:
        warnings.warn(
            f"{name}: {report.describe('online pose')}; put in time order",
            TimeOrderWarning,
            stacklevel=2,
        )
        t, poses = t[order], poses[order]
        cov = None if cov is None else cov[order]
    return OnlineEstimate(Trajectory(t, poses), cov)


class OnlineCovarianceWarning(UserWarning):
    """Online covariances that are zero or singular (no NEES for those poses; counted)."""


def _warn_singular_online(cov: Array, lines: NDArray[np.int64], name: str) -> None:
    """Warn once about covariances of ``online.csv`` that are PSD but not positive definite."""
    if not cov.shape[0]:
        return
    bad = np.flatnonzero(~(np.linalg.eigvalsh(cov)[:, 0] > 0.0))
    if bad.size:
        warnings.warn(
            f"{name}:{int(lines[bad[0]])}: {len(bad)} online pose covariance(s) zero or "
            "singular (positive semi-definite, not definite); those poses get no online NEES "
            "(skipped and counted in the notes)",
            OnlineCovarianceWarning,
            stacklevel=3,
        )


def write_online(path: PathLike, trajectory: Trajectory, covariances: Array | None = None) -> None:
    """Write an ``online.csv`` atomically (``%.17g``: :func:`read_online` reads it back exactly).

    ``covariances`` (N, 3, 3), one per pose, are written as ``cxx,cxy,cxt,cyy,cyt,ctt``
    (the upper triangle; the file holds symmetric covariances).
    """
    t, p = trajectory.timestamps, trajectory.poses
    header = CSV_HEADER.split(",")
    columns: list[Array] = [t, p[:, 0], p[:, 1], p[:, 2]]
    if covariances is not None:
        c = np.asarray(covariances, dtype=np.float64).reshape(-1, 3, 3)
        if c.shape[0] != t.shape[0]:
            raise InputError(
                f"online covariances: expected one per pose ({t.shape[0]}), got {c.shape[0]}",
                path=path,
            )
        header += list(ONLINE_COVARIANCE_COLUMNS)
        columns += [c[:, 0, 0], c[:, 0, 1], c[:, 0, 2], c[:, 1, 1], c[:, 1, 2], c[:, 2, 2]]
    write_csv_table(path, header, columns)
