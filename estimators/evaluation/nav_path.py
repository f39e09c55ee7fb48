"""An estimator's planar trajectory as a ROS ``nav_msgs/Path``, beside the TUM writer.

:func:`path_message` builds the message (one ``geometry_msgs/PoseStamped`` per pose, ``z = 0``,
the quaternion of a rotation by the heading about +z, stamps from the trajectory's times);
:func:`write_path_bag` stores it in a ROS 2 bag (sqlite3 or mcap) on one topic, latest message
last, so rviz shows it with a ``Path`` display; :func:`read_path_bag` reads it back.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lidar_env.core import ConfigError, LogFormatError
from lidar_env.core.se2 import wrap_angle

PATH_TYPE = "nav_msgs/msg/Path"
PATH_TOPIC = "/estimate/path"


def _typestore() -> Any:
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


def _checked(times: ArrayLike, poses: ArrayLike) -> tuple[NDArray, NDArray]:
    times = np.asarray(times, dtype=np.float64)
    poses = np.asarray(poses, dtype=np.float64)
    if poses.ndim != 2 or poses.shape[1] != 3 or len(poses) == 0:
        raise ConfigError(f"poses: expected shape (N >= 1, 3), got {poses.shape}")
    if times.shape != (len(poses),):
        raise ConfigError(f"times: expected shape ({len(poses)},), got {times.shape}")
    if not (np.all(np.isfinite(times)) and np.all(np.isfinite(poses))) or np.any(times < 0):
        raise ConfigError("times and poses: expected finite values and times >= 0 [s]")
    return times, poses


def _stamp(types: Any, t: float) -> Any:
    ns = int(round(t * 1e9))
    return types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)


def path_message(times: ArrayLike, poses: ArrayLike, frame: str = "map",
                 typestore: Any = None) -> Any:
    """A ``nav_msgs/Path`` of ``poses`` (N, 3) (x [m], y [m], heading [rad]) in ``frame``,
    stamped with ``times`` (N,) [s]; the path's own stamp is the last pose's."""
    times, poses = _checked(times, poses)
    types = (typestore or _typestore()).types
    header = types["std_msgs/msg/Header"]
    stamped = []
    for t, (x, y, heading) in zip(times, poses, strict=True):
        pose = types["geometry_msgs/msg/Pose"](
            position=types["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=0.0),
            orientation=types["geometry_msgs/msg/Quaternion"](
                x=0.0, y=0.0, z=float(np.sin(heading / 2)), w=float(np.cos(heading / 2))))
        stamped.append(types["geometry_msgs/msg/PoseStamped"](
            header=header(stamp=_stamp(types, t), frame_id=frame), pose=pose))
    return types[PATH_TYPE](header=header(stamp=_stamp(types, times[-1]), frame_id=frame),
                            poses=stamped)


def write_path_bag(path: str | Path, times: ArrayLike, poses: ArrayLike, frame: str = "map",
                   topic: str = PATH_TOPIC, storage: str = "sqlite3") -> Path:
    """Write the trajectory as one ``nav_msgs/Path`` message into a new ROS 2 bag at ``path``."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    plugins = {"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}
    if storage not in plugins:
        raise ConfigError(f"storage: expected one of {', '.join(plugins)}, got {storage!r}")
    path = Path(path)
    if path.exists():
        raise ConfigError(f"path: {path} exists; expected a new bag path")
    typestore = _typestore()
    message = path_message(times, poses, frame, typestore)
    with Writer(path, version=9, storage_plugin=plugins[storage]) as writer:
        connection = writer.add_connection(topic, PATH_TYPE, typestore=typestore)
        stamp = message.header.stamp
        writer.write(connection, stamp.sec * 10**9 + stamp.nanosec,
                     typestore.serialize_cdr(message, PATH_TYPE))
    return path


def read_path_bag(path: str | Path, topic: str = PATH_TOPIC) -> tuple[NDArray, NDArray]:
    """The last ``nav_msgs/Path`` on ``topic`` of a bag: ``times`` (N,) [s], ``poses`` (N, 3)."""
    from rosbags.highlevel import AnyReader

    with AnyReader([Path(path)], default_typestore=_typestore()) as reader:
        connections = [c for c in reader.connections if c.topic == topic
                       and c.msgtype == PATH_TYPE]
        if not connections:
            raise LogFormatError(f"{path}: expected a {PATH_TYPE} topic {topic}, found "
                                 f"{', '.join(c.topic for c in reader.connections) or 'none'}")
        message = None
        for connection, _, raw in reader.messages(connections=connections):
            message = reader.deserialize(raw, connection.msgtype)
    if message is None:
        raise LogFormatError(f"{path}: topic {topic} holds no {PATH_TYPE} message")
    times = np.array([p.header.stamp.sec + 1e-9 * p.header.stamp.nanosec for p in message.poses])
    q = [p.pose.orientation for p in message.poses]
    heading = np.array([2.0 * np.arctan2(o.z, o.w) for o in q])
    xy = np.array([(p.pose.position.x, p.pose.position.y) for p in message.poses])
    return times, np.column_stack([xy.reshape(-1, 2), wrap_angle(heading)])
