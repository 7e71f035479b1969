"""The SLAM result bundle as a record: what a filter-based SLAM run leaves behind.

:class:`Bundle` holds the models, the log, the data associations and the final map of one
run (format ``slamrel-bundle/1``, docs/bundle.md) and checks itself when it is built: shapes,
finite numbers, times in order, unique map ids, associated landmarks in the map, symmetric
positive semi-definite covariances. Its files are read and written by
:mod:`slamrel.formats.bundle`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from recovery.constants import MAP_SOURCES
from recovery.models import MotionModel, SensorModel
from relation_metric.arrays import Array
from relation_metric.checks import check_covariances, check_joint_covariance
from relation_metric.errors import InputError
from relation_metric.ids import rows_of
from relation_metric.landmarks import check_landmarks
from relation_metric.trajectory import Trajectory, readonly

__all__ = ["Bundle"]


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
    snapped : int
        Measurements whose time lay within :data:`recovery.steps.SNAP_TOLERANCE` of a control
        (or odometry) time without being equal to it and was set to that time by the reader
        (float noise in the files; otherwise the recovery grid gets a second, almost
        coincident pose).
    wrapped_bearings : int
        Measurements whose bearing lay outside ``[−π, π)`` (within ``2π`` in magnitude) and
        was wrapped into it by the reader (counted, warned about).
    time : {"seconds", "steps"}
        The unit of every ``t``: seconds, or step indices (a log without timestamps: the
        rows' ``t`` are integers ``0, 1, 2, …``, one per filter step; rates are per step).
    initialisation : {"updates", "initialises_only"}
        Whether the filter also updated with the measurement that initialised a landmark
        (``"updates"``, PythonRobotics' way; the recovery uses it like every other) or only
        initialised the landmark from it (``"initialises_only"``: the recovery leaves out each
        landmark's first associated measurement, counted by :meth:`initialising`).
    measurement_unprocessed : ndarray of bool, shape (J,), or None
        Measurements of frames the filter never processed (``processed`` 0 in
        ``measurements.csv``): not used by the recovery whatever their landmark, counted
        apart from the unassociated ones.
    step_covariances : ndarray, shape (K, 3, 3), or None
        With a ``step_covariance`` motion model (only then): one covariance per row of the
        motion log (``controls`` or ``odometry``), ``[x, y, θ]``, symmetric PSD; velocity: of
        the increment the row is held over, odometry: of the step that ends at the row (row 0
        unused).
    skipped_invalid : int
        Measurements dropped by the reader for a range ≤ 0 or a non-finite range or bearing
        (only with ``skip_invalid_measurements``; counted, warned about).
    map_source : {"log", "independent"} or None
        Where the map came from (``bundle.json``'s ``map_source``,
        :data:`~recovery.constants.MAP_SOURCES`): ``log``, estimated from this very log (an
        EKF-SLAM's final map), or ``independent`` of it (surveyed); ``None`` when the bundle
        does not say (read as ``independent``, and the recovery says it assumed so).

    Raises
    ------
    InputError
        Every bundle is checked when it is built, whether read from a directory or made in
        memory (simulators, importers, ``dataclasses.replace``): the model the log needs
        (controls or odometry, at least two rows), the shapes above, finite values, positive
        ranges, measurement times in order, the map and the landmark ground truth
        (:func:`relation_metric.landmarks.check_landmarks`: integer unique ids, finite
        positions, symmetric positive semi-definite marginals), associated landmarks that are
        in the map, and symmetric positive semi-definite covariances. The message names the
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
    snapped: int = 0
    wrapped_bearings: int = 0
    skipped_invalid: int = 0
    step_covariances: Array | None = None
    time: str = "seconds"
    initialisation: str = "updates"
    measurement_unprocessed: NDArray[np.bool_] | None = None
    map_source: str | None = None

    def __post_init__(self) -> None:
        if self.map_source is not None and self.map_source not in MAP_SOURCES:
            raise InputError(
                f"map_source: expected one of {', '.join(MAP_SOURCES)}, got {self.map_source!r}",
                path=_where(self, "bundle.json"),
            )
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
        for name in ("controls", "map_covariance", "step_covariances"):
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
        _check_statements(self)
        _check_step_covariances(self)
        _check_shapes(self)
        _check_values(self)
        _check_covariance_fields(self)

    def map_index(self) -> NDArray[np.int64]:
        """Row of ``map_ids`` of each measurement's landmark, −1 when unassociated, never
        processed, or (``initialisation="initialises_only"``) the measurement that
        initialised its landmark, (J,)."""
        idx = rows_of(self.map_ids, self.measurement_landmarks)
        out = np.where(self.measurement_associated & (idx >= 0), idx, -1)
        if self.measurement_unprocessed is not None:
            out[self.measurement_unprocessed] = -1
        out[self.initialising()] = -1
        return out

    def initialising(self) -> NDArray[np.bool_]:
        """(J,) The measurements left out as their landmark's initialisation: with
        ``initialisation="initialises_only"``, the first (in time order) associated,
        processed measurement of each landmark; none otherwise."""
        out = np.zeros(self.measurement_times.shape[0], dtype=bool)
        if self.initialisation != "initialises_only":
            return out
        ok = self.measurement_associated.copy()
        if self.measurement_unprocessed is not None:
            ok &= ~self.measurement_unprocessed
        rows = np.flatnonzero(ok)
        _, first = np.unique(self.measurement_landmarks[rows], return_index=True)
        out[rows[first]] = True
        return out

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


#: The values of :attr:`Bundle.time` and :attr:`Bundle.initialisation` (docs/bundle.md).
TIME_UNITS = ("seconds", "steps")
INITIALISATIONS = ("updates", "initialises_only")


def _check_statements(b: Bundle) -> None:
    """``time``, ``initialisation`` among their values; ``measurement_unprocessed`` (J,)."""
    for name, allowed in (("time", TIME_UNITS), ("initialisation", INITIALISATIONS)):
        if getattr(b, name) not in allowed:
            raise InputError(
                f"{name}: unknown value {getattr(b, name)!r}; expected one of {', '.join(allowed)}",
                path=_where(b, "bundle.json"),
            )
    if b.measurement_unprocessed is not None:
        object.__setattr__(
            b, "measurement_unprocessed", readonly(b.measurement_unprocessed, np.bool_)
        )
        if b.measurement_unprocessed.shape != b.measurement_times.shape:
            raise InputError(
                f"measurement_unprocessed: expected shape {b.measurement_times.shape}, got "
                f"{b.measurement_unprocessed.shape}",
                path=b.path,
            )


def _check_step_covariances(b: Bundle) -> None:
    """``step_covariances`` given exactly with a ``step_covariance`` model, one per log row."""
    wanted = b.motion.step_covariance_frame is not None
    have = b.step_covariances is not None
    where = _where(b, "step_covariance.csv")
    if wanted != have:
        raise InputError(
            "step_covariances: expected one covariance per row of the motion log with a "
            "step_covariance motion model, and none otherwise",
            path=where if wanted else b.path,
        )
    if b.step_covariances is None:
        return
    k = b.controls.shape[0] if b.controls is not None else len(b.odometry)  # type: ignore[arg-type]
    if b.step_covariances.shape != (k, 3, 3):
        raise InputError(
            f"step_covariances: expected shape ({k}, 3, 3), one per row of the motion log, "
            f"got {b.step_covariances.shape}",
            path=where,
        )
    check_covariances(b.step_covariances, path=where, what="step covariance")


def _check_shapes(b: Bundle) -> None:
    """Every array has the shape the :class:`Bundle` docstring gives it."""
    j, m = b.measurement_times.shape[0], b.map_ids.shape[0]
    assert b.measurement_lines is not None  # __post_init__ fills it before the checks
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
    """Finite numbers, positive ranges, times in order, the maps, known landmarks."""
    src = _where(b, "measurements.csv")
    lines = b.measurement_lines
    assert lines is not None  # __post_init__ fills it before the checks

    def line(k: int) -> int | None:
        return int(lines[k]) or None

    for name in ("measurement_times", "measurements", "map_xy", "initial_pose"):
        a = getattr(b, name)  # any row with a non-finite entry (empty arrays have none)
        bad = np.flatnonzero(~np.isfinite(a).all(axis=tuple(range(1, a.ndim))))
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
    check_landmarks(
        b.map_ids, b.map_xy, b.map_marginals, path=_where(b, "map.csv"), allow_unknown=False
    )
    if b.landmarks_groundtruth is not None:
        check_landmarks(*b.landmarks_groundtruth, path=_where(b, "landmarks_groundtruth.csv"))
    unknown = np.flatnonzero(
        b.measurement_associated & ~np.isin(b.measurement_landmarks, b.map_ids)
    )
    if unknown.size:
        k = int(unknown[0])
        raise InputError(
            f"landmark {int(b.measurement_landmarks[k])} is not in map.csv ({unknown.size} such "
            "measurement(s)); expected an id of the map or an empty field (unassociated)",
            path=src,
            line=line(k),
        )


def _check_covariance_fields(b: Bundle) -> None:
    """Initial covariance and joint map covariance: symmetric PSD (the marginals are checked
    with the map, :func:`relation_metric.landmarks.check_landmarks`)."""
    check_covariances(
        b.initial_covariance[None], path=_where(b, "bundle.json"), what="initial_covariance"
    )
    if b.map_covariance is not None:
        check_joint_covariance(
            b.map_covariance, path=_where(b, "map_covariance.npy"), what="map covariance"
        )


# ----------------------------------------------------------------------------------- reading


# ----------------------------------------------------------------------------------- writing
