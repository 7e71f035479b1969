"""Laser scans from CARMEN logs (``FLASER``, ``RLASER``, ``ROBOTLASER1/2``, ``RAWLASER1..4``)
and from ROS bags (``sensor_msgs/LaserScan``, named ``BAG:TOPIC``).

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
Scans stay in file order (keyframes and pairs follow the log as written); scans out of time
order are counted in a :class:`~relation_metric.timeorder.TimeOrderWarning` naming the first
one's line, since a pair of them measures motion backwards in time.

ROS bags
--------
A ``sensor_msgs/LaserScan`` topic (:func:`slamrel.formats.bags.read_bag_laser_scans`) gives
the same record: ``record`` ``"LaserScan"``, the time ``header.stamp``, ``start_angle`` =
``angle_min``, ``angular_resolution`` = ``angle_increment`` (negative for a scanner that
turns clockwise), ``max_range`` = ``range_max`` and :attr:`LaserScans.min_range` =
``range_min``, the laser's :attr:`LaserScans.frame_id`. Readings are kept as recorded and
judged as a CARMEN log's are: a return is ``range_min < r < range_max`` (so NaN, ±inf and
readings outside the range are no returns, masked by :meth:`LaserScans.points`, never
replaced). A LaserScan carries no pose: ``laser_pose`` and ``odometry_pose`` are NaN (as for
RAWLASER; pair the scans with an estimate by time), and ``lines`` is the 1-based message
index on the topic.
"""

from __future__ import annotations

import math
import warnings
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from relation_metric.errors import InputError
from relation_metric.se2 import between
from relation_metric.timeorder import TimeOrderWarning, sort_by_time
from slamrel.formats.bags import (
    BagSpec,
    bag_topics,
    describe_bag_topics,
    is_bag,
    read_bag_laser_scans,
    read_static_transform,
    split_bag_spec,
)
from slamrel.formats.fastparse import parse_decimal_table
from slamrel.formats.text import PathLike, SourceText, read_source
from slamrel.formats.trajectories import (
    CARMEN_LASER_RECORDS,
    CarmenLayout,
    carmen_floats,
    carmen_layout,
)

__all__ = [
    "LaserScans",
    "read_laser_scans",
    "nearest_times",
    "guess_laser_config",
    "FLASER_MAX_RANGE",
    "MAX_LASER_TILT",
    "bag_laser_offset",
    "BagScanWarning",
]

FLASER_MAX_RANGE = 80.0
"""The maximum range CARMEN assumes for FLASER/RLASER records [m]."""


class BagScanWarning(UserWarning):
    """A bag's scans: the laser offset could not be composed from tf_static (taken as zero),
    or scans had no pose of the estimate (left out, counted)."""


MAX_LASER_TILT = 0.1
"""The largest tilt of a bag's laser against its base frame's plane [rad] (≈ 5.7°)."""


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
    frame_id : str
        The laser's frame (ROS bags; ``""`` for CARMEN logs, which name none).
    min_range : (N,) float or None
        The scans' own minimum range [m] (a LaserScan's ``range_min``); None for CARMEN logs,
        which state none.
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
    frame_id: str = ""
    min_range: NDArray[np.float64] | None = None

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
        scan's own maximum range; ``min_range`` is raised to the scan's own minimum when it has
        one, :attr:`min_range`; NaN and ±inf are never returns). NaN rows mark the beams that
        are not returns, so that beam adjacency survives (:mod:`slamrel.scans.matching` needs
        neighbours along the scan).
        """
        n = int(self.beams[i])
        r = self.ranges[i, :n]
        top = float(self.max_range[i]) if max_range is None else min(max_range, self.max_range[i])
        low = min_range if self.min_range is None else max(min_range, float(self.min_range[i]))
        a = self.angles(i)
        with np.errstate(invalid="ignore"):
            ok = (r > low) & (r < top)
            pts = np.column_stack((r * np.cos(a), r * np.sin(a)))
        pts[~ok] = np.nan
        return pts

    def take(self, index: NDArray[np.int64]) -> LaserScans:
        """The scans at ``index`` (in that order), every per-scan array taken alike."""
        index = np.asarray(index, dtype=np.int64)
        per_scan = {
            name: getattr(self, name)[index]
            for name in (
                "timestamps",
                "ranges",
                "beams",
                "start_angle",
                "angular_resolution",
                "max_range",
                "laser_pose",
                "odometry_pose",
                "lines",
            )
        }
        low = None if self.min_range is None else self.min_range[index]
        return replace(self, **per_scan, min_range=low)

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
    """Read the laser scans of a CARMEN log, or of a ROS bag's ``sensor_msgs/LaserScan``
    topic named ``BAG:TOPIC`` (see the module docstring).

    Parameters
    ----------
    path : str or PathLike
    record : str, optional
        Which laser record to read (one of ``FLASER``, ``RLASER``, ``ROBOTLASER1``,
        ``ROBOTLASER2``, ``RAWLASER1``..``RAWLASER4``). When omitted the log must hold one kind
        only; with several kinds an :class:`InputError` lists them. Not for bags (the topic
        names the laser).

    Returns
    -------
    LaserScans
    """
    spec = split_bag_spec(path)
    if spec is not None or is_bag(path):
        return _read_bag_scans(path, spec, record)
    src = read_source(path)
    if record is not None and record not in CARMEN_LASER_RECORDS:
        raise InputError(
            f"unknown laser record {record!r}; expected one of {', '.join(CARMEN_LASER_RECORDS)}",
            path=src.path,
        )
    kinds: Counter[str] = Counter()
    skipped: Counter[str] = Counter()
    texts: list[tuple[int, str]] = []
    for number, text in src.data_lines():
        kind = text.split(None, 1)[0]  # the record's name (the rest is split when read)
        if kind in CARMEN_LASER_RECORDS:
            kinds[kind] += 1
            if record is None or kind == record:
                texts.append((number, text))
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
    if chosen is None or not texts:
        raise InputError(
            f"no {chosen or 'laser'} records found (expected one of "
            f"{', '.join(CARMEN_LASER_RECORDS)})",
            path=src.path,
        )
    if chosen in ("FLASER", "RLASER"):
        got = _flaser_in_one_pass(src, chosen, texts, dict(skipped))
        if got is not None:
            return got
    rows = [(n, t.split()) for n, t in texts]
    return _scans_from_rows(src, chosen, rows, dict(skipped))


def _flaser_in_one_pass(
    src: SourceText, kind: str, texts: list[tuple[int, str]], skipped: dict[str, int]
) -> LaserScans | None:
    """``FLASER``/``RLASER`` records (``KIND n r1..rn x y θ ox oy oθ ipc_t host logger_t``)
    read in one pass of :func:`parse_decimal_table` over their numbers ``r1 … ipc_t``, without
    splitting every record into its fields: when every record has the same plain count ``n``
    and exactly ``n + 7`` plain decimals between it and the last two fields (the parse checks
    the count per line). The values are those of :func:`_scans_from_rows`, bit for bit; None
    for anything else (the record-by-record path then reads or diagnoses it)."""
    heads = [t.split(None, 2) for _, t in texts]
    n_tok = heads[0][1] if len(heads[0]) == 3 else ""
    if not (n_tok.isdigit() and n_tok == str(int(n_tok))):
        return None
    if any(len(h) != 3 or h[1] != n_tok for h in heads):
        return None
    n = int(n_tok)
    text = "\n".join(h[2].rsplit(None, 2)[0] for h in heads)
    if not text.isascii():
        return None
    table = parse_decimal_table((text + "\n").encode("ascii"), n + 7)
    if table is None or table.shape[0] != len(texts):
        return None
    start, res = guess_laser_config(n)
    config = np.empty((len(texts), 4))
    config[:] = (start, math.pi, res, FLASER_MAX_RANGE)
    return _laser_scans(
        src,
        kind,
        texts,
        np.ascontiguousarray(table[:, :n]),
        np.full(len(texts), n, dtype=np.int64),
        config,
        np.ascontiguousarray(table[:, n : n + 3]),
        np.ascontiguousarray(table[:, n + 3 : n + 6]),
        table[:, n + 6].copy(),
        True,
        skipped,
    )


def _fast_rows(
    rows: list[tuple[int, list[str]]],
    layouts: list[CarmenLayout],
    ranges: NDArray[np.float64],
    config: NDArray[np.float64],
    laser: NDArray[np.float64],
    odom: NDArray[np.float64],
    times: NDArray[np.float64],
) -> bool:
    """Fill the arrays from ``rows`` in one pass of :func:`parse_decimal_table` when every row
    has the same layout and every number is a plain decimal within the limits the loop in
    :func:`_scans_from_rows` checks (the same values, bit for bit); False (nothing trusted)
    otherwise, and the loop reads and diagnoses the rows one by one."""
    lay = layouts[0] if layouts else None
    if lay is None or lay.ranges is None or any(other != lay for other in layouts):
        return False
    n = lay.readings
    # (first field, count, where the values go) in the order they are joined
    parts: list[tuple[int, int, NDArray[np.float64]]] = [(lay.ranges, n, ranges[:, :n])]
    if lay.config is not None:
        parts.append((lay.config + 1, 4, config))
    if lay.laser is not None:
        parts.append((lay.laser, 3, laser))
    if lay.robot is not None:
        parts.append((lay.robot, 3, odom))
    parts.append((lay.time, 1, times[:, None]))
    ncols = sum(c for _, c, _ in parts)
    text = "\n".join(" ".join([t for a, c, _ in parts for t in f[a : a + c]]) for _, f in rows)
    if not text.isascii():
        return False
    table = parse_decimal_table((text + "\n").encode("ascii"), ncols)
    if table is None or table.shape[0] != len(rows):
        return False
    k = 0
    for _, c, target in parts:
        target[:] = table[:, k : k + c]
        k += c
    if lay.config is None:
        start, res = guess_laser_config(lay.readings)
        config[:] = (start, math.pi, res, FLASER_MAX_RANGE)
    elif not ((config[:, 2] > 0) & (config[:, 3] > 0)).all():
        return False  # the loop names the first bad record
    return True


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
    if _fast_rows(rows, layouts, ranges, config, laser, odom, times):
        rows_left: list[tuple[int, list[str]]] = []
    else:
        rows_left = rows
    for k, ((number, f), lay) in enumerate(zip(rows_left, layouts, strict=False)):
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
    return _laser_scans(
        src, kind, rows, ranges, beams, config, laser, odom, times, guessed, skipped
    )


def _laser_scans(
    src: SourceText,
    kind: str,
    rows: Sequence[tuple[int, object]],
    ranges: NDArray[np.float64],
    beams: NDArray[np.int64],
    config: NDArray[np.float64],
    laser: NDArray[np.float64],
    odom: NDArray[np.float64],
    times: NDArray[np.float64],
    guessed: bool,
    skipped: dict[str, int],
) -> LaserScans:
    """The :class:`LaserScans` of the records read (file lines from ``rows``), with the
    warning for timestamps out of order."""
    path = src.path
    lines = np.array([number for number, _ in rows], dtype=np.int64)
    report = sort_by_time(times, lines=lines, what=f"{kind} scan")[1]
    if report.out_of_order:
        warnings.warn(
            f"{path}: {report.describe(f'{kind} scan')}; kept in file order (keyframes and "
            "pairs follow the log as written)",
            TimeOrderWarning,
            stacklevel=3,
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
        lines=lines,
        guessed_config=guessed,
        skipped=skipped,
    )


def _read_bag_scans(path: PathLike, spec: BagSpec | None, record: str | None) -> LaserScans:
    """A bag's LaserScan topic as the laser record (NaN poses, the scans' own range_min)."""
    if spec is None:
        raise InputError(
            "is a ROS bag, which holds many topics: name the laser as BAG:TOPIC; "
            f"{describe_bag_topics(bag_topics(path))}",
            path=str(path),
        )
    if record is not None:
        raise InputError(
            f"record={record!r} names a CARMEN laser record; a bag's laser is named by its "
            "topic (BAG:TOPIC)",
            path=str(spec),
        )
    got = read_bag_laser_scans(spec)
    n, b = got.ranges.shape
    no_pose = np.full((n, 3), np.nan)
    return LaserScans(
        path=str(spec),
        record="LaserScan",
        timestamps=got.timestamps,
        ranges=got.ranges,
        beams=np.full(n, b, dtype=np.int64),
        start_angle=got.angle_min,
        angular_resolution=got.angle_increment,
        max_range=got.range_max,
        laser_pose=no_pose,
        odometry_pose=no_pose.copy(),
        lines=np.arange(1, n + 1, dtype=np.int64),
        guessed_config=False,
        frame_id=got.frame_id,
        min_range=got.range_min,
    )


def bag_laser_offset(bag: str, base: str, laser: str) -> tuple[NDArray[np.float64] | None, str]:
    """The laser's pose ``[x, y, θ]`` in frame ``base`` from the bag's ``tf_static``, or None
    when the static transforms do not connect the two frames; and a text for messages (the
    chain's frames and what the projection onto the plane dropped, or the bag's static
    transforms when there is no chain).

    The static chain ``base → laser`` (:func:`slamrel.formats.bags.read_static_transform`) is
    projected onto the plane: ``x, y`` and the yaw; ``z`` is dropped, and so are roll and pitch
    up to :data:`MAX_LASER_TILT` (the scans are planar in the base frame to within
    ``1 − cos(tilt)`` of each range).

    Raises
    ------
    InputError
        The laser is tilted by more than :data:`MAX_LASER_TILT` (an upside-down laser too:
        its scans would be mirrored, which slamrel does not undo).
    """
    from relation_metric import se3

    pose, text = read_static_transform(bag, base, laser)
    if pose is None:
        return None, text
    up = se3.quat_rotate(pose[3:], np.array([0.0, 0.0, 1.0]))
    tilt = float(np.arccos(np.clip(up[2], -1.0, 1.0)))
    if tilt > MAX_LASER_TILT:
        raise InputError(
            f"tf_static puts the laser frame {laser!r} at a tilt of {math.degrees(tilt):.1f}° "
            f"against {base!r}; expected a level laser (within "
            f"{math.degrees(MAX_LASER_TILT):.1f}°; an upside-down laser is not supported)",
            path=bag,
        )
    planar = se3.to_planar(pose)
    dropped = f"z {pose[2]:.3g} m and a tilt of {math.degrees(tilt):.2g}° dropped"
    return planar, f"tf_static {base}->{laser}; {dropped}"
