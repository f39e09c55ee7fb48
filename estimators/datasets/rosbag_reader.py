"""Read ROS 1 (``.bag``) and ROS 2 (``.db3``, ``.mcap`` or a bag directory) recordings.

``sensor_msgs/LaserScan`` topics, one per Lidar, are decoded with the pure-Python ``rosbags``
library (no ROS install): beam ``i`` points at ``angle_min + i * angle_increment`` [rad] in
the scan's ``header.frame_id``; NaN, inf and readings outside ``[range_min, range_max]`` are
"no return" and read ``max_range``; intensities are ignored; header stamps are the clock.
Sensor mounts come from ``tf_static`` (the chain of static transforms from the base frame to
each laser frame, projected on the plane), or from the caller when the bag holds none.

LaserScan stores angles as float32; a scan whose beams cover one full turn gets the exact
float64 angles ``angle_min + 2 pi i / n`` (the env's convention), so a simulated drive read
back sees the same beam geometry it was simulated with.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimators.base import MAX_LIDARS, Sensor, SensorSetup, default_beam_angles
from estimators.datasets.recording import Recording, check_monotonic, synchronise
from estimators.datasets.truth import match_truth
from lidar_env.core import LogFormatError
from lidar_env.core.se2 import compose, wrap_angle

SCAN_TYPE = "sensor_msgs/msg/LaserScan"
TF_TYPE = "tf2_msgs/msg/TFMessage"
#: Ground-truth message types :func:`load_bag` reads from ``truth_topic``.
TRUTH_TYPES = ("nav_msgs/msg/Odometry", "geometry_msgs/msg/PoseStamped")
#: Relative gap of ``n * angle_increment`` to 2 pi below which a scan counts as a full turn
#: (float32 keeps about 7 digits).
FULL_TURN_TOLERANCE = 1e-6


@dataclass(frozen=True)
class ScanTopic:
    """Every LaserScan of one topic, decoded.

    Attributes:
        topic: the topic name.
        frame: the sensor frame (``header.frame_id`` of the first message).
        stamps: ``(N,)`` header stamps [s].
        ranges: ``(N, n)`` float64 readings [m]; no return (NaN, inf, out of range) is ``inf``.
        angles: ``(n,)`` beam directions [rad] in the sensor frame, CCW from forward.
        range_min: [m] the sensor's stated minimum.
        range_max: [m] the sensor's stated maximum.
    """

    topic: str
    frame: str
    stamps: NDArray[np.float64]
    ranges: NDArray[np.float64]
    angles: NDArray[np.float64]
    range_min: float
    range_max: float


def clock_seconds(sec: int, nanosec: int) -> float:
    """A ROS time (``sec`` [s] + ``nanosec`` [ns]) as float seconds, the recording's clock."""
    return float(sec) + 1e-9 * float(nanosec)


def stamp_seconds(stamp: Any) -> float:
    """A ROS 1 or ROS 2 ``Time`` message (``sec``/``nanosec`` in rosbags) as seconds."""
    return clock_seconds(stamp.sec, stamp.nanosec)


def beam_angles(angle_min: float, angle_increment: float, n: int) -> NDArray[np.float64]:
    """The ``n`` beam directions [rad] of a LaserScan (see the module docstring)."""
    if abs(n * angle_increment - 2 * np.pi) <= FULL_TURN_TOLERANCE * 2 * np.pi:
        return float(angle_min) + default_beam_angles(n)
    return float(angle_min) + float(angle_increment) * np.arange(n)


def _decode_scan(message: Any, source: str, topic: str, index: int) -> tuple[Any, ...]:
    ranges = np.asarray(message.ranges, dtype=np.float64)
    n = len(ranges)
    where = f"{source}, topic {topic}, message {index}"
    angles = {key: float(getattr(message, key))
              for key in ("angle_min", "angle_max", "angle_increment")}
    bad = [f"{key} {value}" for key, value in angles.items() if not np.isfinite(value)]
    if bad:
        raise LogFormatError(f"{where}: expected finite angles [rad], got {', '.join(bad)}")
    expected = round((message.angle_max - message.angle_min) / message.angle_increment) + 1 \
        if message.angle_increment != 0 else -1
    if n < 3 or abs(expected - n) > 1:
        raise LogFormatError(
            f"{source}, topic {topic}, message {index}: expected >= 3 ranges matching "
            f"angle_min/max/increment ({expected} beams), got {n}"
        )
    low, high = float(message.range_min), float(message.range_max)
    if not (np.isfinite(high) and high > 0):
        raise LogFormatError(
            f"{source}, topic {topic}, message {index}: range_max: expected a positive finite "
            f"number [m], got {high}"
        )
    if not (np.isfinite(low) and 0 <= low < high):
        raise LogFormatError(f"{where}: range_min: expected a number in [0, range_max) = [0, "
                             f"{high:g}) [m], got {low}")
    valid = np.isfinite(ranges) & (ranges >= low) & (ranges <= high)
    geometry = (float(message.angle_min), float(message.angle_increment), n, low, high)
    return np.where(valid, ranges, np.inf), geometry


def _scan_topic(reader: Any, connections: list[Any], source: str, topic: str) -> ScanTopic:
    stamps, rows, frame, geometry = [], [], "", None
    for index, (connection, _, raw) in enumerate(reader.messages(connections=connections)):
        message = reader.deserialize(raw, connection.msgtype)
        ranges, this = _decode_scan(message, source, topic, index)
        if geometry is None:
            geometry, frame = this, str(message.header.frame_id)
        elif str(message.header.frame_id) != frame:
            raise LogFormatError(
                f"{source}, topic {topic}, message {index}: header.frame_id "
                f"{str(message.header.frame_id)!r:.60} differs from the topic's first, "
                f"{frame!r:.60}; expected one laser frame per topic")
        elif this != geometry:
            raise LogFormatError(
                f"{source}, topic {topic}, message {index}: beam geometry changes within the "
                f"topic (angle_min, increment, beams, range_min, range_max = {this}, first "
                f"{geometry}); expected one laser setup per topic"
            )
        stamps.append(stamp_seconds(message.header.stamp))
        rows.append(ranges)
    if geometry is None:
        raise LogFormatError(f"{source}, topic {topic}: expected LaserScan messages, found none")
    times = np.array(stamps, dtype=np.float64)
    check_monotonic(times, source, topic)
    angle_min, increment, n, low, high = geometry
    return ScanTopic(topic, frame, times, np.stack(rows), beam_angles(angle_min, increment, n),
                     low, high)


def yaw(q: Any) -> float:
    """The yaw [rad] (rotation about +z, in [-pi, pi)) of a ``geometry_msgs/Quaternion``."""
    angle = np.arctan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
    return float(wrap_angle(angle))


def _planar(transform: Any) -> NDArray[np.float64]:
    """A ``geometry_msgs/Transform`` projected on the plane: (x [m], y [m], yaw [rad])."""
    return np.array([transform.translation.x, transform.translation.y, yaw(transform.rotation)])


def static_transforms(reader: Any) -> dict[str, tuple[str, NDArray[np.float64]]]:
    """``{child frame: (parent frame, planar pose of child in parent)}`` from ``/tf_static``."""
    tree: dict[str, tuple[str, NDArray[np.float64]]] = {}
    connections = [c for c in reader.connections if c.msgtype == TF_TYPE
                   and c.topic.lstrip("/") == "tf_static"]
    if not connections:  # rosbags reads every topic when given none
        return tree
    for connection, _, raw in reader.messages(connections=connections):
        for item in reader.deserialize(raw, connection.msgtype).transforms:
            tree[item.child_frame_id.lstrip("/")] = (
                item.header.frame_id.lstrip("/"), _planar(item.transform))
    return tree


def mount_in(tree: dict[str, tuple[str, NDArray[np.float64]]], frame: str,
             base: str | None) -> tuple[str, NDArray[np.float64]] | None:
    """``(base frame, planar pose of frame in it)`` composed up the static tree; ``base=None``
    climbs to the root. ``None`` when ``frame`` is not under ``base``."""
    frame = frame.lstrip("/")
    pose, current, seen = np.zeros(3), frame, {frame}
    while current != base and current in tree:
        parent, local = tree[current]
        pose = compose(local, pose)
        current = parent
        if current in seen:
            return None
        seen.add(current)
    if base is not None and current != base:
        return None
    return current, pose


def _pick_topics(reader: Any, topics: Sequence[str] | None, source: str) -> list[str]:
    scan_topics = sorted({c.topic for c in reader.connections if c.msgtype == SCAN_TYPE})
    if not scan_topics:
        found = ", ".join(sorted({f"{c.topic} ({c.msgtype})" for c in reader.connections}))
        raise LogFormatError(
            f"{source}: expected at least one {SCAN_TYPE} topic, found {found or 'no topics'}")
    if topics is None:
        return scan_topics
    missing = [t for t in topics if t not in scan_topics]
    if missing or not topics:
        raise LogFormatError(
            f"{source}: topic(s) {', '.join(missing) or '(none given)'} not in the bag as "
            f"LaserScan; expected some of {', '.join(scan_topics)}")
    return list(topics)


def _mounts(streams: list[ScanTopic], tree: dict[str, Any], base_frame: str | None,
            source: str) -> NDArray[np.float64]:
    found = [mount_in(tree, s.frame, base_frame) for s in streams]
    missing = [s.frame for s, m in zip(streams, found, strict=True)
               if m is None or (base_frame is None and s.frame.lstrip("/") not in tree)]
    roots = {m[0] for m in found if m is not None}
    if missing or len(roots) > 1:
        raise LogFormatError(
            f"{source}: expected tf_static transforms from one base frame "
            f"({base_frame or 'any'}) to every laser frame; frames without one: "
            f"{', '.join(missing) or 'none'}, roots found: {', '.join(sorted(roots))}. "
            "Pass mounts=(K, 3) to give them")
    return np.array([m[1] for m in found if m is not None])


def _setup(streams: list[ScanTopic], mounts: NDArray[np.float64], source: str) -> SensorSetup:
    if len(streams) > MAX_LIDARS:
        raise LogFormatError(
            f"{source}: {len(streams)} LaserScan topics; a SensorSetup carries at most "
            f"{MAX_LIDARS} Lidars: pass topics= to choose")
    return SensorSetup(sensors=[Sensor(mount, s.angles, s.range_max, k, s.range_min,
                                       s.frame.lstrip("/"))
                                for k, (mount, s) in enumerate(zip(mounts, streams,
                                                                   strict=True))])


def load_bag(
    path: str | Path,
    topics: Sequence[str] | None = None,
    *,
    mounts: ArrayLike | None = None,
    base_frame: str | None = None,
    truth_topic: str | None = None,
    sync_tolerance: float | None = None,
    truth_tolerance: float | None = None,
) -> Recording:
    """Read the LaserScan topics of a ROS 1 or ROS 2 bag as one :class:`Recording`.

    Args:
        path: a ``.bag`` file, a ``.db3`` or ``.mcap`` file, or a ROS 2 bag directory.
        topics: LaserScan topics, in order, as ``lidar_1..lidar_K``; ``None`` takes every
            LaserScan topic in name order.
        mounts: ``(K, 3)`` sensor poses in the base frame (x [m], y [m], heading [rad]); ``None``
            reads them from ``tf_static`` (a single Lidar without tf sits at the origin).
        base_frame: the frame the mounts are given in; ``None`` takes the root of the tf tree.
        truth_topic: an ``nav_msgs/Odometry`` or ``geometry_msgs/PoseStamped`` topic of true
            base poses, each matched to the nearest scan (see :attr:`Recording.truth`); it may
            cover only some scans (keyframes, a motion-capture rate of its own).
        sync_tolerance: largest stamp gap [s] between the scans of one observation (see
            :func:`estimators.datasets.recording.synchronise`).
        truth_tolerance: largest stamp gap [s] between a truth pose and its scan; ``None``
            takes half the median scan period (:func:`estimators.datasets.truth.match_truth`).
    """
    from rosbags.highlevel import AnyReader, AnyReaderError
    from rosbags.typesys import Stores, get_typestore

    path = Path(path)
    source = str(path)
    if not path.exists():
        raise FileNotFoundError(f"ROS bag not found: expected a file or directory at {path}")
    try:
        with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
            names = _pick_topics(reader, topics, source)
            streams = [_scan_topic(reader, [c for c in reader.connections if c.topic == name],
                                   source, name) for name in names]
            tree = static_transforms(reader) if mounts is None else {}
            truth = _truth_stream(reader, truth_topic, source) if truth_topic else None
    except LogFormatError:
        raise
    except FileNotFoundError as error:  # a ROS 2 bag directory without its metadata.yaml
        raise LogFormatError(f"{source}: not a readable ROS bag: expected a .bag, .db3 or .mcap "
                             f"file or a ROS 2 bag directory with its metadata.yaml ({error})"
                             ) from None
    except (AnyReaderError, *_storage_errors()) as error:
        raise LogFormatError(f"{source}: not a readable ROS bag ({error!r})") from None
    if mounts is None:
        if len(streams) == 1 and streams[0].frame.lstrip("/") not in tree:
            chosen = np.zeros((1, 3))
        else:
            chosen = _mounts(streams, tree, base_frame, source)
    else:
        try:
            chosen = np.asarray(mounts, dtype=np.float64)
        except (TypeError, ValueError, OverflowError):
            chosen = np.empty(0)
        if chosen.size == 3 * len(streams):
            chosen = chosen.reshape(-1, 3)
        if chosen.shape != (len(streams), 3) or not np.all(np.isfinite(chosen)):
            raise LogFormatError(
                f"mounts: expected ({len(streams)}, 3) finite poses (x [m], y [m], heading "
                f"[rad]), one per topic, got {str(mounts)[:60]}")
    return _assemble(source, streams, _setup(streams, chosen, source), truth, sync_tolerance,
                     truth_tolerance)


def _storage_errors() -> tuple[type[Exception], ...]:
    """What rosbags' storage back ends raise on a corrupt or truncated file."""
    import sqlite3
    import struct

    from rosbags.rosbag1 import ReaderError as Reader1Error
    from rosbags.rosbag2 import ReaderError as Reader2Error

    return (Reader1Error, Reader2Error, sqlite3.DatabaseError, struct.error, EOFError,
            UnicodeDecodeError, IsADirectoryError, ValueError, KeyError, IndexError)


def read_truth_topic(path: str | Path, topic: str) -> tuple[NDArray, NDArray]:
    """``stamps`` (T,) [s] and planar ``poses`` (T, 3) of a bag's ``nav_msgs/Odometry`` or
    ``geometry_msgs/PoseStamped`` topic, as they are (not matched to any scan)."""
    from rosbags.highlevel import AnyReader, AnyReaderError
    from rosbags.typesys import Stores, get_typestore

    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"ROS bag not found: expected a file or directory at {path}")
    try:
        with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
            return _truth_stream(reader, topic, str(path))
    except LogFormatError:
        raise
    except (AnyReaderError, *_storage_errors()) as error:
        raise LogFormatError(f"{path}: not a readable ROS bag ({error!r})") from None


def _truth_stream(reader: Any, topic: str, source: str) -> tuple[NDArray, NDArray]:
    connections = [c for c in reader.connections if c.topic == topic]
    if not connections or connections[0].msgtype not in TRUTH_TYPES:
        raise LogFormatError(f"{source}: truth_topic {topic}: expected a topic of type "
                             f"{' or '.join(TRUTH_TYPES)} in the bag")
    stamps, poses = [], []
    for connection, _, raw in reader.messages(connections=connections):
        message = reader.deserialize(raw, connection.msgtype)
        pose = message.pose.pose if hasattr(message.pose, "pose") else message.pose
        stamps.append(stamp_seconds(message.header.stamp))
        poses.append((pose.position.x, pose.position.y, yaw(pose.orientation)))
    return np.array(stamps), np.array(poses, dtype=np.float64).reshape(-1, 3)


def _assemble(source: str, streams: list[ScanTopic], setup: SensorSetup,
              truth: tuple[NDArray, NDArray] | None, tolerance: float | None,
              truth_tolerance: float | None = None) -> Recording:
    kept, partners = synchronise([s.stamps for s in streams], tolerance)
    if len(kept) == 0:
        raise LogFormatError(f"{source}: no scan of {streams[0].topic} has a partner within the "
                             "sync tolerance in every other topic")
    scans = {key: np.minimum(stream.ranges[rows], stream.range_max)
             for key, stream, rows in zip(setup.keys, streams, partners, strict=True)}
    times = streams[0].stamps[kept]
    poses = None
    if truth is not None:
        matched = match_truth(times, truth[0], truth[1], truth_tolerance)
        if matched.matched == 0:
            raise LogFormatError(f"{source}: none of the truth topic's {matched.given} poses "
                                 f"lies within {matched.tolerance:.3g} s of a scan")
        poses = matched.on_scans(len(times))
    return Recording(source, setup, times, scans, tuple(s.topic for s in streams),
                     tuple(s.frame for s in streams), poses, len(streams[0].stamps) - len(kept))
