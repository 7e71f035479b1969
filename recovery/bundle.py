"""The SLAM result bundle (format ``slamrel-bundle/1``, see ``BUNDLE.md``): read and write.

A bundle is a directory of comma-separated files (one header line, ``#`` comment lines) and a
JSON manifest ``bundle.json``. The reader is strict: a missing required file or column, a
non-finite number, times that go back more than ``FILTER_TIME_TOLERANCE`` (0.05 s; smaller
steps back are put in time order and counted in ``Bundle.reordered``), an unknown model type,
a measurement whose landmark is not in ``map.csv`` (unless ``skip_unknown_landmarks``, which
counts them), and a covariance that is not symmetric positive semi-definite each raise
:class:`~relation_metric.errors.InputError` naming the file, the line and what was expected.

Landmark ids are integers. Manifest defaults: ``initial_pose`` ``[0, 0, 0]``,
``initial_covariance`` ``1e-9 I``, ``description`` empty.
"""

from __future__ import annotations

import io
import json
import math
import os
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from recovery.models import MOTION_TYPES, SIGMA_NAMES, MotionModel, SensorModel
from relation_metric.arrays import Array
from relation_metric.checks import check_covariances, check_joint_covariance
from relation_metric.errors import InputError
from relation_metric.formats import read_trajectory
from relation_metric.ids import rows_of
from relation_metric.landmarks import integer_ids, read_landmark_csv, write_landmark_csv
from relation_metric.outputs import staged_directory
from relation_metric.textio import (
    read_csv_table,
    read_text,
    write_bytes_atomic,
    write_text_atomic,
)
from relation_metric.timeorder import FILTER_TIME_TOLERANCE, TimeOrderWarning, sort_by_time
from relation_metric.trajectory import Trajectory, readonly

__all__ = ["FORMAT", "Bundle", "read_bundle", "write_bundle"]

FORMAT = "slamrel-bundle/1"
PathLike = str | os.PathLike[str]


@dataclass(frozen=True)
class Bundle:
    """What a filter-based SLAM run leaves behind (read-only arrays).

    Attributes
    ----------
    motion : MotionModel
    sensor : SensorModel
    initial_pose : ndarray, shape (3,)
    initial_covariance : ndarray, shape (3, 3)
    controls : ndarray, shape (K, 3) or None
        ``[t, v, ω]`` rows (velocity model).
    odometry : Trajectory or None
        Wheel-odometry poses (odometry model).
    measurement_times : ndarray, shape (J,)
    measurements : ndarray, shape (J, 2)
        ``[range, bearing]``.
    measurement_landmarks : ndarray of int, shape (J,)
        Associated landmark id; meaningful only where ``measurement_associated``.
    measurement_associated : ndarray of bool, shape (J,)
    map_ids : ndarray of int, shape (M,)
    map_xy : ndarray, shape (M, 2)
    map_marginals : ndarray, shape (M, 2, 2)
        Per-landmark covariances (zeros when ``map.csv`` gives none).
    map_covariance : ndarray, shape (2M, 2M) or None
        Joint map covariance, landmarks in ``map_ids`` order, ``[x, y]`` each.
    groundtruth : Trajectory or None
    landmarks_groundtruth : tuple (ids (L,), xy (L, 2)) or None
    description : str
    measurement_lines : ndarray of int, shape (J,)
        Line of each measurement in ``measurements.csv`` (0 when built in memory).
    skipped_unknown : int
        Measurements dropped because their landmark is not in the map (only with
        ``skip_unknown_landmarks``).
    path : str or None
    reordered : Mapping[str, int]
        Rows of each time-stamped file (``controls.csv`` or ``odometry.csv``,
        ``measurements.csv``, ``groundtruth.csv``) that were out of time order by at most
        :data:`~relation_metric.timeorder.FILTER_TIME_TOLERANCE` and were put in order.

    Raises
    ------
    InputError
        Every bundle is checked when it is built, whether read from a directory or made in
        memory (simulators, importers, ``dataclasses.replace``): the model the log needs
        (controls or odometry, at least two rows), the shapes above, finite values, positive
        ranges, measurement times in order, unique map ids, associated landmarks that are in
        the map, and symmetric positive semi-definite covariances. The message names the
        field; with ``path`` set (a bundle read from disk) also the file, and the line of a
        measurement.
    """

    motion: MotionModel
    sensor: SensorModel
    measurement_times: Array
    measurements: Array
    measurement_landmarks: NDArray[np.int64]
    measurement_associated: NDArray[np.bool_]
    map_ids: NDArray[np.int64]
    map_xy: Array
    map_marginals: Array
    initial_pose: Array = field(default_factory=lambda: np.zeros(3))
    initial_covariance: Array = field(default_factory=lambda: 1e-9 * np.eye(3))
    controls: Array | None = None
    odometry: Trajectory | None = None
    map_covariance: Array | None = None
    groundtruth: Trajectory | None = None
    landmarks_groundtruth: tuple[NDArray[np.int64], Array] | None = None
    description: str = ""
    measurement_lines: NDArray[np.int64] | None = None
    skipped_unknown: int = 0
    path: str | None = None
    reordered: Mapping[str, int] = field(default_factory=dict)

    def __post_init__(self) -> None:
        ro = object.__setattr__
        for name in (
            "measurement_times",
            "measurements",
            "map_xy",
            "map_marginals",
            "initial_pose",
            "initial_covariance",
        ):
            ro(self, name, readonly(getattr(self, name)))
        ro(self, "measurement_landmarks", readonly(self.measurement_landmarks, np.int64))
        ro(self, "measurement_associated", readonly(self.measurement_associated, np.bool_))
        ro(self, "map_ids", readonly(self.map_ids, np.int64))
        for name in ("controls", "map_covariance"):
            if getattr(self, name) is not None:
                ro(self, name, readonly(getattr(self, name)))
        lines = self.measurement_lines
        ro(
            self,
            "measurement_lines",
            readonly(
                np.zeros(self.measurement_times.shape[0]) if lines is None else lines, np.int64
            ),
        )
        if self.landmarks_groundtruth is not None:
            ids, xy = self.landmarks_groundtruth
            ro(self, "landmarks_groundtruth", (readonly(ids, np.int64), readonly(xy)))
        _check_models(self)
        _check_shapes(self)
        _check_values(self)
        _check_covariance_fields(self)

    def map_index(self) -> NDArray[np.int64]:
        """Row of ``map_ids`` of each measurement's landmark, −1 when unassociated, (J,)."""
        idx = rows_of(self.map_ids, self.measurement_landmarks)
        return np.where(self.measurement_associated & (idx >= 0), idx, -1)

    def with_map(self, xy: Array, marginals: Array, covariance: Array | None) -> Bundle:
        """The same bundle with another map (same ids and order)."""
        return replace(self, map_xy=xy, map_marginals=marginals, map_covariance=covariance)


# ------------------------------------------------------------------------------- validation


def _where(bundle: Bundle, name: str) -> Path | None:
    """The file ``name`` of the bundle's directory, for messages (None when built in memory)."""
    return None if bundle.path is None else Path(bundle.path) / name


def _check_models(b: Bundle) -> None:
    """The log the motion model needs: controls (velocity) or odometry poses, two rows at least."""
    if not isinstance(b.motion, MotionModel) or not isinstance(b.sensor, SensorModel):
        raise InputError("motion and sensor: expected a MotionModel and a SensorModel")
    if b.motion.type == "velocity":
        if b.controls is None:
            raise InputError("the velocity model needs controls [t, v, omega]", path=b.path)
        if b.controls.ndim != 2 or b.controls.shape[1] != 3:
            raise InputError(
                f"controls: expected shape (K, 3) [t, v, omega], got {b.controls.shape}",
                path=_where(b, "controls.csv"),
            )
        if b.controls.shape[0] < 2:
            raise InputError(
                "expected at least two control rows (the last one ends the run)",
                path=_where(b, "controls.csv"),
            )
    else:
        if b.odometry is None:
            raise InputError("the odometry model needs odometry poses", path=b.path)
        if len(b.odometry) < 2:
            raise InputError("expected at least two odometry rows", path=_where(b, "odometry.csv"))


def _check_shapes(b: Bundle) -> None:
    """Every array has the shape the :class:`Bundle` docstring gives it."""
    j, m = b.measurement_times.shape[0], b.map_ids.shape[0]
    expected = {
        "measurement_times": (b.measurement_times, (j,)),
        "measurements": (b.measurements, (j, 2)),
        "measurement_landmarks": (b.measurement_landmarks, (j,)),
        "measurement_associated": (b.measurement_associated, (j,)),
        "measurement_lines": (b.measurement_lines, (j,)),
        "map_ids": (b.map_ids, (m,)),
        "map_xy": (b.map_xy, (m, 2)),
        "map_marginals": (b.map_marginals, (m, 2, 2)),
        "initial_pose": (b.initial_pose, (3,)),
        "initial_covariance": (b.initial_covariance, (3, 3)),
    }
    if b.map_covariance is not None:
        expected["map_covariance"] = (b.map_covariance, (2 * m, 2 * m))
    if b.landmarks_groundtruth is not None:
        ids, xy = b.landmarks_groundtruth
        expected["landmarks_groundtruth ids"] = (ids, (ids.shape[0],))
        expected["landmarks_groundtruth xy"] = (xy, (ids.shape[0], 2))
    for name, (array, shape) in expected.items():
        if array.shape != shape:
            raise InputError(
                f"{name}: expected shape {shape} (J = {j} measurements, M = {m} landmarks), "
                f"got {array.shape}",
                path=b.path,
            )


def _check_values(b: Bundle) -> None:
    """Finite numbers, positive ranges, times in order, unique map ids, known landmarks."""
    src = _where(b, "measurements.csv")

    def line(k: int) -> int | None:
        return int(b.measurement_lines[k]) or None

    for name in ("measurement_times", "measurements", "map_xy", "initial_pose"):
        bad = np.flatnonzero(~np.isfinite(getattr(b, name)).reshape(len(getattr(b, name)), -1))
        if bad.size:
            raise InputError(f"{name}: expected finite numbers (row {int(bad[0])})", path=b.path)
    if b.controls is not None and not np.isfinite(b.controls).all():
        raise InputError("controls: expected finite numbers", path=_where(b, "controls.csv"))
    bad = np.flatnonzero(b.measurements[:, 0] <= 0)
    if bad.size:
        k = int(bad[0])
        raise InputError(
            f"range {float(b.measurements[k, 0])}: expected a positive range",
            path=src,
            line=line(k),
        )
    back = np.flatnonzero(np.diff(b.measurement_times) < 0)
    if back.size:
        k = int(back[0]) + 1
        raise InputError(
            f"measurement_times: time {float(b.measurement_times[k]):g} goes back; expected "
            "measurements in time order",
            path=src,
            line=line(k),
        )
    ids, first = np.unique(b.map_ids, return_index=True)
    if ids.size != b.map_ids.size:
        dup = int(np.setdiff1d(np.arange(b.map_ids.size), first)[0])
        raise InputError(
            f"map_ids: duplicate landmark id {int(b.map_ids[dup])}; expected unique ids",
            path=_where(b, "map.csv"),
        )
    unknown = np.flatnonzero(b.measurement_associated & ~np.isin(b.measurement_landmarks, ids))
    if unknown.size:
        k = int(unknown[0])
        raise InputError(
            f"landmark {int(b.measurement_landmarks[k])} is not in map.csv ({unknown.size} such "
            "measurement(s)); expected an id of the map or an empty field (unassociated)",
            path=src,
            line=line(k),
        )


def _check_covariance_fields(b: Bundle) -> None:
    """Initial covariance, map marginals and joint map covariance: symmetric PSD."""
    check_covariances(
        b.initial_covariance[None], path=_where(b, "bundle.json"), what="initial_covariance"
    )
    check_covariances(
        b.map_marginals,
        path=_where(b, "map.csv"),
        what=lambda k: f"landmark {int(b.map_ids[k])}: covariance",
    )
    if b.map_covariance is not None:
        check_joint_covariance(
            b.map_covariance, path=_where(b, "map_covariance.npy"), what="map covariance"
        )


# ----------------------------------------------------------------------------------- reading


def _shown(value: Any) -> str:
    """A JSON value for a message (as JSON, shortened; odd characters as ``<U+XXXX>``)."""
    text = f"'{value}'" if isinstance(value, str) else json.dumps(value, ensure_ascii=False)
    text = text if len(text) <= 60 else text[:60] + "..."
    return "".join(c if c.isprintable() else f"<U+{ord(c):04X}>" for c in text)


def _line_of_key(text: str, key: str) -> int | None:
    needle = f'"{key}"'
    pos = text.find(needle)
    return None if pos < 0 else text.count("\n", 0, pos) + 1


def _number(
    value: Any, *, what: str, path: str, line: int | None, minimum: float | None = 0.0
) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise InputError(
            f"{what}: expected a finite number, got {_shown(value)}", path=path, line=line
        )
    if minimum is not None and value < minimum:
        raise InputError(
            f"{what}: expected a number >= {minimum}, got {_shown(value)}", path=path, line=line
        )
    return float(value)


def _numbers(
    value: Any, n: int, *, what: str, path: str, line: int | None, minimum: float | None
) -> tuple[float, ...]:
    if not isinstance(value, list) or len(value) != n:
        raise InputError(
            f"{what}: expected a list of {n} numbers, got {_shown(value)}", path=path, line=line
        )
    return tuple(_number(v, what=what, path=path, line=line, minimum=minimum) for v in value)


def _check_psd(cov: Array, *, what: str, path: str, line: int | None) -> None:
    check_covariances(cov[None], path=path, lines=None if line is None else [line], what=what)


def _parse_motion(spec: Any, text: str, path: str) -> MotionModel:
    line = _line_of_key(text, "motion_model")
    if not isinstance(spec, dict):
        raise InputError("motion_model: expected an object", path=path, line=line)
    kind = spec.get("type")
    if kind not in MOTION_TYPES:
        raise InputError(
            f"motion_model: unknown type {_shown(kind)}; expected one of {', '.join(MOTION_TYPES)}",
            path=path,
            line=_line_of_key(text, "type") if kind is not None else line,
        )
    names = SIGMA_NAMES[kind]
    if "alpha" in spec:
        if any(n in spec for n in names):
            raise InputError(
                f"motion_model: give either alpha or {', '.join(names)}, not both",
                path=path,
                line=line,
            )
        alpha = _numbers(
            spec["alpha"],
            4,
            what="motion_model.alpha",
            path=path,
            line=_line_of_key(text, "alpha"),
            minimum=0.0,
        )
        return MotionModel(kind, alpha=alpha)
    missing = [n for n in names if n not in spec]
    if missing:
        raise InputError(
            f"motion_model ({kind}): missing {', '.join(missing)}; "
            f"expected {', '.join(names)} or alpha",
            path=path,
            line=line,
        )
    sigma = tuple(
        _number(spec[n], what=f"motion_model.{n}", path=path, line=_line_of_key(text, n))
        for n in names
    )
    return MotionModel(kind, sigma=sigma)


def _parse_sensor(spec: Any, text: str, path: str) -> SensorModel:
    line = _line_of_key(text, "sensor_model")
    if not isinstance(spec, dict):
        raise InputError("sensor_model: expected an object", path=path, line=line)
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
        v = _number(spec[n], what=f"sensor_model.{n}", path=path, line=_line_of_key(text, n))
        if v <= 0:
            raise InputError(
                f"sensor_model.{n}: expected a positive number, got {v}",
                path=path,
                line=_line_of_key(text, n),
            )
        vals.append(v)
    return SensorModel(*vals)


def _read_manifest(path: Path) -> dict[str, Any]:
    name = str(path)
    text = read_text(path)
    try:
        doc = json.loads(text)
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
    for key in ("motion_model", "sensor_model"):
        if key not in doc:
            raise InputError(f"missing {key}", path=name)
    out: dict[str, Any] = {
        "motion": _parse_motion(doc["motion_model"], text, name),
        "sensor": _parse_sensor(doc["sensor_model"], text, name),
        "description": str(doc.get("description", "")),
    }
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
            _numbers(r, 3, what="initial_covariance", path=name, line=line, minimum=None)
            for r in cov
        ]
        mat = np.array(rows)
        _check_psd(mat, what="initial_covariance", path=name, line=line)
        out["initial_covariance"] = mat
    return out


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
    if dtype.hasobject or dtype.kind not in "fi" or dtype.fields is not None:
        raise InputError(
            f"holds a {dtype.name} array (pickled objects are never loaded); {expected}",
            path=path,
        )
    if tuple(shape) != (n, n):
        shown = " x ".join(str(d) for d in shape) or "a scalar"
        raise InputError(f"holds an array of shape {shown}; {expected}", path=path)
    try:
        arr = np.load(path, allow_pickle=False)
    except Exception:  # noqa: BLE001 - a cut-off or corrupt body
        raise InputError(f"cannot read the array (cut off?); {expected}", path=path) from None
    return np.asarray(arr, dtype=np.float64)


def read_bundle(directory: PathLike, *, skip_unknown_landmarks: bool = False) -> Bundle:
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

    Returns
    -------
    Bundle

    Raises
    ------
    InputError
        For every defect listed in ``BUNDLE.md``, naming file, line and what was expected.
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
    meas = _read_measurements(root, reordered)
    skipped = 0
    if skip_unknown_landmarks:
        unknown = meas["measurement_associated"] & ~np.isin(
            meas["measurement_landmarks"], map_fields["map_ids"]
        )
        skipped = int(unknown.sum())
        meas = {k: v[~unknown] for k, v in meas.items()}
    return Bundle(
        **meta,
        **log,
        **map_fields,
        **meas,
        **_read_truth(root, reordered),
        skipped_unknown=skipped,
        path=str(root),
        reordered=reordered,
    )


def _read_motion_log(root: Path, motion: MotionModel, reordered: dict[str, int]) -> dict[str, Any]:
    """``controls`` (velocity model) or ``odometry`` (odometry model), in time order."""
    if motion.type == "velocity":
        p = root / "controls.csv"
        cols, lines = _read_csv(p, required=("t", "v", "omega"))
        cols, lines, reordered[p.name] = _time_ordered(cols, lines, p, "control")
        return {"controls": np.column_stack((cols["t"], cols["v"], cols["omega"]))}
    p = root / "odometry.csv"
    cols, lines = _read_csv(p, required=("t", "x", "y", "theta"))
    cols, lines, reordered[p.name] = _time_ordered(cols, lines, p, "odometry pose")
    poses = np.column_stack((cols["x"], cols["y"], cols["theta"]))
    return {"odometry": Trajectory(cols["t"], poses)}


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
    return {"map_ids": table.ids, "map_xy": table.xy, "map_marginals": marg, "map_covariance": cov}


def _read_measurements(root: Path, reordered: dict[str, int]) -> dict[str, NDArray[Any]]:
    """``measurements.csv`` in time order: the five ``measurement*`` fields of the bundle."""
    p = root / "measurements.csv"
    cols, lines = _read_csv(
        p, required=("t", "range", "bearing", "landmark"), empty_ok=("landmark",)
    )
    cols, lines, reordered[p.name] = _time_ordered(cols, lines, p, "measurement")
    return {
        "measurement_times": cols["t"],
        "measurements": np.column_stack((cols["range"], cols["bearing"])),
        "measurement_landmarks": integer_ids(cols["landmark"], lines, p, "landmark"),
        "measurement_associated": ~np.isnan(cols["landmark"]),
        "measurement_lines": lines,
    }


def _read_truth(root: Path, reordered: dict[str, int]) -> dict[str, Any]:
    """``groundtruth.csv`` and ``landmarks_groundtruth.csv`` when present (else None)."""
    out: dict[str, Any] = {"groundtruth": None, "landmarks_groundtruth": None}
    if (root / "groundtruth.csv").exists():
        loaded = read_trajectory(
            root / "groundtruth.csv", format="csv", max_step_back=FILTER_TIME_TOLERANCE
        )
        out["groundtruth"] = loaded.trajectory
        reordered["groundtruth.csv"] = loaded.out_of_order
    p_lgt = root / "landmarks_groundtruth.csv"
    if p_lgt.exists():
        table = read_landmark_csv(p_lgt, covariance=False, describe="landmark ground truth")
        out["landmarks_groundtruth"] = (table.ids, table.xy)
    return out


# ----------------------------------------------------------------------------------- writing


def _csv(header: str, columns: Sequence[Array], fmt: str = "%.17g") -> str:
    if not columns or columns[0].shape[0] == 0:
        return header + "\n"
    buf = io.StringIO()
    np.savetxt(buf, np.column_stack(columns), fmt=fmt, delimiter=",")
    return header + "\n" + buf.getvalue()


def write_bundle(
    directory: PathLike,
    bundle: Bundle,
    *,
    force: bool = True,
    extra: Callable[[Path], None] | None = None,
) -> None:
    """Write ``bundle`` as a bundle directory, replaced as a whole (round-trips exactly).

    The files are written into a hidden folder beside ``directory`` that is swapped in only
    when complete (:func:`relation_metric.outputs.staged_directory`): no file of an earlier
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
    write_text_atomic(root / "bundle.json", json.dumps(meta, indent=2) + "\n")
    if bundle.controls is not None:
        c = bundle.controls
        write_text_atomic(root / "controls.csv", _csv("t,v,omega", [c[:, 0], c[:, 1], c[:, 2]]))
    if bundle.odometry is not None:
        o = bundle.odometry
        write_text_atomic(root / "odometry.csv", _csv("t,x,y,theta", [o.timestamps, *o.poses.T]))
    t = bundle.measurement_times
    rows = _csv(
        "t,range,bearing", [t, bundle.measurements[:, 0], bundle.measurements[:, 1]]
    ).splitlines()
    ids = np.where(bundle.measurement_associated, bundle.measurement_landmarks.astype(str), "")
    text = "t,range,bearing,landmark\n" + "".join(f"{r},{i}\n" for r, i in zip(rows[1:], ids))
    write_text_atomic(root / "measurements.csv", text)
    write_landmark_csv(root / "map.csv", bundle.map_ids, bundle.map_xy, bundle.map_marginals)
    if bundle.map_covariance is not None:
        buf = io.BytesIO()
        np.save(buf, np.asarray(bundle.map_covariance), allow_pickle=False)
        write_bytes_atomic(root / "map_covariance.npy", buf.getvalue())
    if bundle.groundtruth is not None:
        g = bundle.groundtruth
        write_text_atomic(root / "groundtruth.csv", _csv("t,x,y,theta", [g.timestamps, *g.poses.T]))
    if bundle.landmarks_groundtruth is not None:
        write_landmark_csv(root / "landmarks_groundtruth.csv", *bundle.landmarks_groundtruth)
