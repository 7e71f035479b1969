"""Poses and laser scans from ROS bags: ROS 1 ``.bag``, ROS 2 sqlite3 (``.db3`` or a bag
directory) and MCAP.

Read through `rosbags <https://gitlab.com/ternaris/rosbags>`_ (pure Python, Apache-2.0), a
dependency of slamrel as of evo (bags work after ``pip install .``); it is imported only when a
bag is read, so start-up and ``--help`` do not pay for it.

Naming a trajectory in a bag
----------------------------
A bag holds many topics, so a trajectory is named ``BAG:TOPIC`` wherever a trajectory file is
expected (``slamrel evaluate run.bag:/groundtruth run.bag:/orb_slam/pose``), the ``bag file +
topic`` pair of ``evo_ape bag``. ``BAG`` is a ``.bag`` file (ROS 1), a ``.db3`` or ``.mcap``
file, or a ROS 2 bag directory (with ``metadata.yaml``); ``TOPIC`` is the topic's name exactly
as the bag spells it (leading slash or not). A transform chain of the tf tree is named
``BAG:/tf:PARENT.CHILD`` (evo's spelling): the pose of frame ``CHILD`` in frame ``PARENT``.
When a frame name itself contains a dot, the split whose two names are both frames of the
bag is taken (two such splits are refused as ambiguous).

Message types
-------------
``geometry_msgs/PoseStamped``           ``pose``
``geometry_msgs/PoseWithCovarianceStamped`` ``pose.pose`` and the 6×6 ``pose.covariance``
``nav_msgs/Odometry``                   ``pose.pose`` and ``pose.covariance`` (child frame kept)
``geometry_msgs/TransformStamped``      ``transform``
``tf2_msgs/TFMessage`` (``/tf``, ``/tf_static``)  a chain ``PARENT.CHILD``, see below

The time of a pose is its ``header.stamp`` (``sec + nanosec · 1e-9``, as evo converts it), not
the time the bag recorded the message. Poses are ``[x, y, z, qx, qy, qz, qw]`` (Hamilton,
scalar last: the pose of the message's child/body frame in ``header.frame_id``).

Covariances are ROS's: row-major 6×6 over ``(x, y, z, rotation about X, about Y, about Z)``
(``geometry_msgs/PoseWithCovariance``). A message whose covariance is all zero (ROS's "not
filled in") is kept as a pose; the covariance of such a topic is then absent.

Laser scans
-----------
``sensor_msgs/LaserScan``               ``ranges``, ``angle_min``, ``angle_increment``,
                                        ``range_min``, ``range_max``, ``header.frame_id``

:func:`read_bag_laser_scans` reads a scan topic named ``BAG:TOPIC`` as a trajectory topic is
named (``slamrel.formats.laser.read_laser_scans`` turns it into the laser reader's record).
The time of a scan is its ``header.stamp``; beam ``k`` points at ``angle_min + k ·
angle_increment`` in the laser's frame (``angle_max`` is not needed). Readings are kept as
recorded, NaN and ±inf included (REP 117's "no return" values); which of them are returns
(``range_min < r < range_max``) the scan record decides, as it does for a CARMEN log's
readings at or beyond the maximum range. One topic is one laser: a beam count or
``frame_id`` that changes within it is refused. The laser's pose on the robot is not in a
LaserScan; :func:`read_static_transform` composes it from the bag's ``tf_static`` (the static
transforms alone, e.g. ``base_link → laser``), when they connect the two frames.

tf chains
---------
Every ``TFMessage`` topic is read; a topic named ``tf_static`` (with or without slash) holds
static transforms (valid at all times). The path from ``PARENT`` to ``CHILD`` in the frame tree
(edges may be walked backwards: the inverse transform) is composed as
``T_parent_child = T_1 ∘ T_2 ∘ …``. The chain's poses are at the stamps of its dynamic edge
closest to ``CHILD``; every other dynamic edge is interpolated at those stamps as tf2 does
(translation linearly, rotation by slerp). Stamps outside another dynamic edge's time span
cannot be interpolated (tf2's extrapolation error): they are dropped and counted
(``skipped["outside the tf chain's time span"]``).
"""

from __future__ import annotations

import os
import warnings
from collections import Counter
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from relation_metric.errors import InputError

__all__ = [
    "BAG_EXTENSIONS",
    "POSE_MESSAGE_TYPES",
    "BagSpec",
    "TfChainWarning",
    "BagTopic",
    "BagPoses",
    "split_bag_spec",
    "is_bag",
    "names_bag",
    "bag_topics",
    "describe_bag_topics",
    "read_bag_poses",
    "one_opening",
    "LASER_MESSAGE_TYPES",
    "BagScans",
    "read_bag_laser_scans",
    "read_static_transform",
    "bag_topic_frames",
]

#: Bag file extensions and their storage (a ROS 2 bag may also be a directory).
BAG_EXTENSIONS = {".bag": "ROS 1", ".db3": "ROS 2 sqlite3", ".mcap": "MCAP"}

_POSE = "geometry_msgs/msg/PoseStamped"
_POSE_COV = "geometry_msgs/msg/PoseWithCovarianceStamped"
_ODOM = "nav_msgs/msg/Odometry"
_TRANSFORM = "geometry_msgs/msg/TransformStamped"
_TF = "tf2_msgs/msg/TFMessage"
_LASER = "sensor_msgs/msg/LaserScan"
#: The message types whose topics are laser scans (:func:`read_bag_laser_scans`).
LASER_MESSAGE_TYPES = (_LASER,)
#: The message types whose topics are trajectories (TFMessage through a ``PARENT.CHILD`` chain).
POSE_MESSAGE_TYPES = (_POSE, _POSE_COV, _ODOM, _TRANSFORM, _TF)
#: The types whose messages carry a pose covariance.
COVARIANCE_TYPES = (_POSE_COV, _ODOM)


class TfChainWarning(UserWarning):
    """Stamps of a tf chain that cannot be interpolated were left out (counted)."""


_INSTALL = "rosbags is a dependency of slamrel: reinstall it (pip install .) or pip install rosbags"


@dataclass(frozen=True)
class BagSpec:
    """A trajectory named in a bag: ``BAG:TOPIC`` or ``BAG:/tf:PARENT.CHILD``."""

    #: The bag: a .bag/.db3/.mcap file or a ROS 2 bag directory.
    path: str
    #: The topic (for a tf chain, the tf topic as written, e.g. ``/tf``).
    topic: str
    #: ``PARENT.CHILD`` of a tf chain, as written (split by :func:`read_bag_poses`), or None.
    frames: str | None = None

    def __str__(self) -> str:
        return f"{self.path}:{self.topic}" + (f":{self.frames}" if self.frames else "")


@dataclass(frozen=True)
class BagTopic:
    """One topic of a bag."""

    topic: str
    #: The ROS 2 spelling of its type (``geometry_msgs/msg/PoseStamped``), also for ROS 1.
    msgtype: str
    #: Messages on it.
    count: int

    @property
    def is_trajectory(self) -> bool:
        """Whether slamrel reads poses from it (:data:`POSE_MESSAGE_TYPES`)."""
        return self.msgtype in POSE_MESSAGE_TYPES

    @property
    def is_laser(self) -> bool:
        """Whether slamrel reads laser scans from it (:data:`LASER_MESSAGE_TYPES`)."""
        return self.msgtype in LASER_MESSAGE_TYPES

    @property
    def read_as(self) -> str | None:
        """What slamrel reads from the topic: ``"trajectory"``, ``"laser scans"`` or None."""
        return "trajectory" if self.is_trajectory else "laser scans" if self.is_laser else None


@dataclass(frozen=True)
class BagPoses:
    """Poses read from one topic (or tf chain) of a bag, in the bag's message order.

    Attributes
    ----------
    timestamps : ndarray, shape (N,)
        ``header.stamp`` in seconds.
    poses : ndarray, shape (N, 7)
        ``[x, y, z, qx, qy, qz, qw]``.
    covariances : ndarray, shape (N, 6, 6), or None
        ROS order ``(x, y, z, rx, ry, rz)``; None for types without covariance or when every
        message's covariance is zero (not filled in).
    msgtype : str
    frame_id, child_frame_id : str
        ``header.frame_id`` of the first message (PARENT of a tf chain); the child frame
        (Odometry, TransformStamped, CHILD of a tf chain; ``""`` otherwise).
    skipped : Mapping[str, int]
        What was not used, by reason.
    """

    timestamps: NDArray[np.float64]
    poses: NDArray[np.float64]
    covariances: NDArray[np.float64] | None
    msgtype: str
    frame_id: str
    child_frame_id: str = ""
    skipped: Mapping[str, int] = field(default_factory=dict)


def is_bag(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is a bag: a .bag/.db3/.mcap file or a directory with metadata.yaml."""
    p = Path(path)
    if p.is_dir():
        return (p / "metadata.yaml").is_file()
    return p.suffix.lower() in BAG_EXTENSIONS and p.is_file()


def names_bag(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is a bag or a ``BAG:TOPIC`` (:func:`split_bag_spec`)."""
    return is_bag(path) or split_bag_spec(path) is not None


def split_bag_spec(spec: str | os.PathLike[str]) -> BagSpec | None:
    """``BAG:TOPIC`` split into the bag and the topic; None when ``spec`` names no bag topic.

    The bag is the longest prefix before a ``:`` that is a bag (:func:`is_bag`); an existing
    file of that whole name is a file, never a bag topic. ``TOPIC`` ``/tf:PARENT.CHILD``
    (or ``tf:…``, ``/tf_static:…``) names a tf chain. A bag given without a topic is refused
    by the trajectory reader (which lists the topics).
    """
    text = os.fspath(spec)
    if os.path.exists(text):
        return None
    cut = [k for k, ch in enumerate(text) if ch == ":"]
    for k in reversed(cut):
        head, tail = text[:k], text[k + 1 :]
        if head and is_bag(head):
            break
    else:
        return None
    if not tail:
        raise InputError("no topic after the ':'; expected BAG:TOPIC", path=head)
    topic, sep, frames = tail.partition(":")
    if sep and topic.lstrip("/") not in ("tf", "tf_static"):
        raise InputError(
            f"topic {tail!r}: a second ':' names the frames of a tf chain (BAG:/tf:PARENT.CHILD), "
            f"but {topic!r} is not a tf topic",
            path=head,
        )
    if sep and not frames:
        raise InputError(
            f"topic {tail!r}: expected the frames of the tf chain after the ':' "
            "(BAG:/tf:PARENT.CHILD)",
            path=head,
        )
    return BagSpec(head, topic, frames or None)


#: Readers kept open by :func:`one_opening`, by path.
_KEPT: dict[str, Any] = {}


@contextmanager
def one_opening(path: str | os.PathLike[str]) -> Iterator[None]:
    """Within the block, every read of the bag at ``path`` shares one open reader.

    Opening a bag indexes it and builds its message types (~0.4 s for ``ROS_example.bag``);
    ``slamrel ape bag BAG REF EST`` reads two topics of one bag and pays that once.
    """
    key = os.fspath(path)
    if key in _KEPT:
        yield
        return
    with _open(key) as reader:
        _KEPT[key] = reader
        try:
            yield
        finally:
            _KEPT.pop(key, None)


@contextmanager
def _open(path: str) -> Iterator[Any]:
    """An open ``rosbags`` reader of any of the three storages, errors as InputError (the
    one :func:`one_opening` keeps, when it keeps one for ``path``)."""
    if path in _KEPT:
        yield _KEPT[path]
        return
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise InputError(f"reading a ROS bag needs rosbags; {_INSTALL}", path=path) from None
    p = Path(path)
    try:
        # ROS 1 bags carry their message definitions; ROS 2 storages may not: default types
        reader = AnyReader([p], default_typestore=get_typestore(Stores.LATEST))
        reader.open()
    except Exception as exc:  # rosbags raises its own errors and OSError: one message
        raise InputError(
            f"cannot read the bag ({type(exc).__name__}: {exc}); expected a ROS 1 .bag, a ROS 2 "
            "sqlite3 .db3 or MCAP .mcap file, or a ROS 2 bag directory",
            path=path,
        ) from None
    try:
        yield reader
    finally:
        reader.close()


def bag_topics(path: str | os.PathLike[str]) -> list[BagTopic]:
    """The topics of a bag, by name (message counts summed over connections)."""
    with _open(os.fspath(path)) as reader:
        return _topics(reader)


def _topics(reader: Any) -> list[BagTopic]:
    count: Counter[str] = Counter()
    kind: dict[str, str] = {}
    for c in reader.connections:
        count[c.topic] += int(c.msgcount)
        kind.setdefault(c.topic, c.msgtype)
    return [BagTopic(t, kind[t], count[t]) for t in sorted(kind)]


def _messages(
    reader: Any, connections: list[Any], *, decode: bool = True
) -> Iterator[tuple[int, Any, Any]]:
    """``(k, connection, message)`` of ``connections`` in bag order, ``k`` the 1-based index
    of the message on its topic; a message that cannot be read or deserialized (cut off,
    another type than its connection declares) raises :class:`InputError` naming the bag,
    the topic and ``k`` instead of a bug report. ``decode=False``: the raw bytes."""
    count: Counter[str] = Counter()
    stream = iter(reader.messages(connections=connections))
    while True:
        try:
            connection, _, raw = next(stream)
        except StopIteration:
            return
        except Exception as exc:  # noqa: BLE001 - rosbags' own errors, struct, OSError
            after = ", ".join(f"{t} after {n}" for t, n in sorted(count.items()))
            raise InputError(
                f"cannot read the next message ({type(exc).__name__}: {exc})"
                + (f" (messages read: {after})" if after else "")
                + "; expected a complete bag",
                path=reader.paths[0],
            ) from None
        count[connection.topic] += 1
        k = count[connection.topic]
        if not decode:
            yield k, connection, raw
            continue
        try:
            msg = reader.deserialize(raw, connection.msgtype)
        except Exception as exc:  # noqa: BLE001 - any bytes that do not decode
            raise InputError(
                f"topic {connection.topic!r}, message {k}: does not deserialize as "
                f"{connection.msgtype.replace('/msg/', '/')} ({type(exc).__name__}: {exc}); "
                "expected a message of the type its connection declares",
                path=reader.paths[0],
            ) from None
        yield k, connection, msg


def describe_bag_topics(topics: list[BagTopic]) -> str:
    """``its topics: /a (geometry_msgs/PoseStamped, 12), ...`` for messages."""
    if not topics:
        return "the bag has no topics"
    rows = [f"{t.topic} ({t.msgtype.replace('/msg/', '/')}, {t.count})" for t in topics]
    return "its topics: " + ", ".join(rows)


def read_bag_poses(spec: BagSpec) -> BagPoses:
    """The poses of ``spec``'s topic or tf chain (see the module docstring).

    Raises
    ------
    InputError
        A missing topic (the bag's topics listed), a message type without poses, a topic
        without messages, a tf chain whose frames are not connected, rosbags not installed.
    """
    with _open(spec.path) as reader:
        topics = {t.topic: t for t in _topics(reader)}
        where = str(spec)
        info = _typed_topic(topics, spec, POSE_MESSAGE_TYPES)
        if info.msgtype == _TF:
            if spec.frames is None:
                raise InputError(
                    f"topic {spec.topic!r} is a tf tree; name the chain as "
                    f"{spec.path}:{spec.topic}:PARENT.CHILD ({_frames_text(reader, topics)})",
                    path=spec.path,
                )
            return _finite(_tf_chain(reader, topics, spec), spec)
        if info.count == 0:
            raise InputError(f"topic {spec.topic!r} has no messages", path=where)
        return _finite(_read_topic(reader, spec.topic, info.msgtype), spec)


_POSE_FIELDS = ("x", "y", "z", "qx", "qy", "qz", "qw")


def _finite(got: BagPoses, spec: BagSpec) -> BagPoses:
    """``got``, or :class:`InputError` at the first message (1-based, in bag order: a bag's
    line) whose stamp or pose holds a non-finite number."""
    bad = ~np.isfinite(got.poses).all(axis=1) | ~np.isfinite(got.timestamps)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        row = got.poses[k]
        fields = [n for n, v in zip(_POSE_FIELDS, row, strict=True) if not np.isfinite(v)]
        what = f"{', '.join(fields)} = {row[~np.isfinite(row)][0]}" if fields else "its stamp"
        raise InputError(
            f"topic {spec.topic!r}, message {k + 1} of {bad.size} (stamp "
            f"{float(got.timestamps[k])!r}): {what}; expected finite numbers "
            f"({int(bad.sum())} such message(s))",
            path=spec.path,
        )
    return got


def _typed_topic(topics: Mapping[str, BagTopic], spec: BagSpec, types: tuple[str, ...]) -> BagTopic:
    """The topic ``spec`` names, refused when missing (the bag's topics listed) or of a type
    not among ``types``."""
    if spec.topic not in topics:
        raise InputError(
            f"no topic {spec.topic!r} in the bag; {describe_bag_topics(list(topics.values()))}",
            path=spec.path,
        )
    info = topics[spec.topic]
    if info.msgtype not in types:
        names = ", ".join(t.replace("/msg/", "/") for t in types)
        expected = f"one of {names}" if len(types) > 1 else names
        raise InputError(
            f"topic {spec.topic!r} holds {info.msgtype.replace('/msg/', '/')} messages; "
            f"expected {expected}",
            path=spec.path,
        )
    return info


def _read_topic(reader: Any, topic: str, msgtype: str) -> BagPoses:
    """Poses (and covariances) of one pose topic, in bag order."""
    connections = [c for c in reader.connections if c.topic == topic]
    if msgtype == _POSE and not reader.is2:
        raw = [r for _, _, r in _messages(reader, connections, decode=False)]
        fast = _ros1_pose_stamped(raw)
        if fast is not None:
            return BagPoses(fast[0], fast[1], None, msgtype, fast[2], "")
    stamps: list[float] = []
    rows: list[tuple[float, ...]] = []
    covs: list[Any] = []
    frame = child = None
    for _, _, msg in _messages(reader, connections):
        s = msg.header.stamp
        stamps.append(s.sec + s.nanosec * 1e-9)
        if msgtype == _TRANSFORM:
            p, q = msg.transform.translation, msg.transform.rotation
            child = msg.child_frame_id if child is None else child
        else:
            pose = msg.pose.pose if msgtype in COVARIANCE_TYPES else msg.pose
            p, q = pose.position, pose.orientation
            if msgtype in COVARIANCE_TYPES:
                covs.append(msg.pose.covariance)
            if msgtype == _ODOM and child is None:
                child = msg.child_frame_id
        rows.append((p.x, p.y, p.z, q.x, q.y, q.z, q.w))
        frame = msg.header.frame_id if frame is None else frame
    cov = None
    if covs:
        c = np.asarray(covs, dtype=np.float64).reshape(-1, 6, 6)
        cov = c if np.any(c) else None
    return BagPoses(
        np.asarray(stamps, dtype=np.float64),
        np.asarray(rows, dtype=np.float64).reshape(-1, 7),
        cov,
        msgtype,
        frame or "",
        child or "",
    )


def _ros1_pose_stamped(raw: list[bytes]) -> tuple[NDArray, NDArray, str] | None:
    """ROS 1 ``PoseStamped`` messages decoded at once: ``(stamps (N,), poses (N, 7), frame)``.

    The ROS 1 layout, little-endian: ``uint32 seq, uint32 sec, uint32 nsec, uint32 len,
    frame_id[len], float64 x y z qx qy qz qw``. Deserialising message by message costs ~45 µs
    each (rosbags; 21,127 messages of ``ROS_example.bag``: ~1 s); when every message has
    the same size and the same frame_id length (one frame, as a topic has), the bytes are
    one ``(N, size)`` array and the fields are views of it. None otherwise (the caller then
    deserialises each message).
    """
    if not raw or len({len(r) for r in raw}) != 1:
        return None
    size = len(raw[0])
    flen = size - 16 - 56
    if flen < 0:
        return None
    buf = np.frombuffer(b"".join(raw), dtype=np.uint8).reshape(-1, size)
    head = np.ascontiguousarray(buf[:, :16]).view("<u4")
    if (head[:, 3] != flen).any() or (buf[:, 16 : 16 + flen] != buf[0, 16 : 16 + flen]).any():
        return None
    stamps = head[:, 1].astype(np.float64) + head[:, 2].astype(np.float64) * 1e-9
    poses = np.ascontiguousarray(buf[:, 16 + flen :]).view("<f8").astype(np.float64)
    return stamps, poses, bytes(buf[0, 16 : 16 + flen]).decode("utf-8", "replace")


@dataclass
class _Edge:
    parent: str
    child: str
    static: bool
    t: list[float] = field(default_factory=list)
    rows: list[tuple[float, ...]] = field(default_factory=list)


def _tf_edges(reader: Any, topics: Mapping[str, Any]) -> dict[str, _Edge]:
    """Every transform of every TFMessage topic, by child frame (a tree: one parent each)."""
    tf_topics = [t for t, info in topics.items() if info.msgtype == _TF]
    connections = [c for c in reader.connections if c.topic in tf_topics]
    edges: dict[str, _Edge] = {}
    if not connections:  # rosbags reads every topic for an empty list
        return edges
    for _, connection, msg in _messages(reader, connections):
        static = connection.topic.lstrip("/") == "tf_static"
        for tf in msg.transforms:
            parent, child = tf.header.frame_id.lstrip("/"), tf.child_frame_id.lstrip("/")
            edge = edges.setdefault(child, _Edge(parent, child, static))
            if edge.parent != parent:
                raise InputError(
                    f"frame {child!r} has two parents in the tf tree ({edge.parent!r} and "
                    f"{parent!r}); expected a tree",
                    path=reader.paths[0],
                )
            s = tf.header.stamp
            p, q = tf.transform.translation, tf.transform.rotation
            edge.t.append(s.sec + s.nanosec * 1e-9)
            edge.rows.append((p.x, p.y, p.z, q.x, q.y, q.z, q.w))
    return edges


def _frames_text(reader: Any, topics: Mapping[str, Any]) -> str:
    edges = _tf_edges(reader, topics)
    pairs = sorted(f"{e.parent}->{e.child}" for e in edges.values())
    return "its transforms: " + (", ".join(pairs) if pairs else "none")


def _split_frames(frames: str, known: set[str], path: str) -> tuple[str, str]:
    """``PARENT.CHILD`` split at the dot whose two sides are frames of the tree."""
    cuts = [k for k, ch in enumerate(frames) if ch == "."]
    fits = [
        (frames[:k].lstrip("/"), frames[k + 1 :].lstrip("/"))
        for k in cuts
        if frames[:k].lstrip("/") in known and frames[k + 1 :].lstrip("/") in known
    ]
    if len(fits) == 1:
        return fits[0]
    if not cuts:
        raise InputError(
            f"tf chain {frames!r}: expected PARENT.CHILD (two frame names joined by a dot)",
            path=path,
        )
    what = "is ambiguous: more than one split" if fits else "names no two frames"
    raise InputError(
        f"tf chain {frames!r} {what} of the tf tree; its frames: {', '.join(sorted(known))}",
        path=path,
    )


def _chain(edges: Mapping[str, _Edge], parent: str, child: str) -> list[tuple[_Edge, bool]]:
    """The edges from ``parent`` down to ``child``: (edge, walked forward), or [] if none."""

    def up(frame: str) -> list[str]:
        out = [frame]
        while out[-1] in edges and len(out) <= len(edges):
            out.append(edges[out[-1]].parent)
        return out

    from_child, from_parent = up(child), up(parent)
    common = next((f for f in from_child if f in from_parent), None)
    if common is None:
        return []
    back = [(edges[f], False) for f in from_parent[: from_parent.index(common)]]
    down = [(edges[f], True) for f in reversed(from_child[: from_child.index(common)])]
    return back + down


def _tf_chain(reader: Any, topics: Mapping[str, Any], spec: BagSpec) -> BagPoses:
    from relation_metric import se3

    assert spec.frames is not None  # called for a tf chain
    edges = _tf_edges(reader, topics)
    known = set(edges) | {e.parent for e in edges.values()}
    parent, child = _split_frames(spec.frames, known, spec.path)
    chain = _chain(edges, parent, child) if parent != child else []
    if not chain:
        raise InputError(
            f"no transform chain from {parent!r} to {child!r} in the tf tree; "
            f"{_frames_text(reader, topics)}",
            path=spec.path,
        )
    dynamic = [e for e, _ in chain if not e.static]
    last = dynamic[-1] if dynamic else chain[-1][0]
    t_last = np.asarray(last.t)
    order = np.argsort(t_last, kind="stable")
    t = t_last[order]
    keep = np.ones(t.size, dtype=bool)
    for e in dynamic:
        lo, hi = min(e.t), max(e.t)
        keep &= (t >= lo) & (t <= hi)
    skipped = {}
    if not keep.all():
        dropped = int(np.count_nonzero(~keep))
        skipped["outside the tf chain's time span"] = dropped
        warnings.warn(
            f"{spec}: {dropped} of {t.size} stamps of {last.parent}->{last.child} lie outside the "
            "time span of another moving transform of the chain (tf2 cannot interpolate "
            "there); left out",
            TfChainWarning,
            stacklevel=3,
        )
    t = t[keep]
    if t.size == 0:
        raise InputError(
            f"tf chain {parent}.{child}: no stamp of {last.parent}->{last.child} lies inside the "
            "time span of every other moving transform of the chain",
            path=spec.path,
        )
    pose = se3.identity((t.size,))
    for e, forward in chain:
        step = _edge_at(e, t)
        pose = se3.compose(pose, step if forward else se3.inverse(step))
    return BagPoses(t, se3.normalize(pose), None, _TF, parent, child, skipped)


def _edge_at(edge: _Edge, t: NDArray[np.float64]) -> NDArray[np.float64]:
    """The edge's transform at times ``t`` (static: the last one; else tf2's interpolation)."""
    rows = np.asarray(edge.rows, dtype=np.float64)
    if edge.static:
        return np.broadcast_to(rows[-1], (t.size, 7))
    et = np.asarray(edge.t)
    order = np.argsort(et, kind="stable")
    et, rows = et[order], rows[order]
    k = np.clip(np.searchsorted(et, t, side="right") - 1, 0, max(et.size - 2, 0))
    if et.size == 1:
        return np.broadcast_to(rows[0], (t.size, 7))
    span = et[k + 1] - et[k]
    s = np.where(span > 0, (t - et[k]) / np.where(span > 0, span, 1.0), 0.0)
    xyz = rows[k, :3] + s[:, None] * (rows[k + 1, :3] - rows[k, :3])
    return np.column_stack((xyz, _slerp(rows[k, 3:], rows[k + 1, 3:], s)))


def _slerp(a: NDArray[np.float64], b: NDArray[np.float64], s: NDArray[np.float64]) -> NDArray:
    """Spherical interpolation of unit quaternions (N, 4) by fractions ``s`` (N,), the short way."""
    a = a / np.linalg.norm(a, axis=1, keepdims=True)
    b = b / np.linalg.norm(b, axis=1, keepdims=True)
    dot = np.einsum("ni,ni->n", a, b)
    b = np.where(dot[:, None] < 0, -b, b)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    small = theta < 1e-9
    sin = np.where(small, 1.0, np.sin(theta))
    wa = np.where(small, 1.0 - s, np.sin((1.0 - s) * theta) / sin)
    wb = np.where(small, s, np.sin(s * theta) / sin)
    q = wa[:, None] * a + wb[:, None] * b
    return q / np.linalg.norm(q, axis=1, keepdims=True)


@dataclass(frozen=True)
class BagScans:
    """The scans of one ``sensor_msgs/LaserScan`` topic, in the bag's message order.

    Attributes
    ----------
    timestamps : ndarray, shape (N,)
        ``header.stamp`` in seconds.
    ranges : ndarray, shape (N, B)
        ``ranges`` as recorded (float32 widened to float64); NaN, ±inf and readings outside
        ``range_min … range_max`` are kept as they are (REP 117's "no return" values).
    angle_min, angle_increment, range_min, range_max : ndarray, shape (N,)
        Each message's configuration [rad, rad, m, m].
    frame_id : str
        The laser's frame (``header.frame_id``, without a leading slash).
    """

    timestamps: NDArray[np.float64]
    ranges: NDArray[np.float64]
    angle_min: NDArray[np.float64]
    angle_increment: NDArray[np.float64]
    range_min: NDArray[np.float64]
    range_max: NDArray[np.float64]
    frame_id: str


def read_bag_laser_scans(spec: BagSpec) -> BagScans:
    """The scans of ``spec``'s ``sensor_msgs/LaserScan`` topic (see the module docstring).

    Raises
    ------
    InputError
        A missing topic (the bag's topics listed), a topic of another type, no messages, a
        beam count or ``frame_id`` that changes within the topic (two lasers on one topic),
        a configuration that is not finite (or a zero increment, or not
        ``0 ≤ range_min < range_max``), rosbags not installed.
    """
    where = str(spec)
    if spec.frames is not None:
        raise InputError(
            "a tf chain holds no laser scans; expected BAG:TOPIC of sensor_msgs/LaserScan",
            path=spec.path,
        )
    with _open(spec.path) as reader:
        info = _typed_topic({t.topic: t for t in _topics(reader)}, spec, LASER_MESSAGE_TYPES)
        if info.count == 0:
            raise InputError(f"topic {spec.topic!r} has no messages", path=where)
        connections = [c for c in reader.connections if c.topic == spec.topic]
        stamps: list[float] = []
        config: list[tuple[float, float, float, float]] = []
        rows: list[NDArray[np.float64]] = []
        frame: str | None = None
        for k, _, msg in _messages(reader, connections):
            r = np.asarray(msg.ranges, dtype=np.float64)
            if rows and r.size != rows[0].size:
                raise InputError(
                    f"message {k}: {r.size} beams, but the topic's first message has "
                    f"{rows[0].size}; expected one beam count on a laser topic",
                    path=where,
                )
            fid = msg.header.frame_id.lstrip("/")
            if frame is not None and fid != frame:
                raise InputError(
                    f"message {k}: frame_id {fid!r}, but the first message's is {frame!r}; "
                    "expected one laser on a laser topic",
                    path=where,
                )
            frame = fid
            s = msg.header.stamp
            stamps.append(s.sec + s.nanosec * 1e-9)
            config.append((msg.angle_min, msg.angle_increment, msg.range_min, msg.range_max))
            rows.append(r)
    cfg = np.asarray(config, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        bad = ~np.isfinite(cfg).all(axis=1) | (cfg[:, 1] == 0) | ~(cfg[:, 2] >= 0)
        bad |= ~(cfg[:, 2] < cfg[:, 3])
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        a0, da, lo, hi = cfg[k]
        raise InputError(
            f"message {k + 1}: angle_min {a0}, angle_increment {da}, range_min {lo}, range_max "
            f"{hi}; expected finite numbers, a non-zero increment and 0 ≤ range_min < range_max",
            path=where,
        )
    if rows[0].size == 0:
        raise InputError(f"topic {spec.topic!r}: the scans have no ranges", path=where)
    return BagScans(
        np.asarray(stamps, dtype=np.float64),
        np.stack(rows),
        cfg[:, 0].copy(),
        cfg[:, 1].copy(),
        cfg[:, 2].copy(),
        cfg[:, 3].copy(),
        frame or "",
    )


def read_static_transform(
    path: str | os.PathLike[str], parent: str, child: str
) -> tuple[NDArray[np.float64] | None, str]:
    """The pose ``[x, y, z, qx, qy, qz, qw]`` of frame ``child`` in ``parent`` composed from
    the static transforms (``tf_static``) alone, or None when they do not connect the two
    frames; and the bag's static transforms as text (``its static transforms: a->b, ...``).

    The chain is walked as :func:`read_bag_poses` walks a tf chain (edges backwards are
    inverted); a frame is its own identity.
    """
    from relation_metric import se3

    with _open(os.fspath(path)) as reader:
        topics = {t.topic: t for t in _topics(reader)}
        edges = {c: e for c, e in _tf_edges(reader, topics).items() if e.static}
    pairs = sorted(f"{e.parent}->{e.child}" for e in edges.values())
    text = "its static transforms: " + (", ".join(pairs) if pairs else "none")
    parent, child = parent.lstrip("/"), child.lstrip("/")
    if parent == child:
        return se3.identity(), text
    chain = _chain(edges, parent, child)
    if not chain:
        return None, text
    pose = se3.identity()
    for e, forward in chain:
        step = np.asarray(e.rows[-1], dtype=np.float64)
        pose = se3.compose(pose, step if forward else se3.inverse(step))
    return se3.normalize(pose), text


def bag_topic_frames(spec: BagSpec) -> tuple[str, str]:
    """``(frame_id, child_frame_id)`` of the first message of ``spec``'s topic (PARENT and
    CHILD of a tf chain); ``""`` for what the type does not carry (a PoseStamped's child)."""
    with _open(spec.path) as reader:
        topics = {t.topic: t for t in _topics(reader)}
        if spec.frames is not None:
            edges = _tf_edges(reader, topics)
            known = set(edges) | {e.parent for e in edges.values()}
            return _split_frames(spec.frames, known, spec.path)
        connections = [c for c in reader.connections if c.topic == spec.topic]
        for _, _, msg in _messages(reader, connections) if connections else ():
            child = getattr(msg, "child_frame_id", "")
            return msg.header.frame_id.lstrip("/"), str(child).lstrip("/")
    return "", ""
