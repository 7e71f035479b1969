"""Laser scans from CARMEN logs (``FLASER``, ``RLASER``, ``ROBOTLASER1/2``, ``RAWLASER1..4``).

The record layouts are the ones of the trajectory reader
(:class:`slamrel.formats.trajectories.CarmenLayout`): one description of the CARMEN format,
two views of it (poses there, scans here).

What a scan carries
-------------------
``ROBOTLASER*`` and ``RAWLASER*`` state their configuration: ``start_angle``, ``fov``,
``angular_resolution``, ``maximum_range`` (radians, metres). The old ``FLASER``/``RLASER``
records do not; CARMEN's own reader guesses them from the beam count
(``carmen_laser_guess_fov`` / ``carmen_laser_guess_angle_increment``): start angle −π/2,
resolution π/180 for 180/181 beams, π/360 for 360/361, π/720 for 400/401, else
π/(n − 1); maximum range 80 m. This reader applies the same rule (so 361 beams span
−90°…+90° at 0.5°) and says so in :attr:`LaserScans.guessed_config`.

Beam ``k`` of a scan points at ``start_angle + k · angular_resolution`` in the laser frame;
a reading ``r`` is a return when ``min_range < r < maximum_range`` (readings at or beyond
the maximum, e.g. the SICK's 81.91 m "no return", are kept in :attr:`LaserScans.ranges` and
masked by :meth:`LaserScans.points`).

Poses: the laser pose (``x y θ`` of FLASER/RLASER, ``laser_*`` of ROBOTLASER) and the
odometry pose (``odom_*`` / ``robot_*``) of each record, both in the log's world frame;
the **laser offset** ``o = odom⁻¹ ∘ laser`` (the laser's pose on the robot, when both
are from the same odometry). RAWLASER records carry no pose: their poses are NaN (pair them
with an estimate by time). The time of a scan is its ipc timestamp, as for poses.

Input rule: a record whose counts or numbers are wrong raises :class:`InputError` with file
and line; a log with more than one kind of laser record needs ``record=`` (no guess which
sensor is meant); other records are skipped and counted in :attr:`LaserScans.skipped`.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from relation_metric.errors import InputError
from relation_metric.se2 import between
from slamrel.formats.text import PathLike, SourceText, read_source
from slamrel.formats.trajectories import (
    CARMEN_LASER_RECORDS,
    carmen_floats,
    carmen_layout,
)

__all__ = [
    "LaserScans",
    "read_laser_scans",
    "nearest_times",
    "guess_laser_config",
    "FLASER_MAX_RANGE",
]

FLASER_MAX_RANGE = 80.0
"""The maximum range CARMEN assumes for FLASER/RLASER records [m]."""


def guess_laser_config(beams: int) -> tuple[float, float]:
    """CARMEN's guess ``(start_angle, angular_resolution)`` [rad] for an old-style record."""
    if beams in (180, 181):
        res = math.pi / 180.0
    elif beams in (360, 361):
        res = math.pi / 360.0
    elif beams in (400, 401):
        res = math.pi / 720.0
    else:
        res = math.pi / max(beams - 1, 1)
    return -math.pi / 2.0, res


@dataclass(frozen=True)
class LaserScans:
    """The scans of one laser of a log, in file order.

    Attributes
    ----------
    path : str
    record : str
        The record kind read (``"FLASER"``, ``"ROBOTLASER1"``, ...).
    timestamps : (N,) float
        ipc timestamps [s].
    ranges : (N, B) float
        Range readings [m]; ``B`` the largest beam count; beams a scan does not have are NaN.
    beams : (N,) int
        Beam count of each scan.
    start_angle, angular_resolution, max_range : (N,) float
        Configuration per scan [rad, rad, m].
    laser_pose, odometry_pose : (N, 3) float
        ``[x, y, θ]`` in the log's frame; NaN for RAWLASER records.
    lines : (N,) int
        1-based line of each scan in the file.
    guessed_config : bool
        True when the configuration is CARMEN's guess from the beam count (FLASER/RLASER).
    skipped : Mapping[str, int]
        Records not read, by kind.
    """

    path: str
    record: str
    timestamps: NDArray[np.float64]
    ranges: NDArray[np.float64]
    beams: NDArray[np.int64]
    start_angle: NDArray[np.float64]
    angular_resolution: NDArray[np.float64]
    max_range: NDArray[np.float64]
    laser_pose: NDArray[np.float64]
    odometry_pose: NDArray[np.float64]
    lines: NDArray[np.int64]
    guessed_config: bool
    skipped: Mapping[str, int] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.timestamps.shape[0])

    @property
    def laser_offset(self) -> NDArray[np.float64]:
        """``odom⁻¹ ∘ laser`` per scan, ``(N, 3)`` (the laser's pose on the robot)."""
        return between(self.odometry_pose, self.laser_pose)

    def angles(self, i: int) -> NDArray[np.float64]:
        """Beam angles of scan ``i`` in the laser frame, ``(beams[i],)`` [rad]."""
        k = np.arange(int(self.beams[i]))
        return self.start_angle[i] + k * self.angular_resolution[i]

    def points(
        self, i: int, *, min_range: float = 0.0, max_range: float | None = None
    ) -> NDArray[np.float64]:
        """Cartesian returns of scan ``i`` in the laser frame, ``(M, 2)``, in beam order.

        A reading is a return when ``min_range < r < max_range`` (``max_range`` defaults to the
        scan's own maximum range). NaN rows mark the beams that are not returns, so that beam
        adjacency survives (:mod:`slamrel.scans.matching` needs neighbours along the scan).
        """
        n = int(self.beams[i])
        r = self.ranges[i, :n]
        top = float(self.max_range[i]) if max_range is None else min(max_range, self.max_range[i])
        a = self.angles(i)
        ok = (r > min_range) & (r < top)
        pts = np.column_stack((r * np.cos(a), r * np.sin(a)))
        pts[~ok] = np.nan
        return pts

    def nearest(self, t: NDArray[np.float64]) -> NDArray[np.int64]:
        """Index of the scan nearest in time to each of ``t`` (:func:`nearest_times`)."""
        return nearest_times(self.timestamps, t)[0]


def nearest_times(
    times: NDArray[np.float64], t: NDArray[np.float64]
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """For each of ``t``: the index into ``times`` nearest to it and the gap ``|Δt|`` [s].

    ``times`` need not be sorted; a tie goes to the earlier time.
    """
    t = np.asarray(t, dtype=np.float64)
    order = np.argsort(times, kind="stable")
    ts = np.asarray(times, dtype=np.float64)[order]
    k = np.clip(np.searchsorted(ts, t), 1, max(len(ts) - 1, 1))
    left = k - 1
    right = np.minimum(k, len(ts) - 1)
    pick = np.where(np.abs(ts[right] - t) < np.abs(t - ts[left]), right, left)
    return order[pick], np.abs(ts[pick] - t)


def read_laser_scans(path: PathLike, *, record: str | None = None) -> LaserScans:
    """Read the laser scans of a CARMEN log.

    Parameters
    ----------
    path : str or PathLike
    record : str, optional
        Which laser record to read (one of ``FLASER``, ``RLASER``, ``ROBOTLASER1``,
        ``ROBOTLASER2``, ``RAWLASER1``..``RAWLASER4``). When omitted the log must hold one kind
        only; with several kinds an :class:`InputError` lists them.

    Returns
    -------
    LaserScans
    """
    src = read_source(path)
    if record is not None and record not in CARMEN_LASER_RECORDS:
        raise InputError(
            f"unknown laser record {record!r}; expected one of {', '.join(CARMEN_LASER_RECORDS)}",
            path=src.path,
        )
    kinds: Counter[str] = Counter()
    skipped: Counter[str] = Counter()
    rows: list[tuple[int, list[str]]] = []
    for number, text in src.data_lines():
        fields = text.split()
        kind = fields[0]
        if kind in CARMEN_LASER_RECORDS:
            kinds[kind] += 1
            if record is None or kind == record:
                rows.append((number, fields))
                continue
        skipped[kind] += 1
    if src.cut_off_line() is not None:
        skipped["truncated last line"] += 1
    if record is None and len(kinds) > 1:
        found = ", ".join(f"{k} ({v})" for k, v in sorted(kinds.items()))
        raise InputError(
            f"the log holds several kinds of laser records: {found}; choose one (record=...)",
            path=src.path,
        )
    chosen = record or (next(iter(kinds)) if kinds else None)
    if chosen is None or not rows:
        raise InputError(
            f"no {chosen or 'laser'} records found (expected one of "
            f"{', '.join(CARMEN_LASER_RECORDS)})",
            path=src.path,
        )
    rows = [(n, f) for n, f in rows if f[0] == chosen]
    return _scans_from_rows(src, chosen, rows, dict(skipped))


def _scans_from_rows(
    src: SourceText, kind: str, rows: list[tuple[int, list[str]]], skipped: dict[str, int]
) -> LaserScans:
    path = src.path
    n = len(rows)
    layouts = [carmen_layout(f, src, number) for number, f in rows]
    beams = np.array([lay.readings for lay in layouts], dtype=np.int64)
    width = int(beams.max()) if n else 0
    ranges = np.full((n, width), np.nan)
    config = np.empty((n, 4))
    laser = np.full((n, 3), np.nan)
    odom = np.full((n, 3), np.nan)
    times = np.empty(n)
    guessed = kind in ("FLASER", "RLASER")
    for k, ((number, f), lay) in enumerate(zip(rows, layouts, strict=True)):
        assert lay.ranges is not None
        r = carmen_floats(f, lay.ranges, lay.readings, "range reading", src, number)
        ranges[k, : lay.readings] = r
        if lay.config is not None:
            config[k] = carmen_floats(f, lay.config + 1, 4, "laser configuration", src, number)
        else:
            start, res = guess_laser_config(lay.readings)
            config[k] = (start, math.pi, res, FLASER_MAX_RANGE)
        if lay.laser is not None:
            laser[k] = carmen_floats(f, lay.laser, 3, "laser pose", src, number)
        if lay.robot is not None:
            odom[k] = carmen_floats(f, lay.robot, 3, "odometry pose", src, number)
        times[k] = carmen_floats(f, lay.time, 1, "ipc_timestamp", src, number)[0]
        bad = [
            what
            for what, values in (
                ("range reading", r),
                ("laser configuration", config[k]),
                ("pose", np.concatenate((laser[k], odom[k])) if lay.laser is not None else ()),
                ("ipc_timestamp", times[k : k + 1]),
            )
            if not np.isfinite(values).all()
        ]
        if bad:
            raise InputError(
                f"{kind} record: non-finite {bad[0]}; expected finite numbers",
                path=path,
                line=number,
            )
        if config[k, 2] <= 0 or config[k, 3] <= 0:
            raise InputError(
                f"{kind} record: angular resolution and maximum range must be positive, got "
                f"{config[k, 2]} and {config[k, 3]}",
                path=path,
                line=number,
            )
    return LaserScans(
        path=path,
        record=kind,
        timestamps=times,
        ranges=ranges,
        beams=beams,
        start_angle=config[:, 0].copy(),
        angular_resolution=config[:, 2].copy(),
        max_range=config[:, 3].copy(),
        laser_pose=laser,
        odometry_pose=odom,
        lines=np.array([number for number, _ in rows], dtype=np.int64),
        guessed_config=guessed,
        skipped=skipped,
    )
