"""A recorder a running filter calls, a few lines per step, to leave a SLAM result bundle.

The filter says what it does as it does it — the control (or odometry reading) of each step,
the measurements with the landmark each was associated with, optionally its own pose and
covariance — and, at the end, its final map and covariance; :meth:`BundleRecorder.write`
then writes the bundle (docs/bundle.md) with slamrel's one writer
(:func:`slamrel.formats.bundle.write_bundle`, ``online.csv`` by
:func:`~slamrel.formats.bundle.write_online`). Everything is checked when the bundle is built
(:class:`recovery.bundle.Bundle`); measurements with a range ≤ 0 or a non-finite value
(a sensor's dropout) are written as recorded — the reader skips and counts them with
``skip_invalid_measurements`` (``--skip-invalid-measurements``) and refuses them without.

Worked example (a filter with velocity controls stamped when their interval ends)::

    rec = BundleRecorder(
        MotionModel("velocity", sigma=(0.1, 0.02), integration="euler", control_stamp="end"),
        SensorModel(0.2, 0.02, max_range=20.0),
    )
    rec.control(0.0, 0.0, 0.0)                       # opens the log
    for k in range(1, steps + 1):
        t = k * dt
        rec.control(t, v[k], omega[k])               # the control the filter predicted with
        for z, j in zip(zs, associations):           # after its updates at t
            rec.measurement(t, z[0], z[1], j)        # j: the landmark id, None: unassociated
        rec.online(t, x[:3], P[:3, :3])              # optional: its own estimate
    rec.write("run-bundle", map_ids, x[3:].reshape(-1, 2), map_covariance=P[3:, 3:])

The per-step calls only append to lists (the filter's loop stays the filter's); the arrays
are made once, in :meth:`BundleRecorder.bundle`.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from recovery.bundle import Bundle
from recovery.models import MotionModel, SensorModel
from relation_metric.arrays import Array, PathLike
from relation_metric.errors import InputError
from relation_metric.trajectory import Trajectory
from slamrel.formats.bundle import write_bundle, write_measurements, write_online

__all__ = ["BundleRecorder"]


class BundleRecorder:
    """Collects what a running filter does, step by step, and writes it as a bundle.

    Parameters
    ----------
    motion, sensor : MotionModel, SensorModel
        The models the filter uses (its assumed noise; ``sensor.mount`` when the sensor is
        mounted off the robot's origin; ``MotionModel(..., step_covariance_frame=...)``
        when it states a covariance per step, given with each :meth:`control` or
        :meth:`odometry` call).
    initial_pose : array_like, shape (3,)
    initial_covariance : array_like, shape (3, 3)
        The filter's initial state; a zero covariance (the start known exactly) is allowed.
    description : str
    """

    def __init__(
        self,
        motion: MotionModel,
        sensor: SensorModel,
        *,
        initial_pose: ArrayLike = (0.0, 0.0, 0.0),
        initial_covariance: ArrayLike | None = None,
        description: str = "",
    ) -> None:
        self.motion, self.sensor, self.description = motion, sensor, description
        self.initial_pose = np.asarray(initial_pose, dtype=np.float64)
        self.initial_covariance = (
            np.zeros((3, 3))
            if initial_covariance is None
            else np.asarray(initial_covariance, dtype=np.float64)
        )
        self._log: list[tuple[float, ...]] = []
        self._step_cov: list[Array] = []
        self._meas: list[tuple[float, float, float, int, bool, bool]] = []
        self._online: list[tuple[float, Array, Array | None]] = []

    # -------------------------------------------------------------------- per step

    def control(
        self, t: float, v: float, omega: float, covariance: ArrayLike | None = None
    ) -> None:
        """A velocity control row ``(t, v, ω)`` (velocity model), with its step covariance
        (3 × 3, ``[x, y, θ]``) when the motion model states one per step."""
        self._row("velocity", (float(t), float(v), float(omega)), covariance)

    def odometry(
        self, t: float, x: float, y: float, theta: float, covariance: ArrayLike | None = None
    ) -> None:
        """An odometry pose row (odometry model), with the covariance of the step that ends at
        it when the motion model states one per step (zeros for the first row)."""
        self._row("odometry", (float(t), float(x), float(y), float(theta)), covariance)

    def measurement(
        self,
        t: float,
        range_: float,
        bearing: float,
        landmark: int | None = None,
        *,
        processed: bool = True,
    ) -> None:
        """One range-bearing measurement at ``t``; ``landmark`` the id the filter associated
        it with (also the landmark it initialised), ``None`` when it left it unassociated;
        ``processed=False`` for a frame the filter never processed (counted apart)."""
        lm = -1 if landmark is None else int(landmark)
        row = (float(t), float(range_), float(bearing), lm, landmark is not None, not processed)
        self._meas.append(row)

    def online(self, t: float, pose: ArrayLike, covariance: ArrayLike | None = None) -> None:
        """The filter's own pose estimate at ``t`` (after its updates), with its 3 × 3
        covariance when known; written as ``online.csv`` (validation only)."""
        cov = None if covariance is None else np.array(covariance, dtype=np.float64)
        self._online.append((float(t), np.array(pose, dtype=np.float64), cov))

    def _row(self, kind: str, row: tuple[float, ...], covariance: ArrayLike | None) -> None:
        if self.motion.type != kind:
            raise InputError(
                f"the recorder's motion model is {self.motion.type!r}; expected "
                f"{'control' if self.motion.type == 'velocity' else 'odometry'}() calls"
            )
        stated = self.motion.step_covariance_frame is not None
        if stated != (covariance is not None):
            raise InputError(
                "a step covariance: expected one with every row exactly when the motion "
                "model states step_covariance"
            )
        self._log.append(row)
        if covariance is not None:
            self._step_cov.append(np.array(covariance, dtype=np.float64).reshape(3, 3))

    # ------------------------------------------------------------------ at the end

    def bundle(
        self,
        map_ids: ArrayLike,
        map_xy: ArrayLike,
        *,
        map_covariance: ArrayLike | None = None,
        map_marginals: ArrayLike | None = None,
        groundtruth: Trajectory | None = None,
        landmarks_groundtruth: tuple[ArrayLike, ArrayLike] | None = None,
    ) -> Bundle:
        """The recorded run with its final map as a checked :class:`Bundle`.

        ``map_covariance`` (2M, 2M), landmarks in ``map_ids`` order, ``[x, y]`` each: its
        diagonal blocks become ``map.csv``'s marginals; else ``map_marginals`` (M, 2, 2);
        neither: an exact map (no covariance columns).
        """
        ids = np.asarray(map_ids, dtype=np.int64)
        m = ids.shape[0]
        joint = None if map_covariance is None else np.asarray(map_covariance, dtype=np.float64)
        if joint is not None:
            idx = np.arange(m)
            marg = 0.5 * (joint + joint.T).reshape(m, 2, m, 2)[idx, :, idx, :]
        elif map_marginals is not None:
            marg = np.asarray(map_marginals, dtype=np.float64)
        else:
            marg = np.full((m, 2, 2), np.nan)
        meas = self._measurement_rows()
        invalid = ~(np.isfinite(meas[:, 1:3]).all(1) & (meas[:, 1] > 0))
        meas = meas[~invalid]  # kept in the files (write), dropped and counted here
        log = np.array(self._log, dtype=np.float64)
        truth = None
        if landmarks_groundtruth is not None:
            tid, txy = landmarks_groundtruth
            truth = (np.asarray(tid, dtype=np.int64), np.asarray(txy, dtype=np.float64))
        return Bundle(
            motion=self.motion,
            sensor=self.sensor,
            controls=log if self.motion.type == "velocity" else None,
            odometry=None if self.motion.type == "velocity" else Trajectory(log[:, 0], log[:, 1:]),
            step_covariances=np.array(self._step_cov) if self._step_cov else None,
            measurement_times=meas[:, 0],
            measurements=meas[:, 1:3],
            measurement_landmarks=np.where(meas[:, 4] > 0, meas[:, 3], 0).astype(np.int64),
            measurement_associated=meas[:, 4] > 0,
            measurement_unprocessed=meas[:, 5] > 0 if (meas[:, 5] > 0).any() else None,
            map_ids=ids,
            map_xy=np.asarray(map_xy, dtype=np.float64),
            map_marginals=np.nan_to_num(marg, nan=0.0),
            map_covariance=joint,
            initial_pose=self.initial_pose,
            initial_covariance=self.initial_covariance,
            groundtruth=groundtruth,
            landmarks_groundtruth=truth,
            description=self.description,
            skipped_invalid=int(invalid.sum()),
        )

    def _measurement_rows(self) -> Array:
        """The recorded measurements, (J, 6): ``t, range, bearing, landmark, associated,
        unprocessed``."""
        return np.array(self._meas, dtype=np.float64).reshape(-1, 6)

    def online_estimate(self) -> tuple[Trajectory, Array | None] | None:
        """The recorded online poses and their covariances (None when none was recorded;
        covariances None unless every pose came with one)."""
        if not self._online:
            return None
        t = np.array([o[0] for o in self._online])
        poses = np.array([o[1] for o in self._online]).reshape(-1, 3)
        covs: Sequence[Array | None] = [o[2] for o in self._online]
        has = all(c is not None for c in covs)
        return Trajectory(t, poses), (np.array(covs).reshape(-1, 3, 3) if has else None)

    def write(
        self, directory: PathLike, map_ids: ArrayLike, map_xy: ArrayLike, **kw: object
    ) -> Path:
        """Write the bundle (:meth:`bundle`'s keywords) and ``online.csv`` into ``directory``,
        replaced whole (:func:`~slamrel.formats.bundle.write_bundle`); returns its path."""
        b = self.bundle(map_ids, map_xy, **kw)  # type: ignore[arg-type]
        online = self.online_estimate()
        exact = kw.get("map_covariance") is None and kw.get("map_marginals") is None

        def extra(root: Path) -> None:
            if b.skipped_invalid:  # the log as the filter saw it, invalid readings included
                meas = self._measurement_rows()
                write_measurements(
                    root / "measurements.csv",
                    meas[:, 0],
                    meas[:, 1:3],
                    meas[:, 3],
                    meas[:, 4] > 0,
                    meas[:, 5] > 0,
                )
            if online is not None:
                write_online(root / "online.csv", *online)
            if exact:  # an exact map: map.csv without covariance columns
                _strip_map_covariance(root / "map.csv")

        write_bundle(directory, b, extra=extra)
        return Path(directory)


def _strip_map_covariance(path: Path) -> None:
    """Rewrite ``map.csv`` as ``landmark,x,y`` (the map stated exact, no covariance)."""
    from slamrel.formats.landmark_csv import read_landmark_csv, write_landmark_csv

    table = read_landmark_csv(path, covariance=False, describe="the bundle's map")
    path.unlink()
    write_landmark_csv(path, table.ids, table.xy)
