"""Write a Lidar drive as a ROS bag, so a simulated run opens in ROS tools (rviz, rqt_bag).

Layout of the bag (ROS 2 ``sqlite3`` or ``mcap``, or ROS 1 ``.bag``):

======================  ==========================  ==========================================
topic                   type                        content
======================  ==========================  ==========================================
``/lidar_k/scan``       ``sensor_msgs/LaserScan``   one per Lidar and step, in the sensor's
                                                    ``frame`` (``lidar_k`` unless named), with
                                                    its ``range_min`` and ``range_max``; no
                                                    return is ``+inf`` (REP 117)
``/tf_static``          ``tf2_msgs/TFMessage``      ``base_link -> frame`` mounts, once
``/tf``                 ``tf2_msgs/TFMessage``      ``map -> base_link`` true pose per step
``/ground_truth``       ``nav_msgs/Odometry``       the same true pose, frame ``map``
======================  ==========================  ==========================================

Stamps are the drive's times in integer nanoseconds. :func:`estimators.datasets.load_bag`
reads it back (``truth_topic=TRUTH_TOPIC`` for the poses).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimators.base import Sensor, SensorSetup
from lidar_env.core import ConfigError

TRUTH_TOPIC = "/ground_truth"
BASE_FRAME = "base_link"
WORLD_FRAME = "map"
#: ``storage`` values of :func:`write_bag` and the file each one writes.
STORAGES = {"sqlite3": "ROS 2 bag directory (.db3)", "mcap": "ROS 2 bag directory (.mcap)",
            "ros1": "ROS 1 .bag file"}


def scan_topic(key: str) -> str:
    """The LaserScan topic of observation key ``key`` (``lidar_1`` -> ``/lidar_1/scan``)."""
    return f"/{key}/scan"


def nanoseconds(t: float) -> int:
    """[s] -> integer [ns], the ROS clock."""
    return int(round(float(t) * 1e9))


def _time(types: Mapping[str, Any], t: float) -> Any:
    ns = nanoseconds(t)
    return types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)


def header(types: Mapping[str, Any], t: float, frame: str, seq: int, ros1: bool) -> Any:
    """A ``std_msgs/Header`` stamped ``t`` [s] in ``frame`` (ROS 1 headers carry ``seq``)."""
    fields = {"stamp": _time(types, t), "frame_id": frame}
    if ros1:
        fields["seq"] = seq
    return types["std_msgs/msg/Header"](**fields)


def _transform(types: Mapping[str, Any], header: Any, child: str, pose: ArrayLike) -> Any:
    x, y, heading = (float(v) for v in np.asarray(pose, dtype=np.float64))
    transform = types["geometry_msgs/msg/Transform"](
        translation=types["geometry_msgs/msg/Vector3"](x=x, y=y, z=0.0),
        rotation=_quaternion(types, heading))
    return types["geometry_msgs/msg/TransformStamped"](
        header=header, child_frame_id=child, transform=transform)


def _quaternion(types: Mapping[str, Any], heading: float) -> Any:
    return types["geometry_msgs/msg/Quaternion"](
        x=0.0, y=0.0, z=float(np.sin(heading / 2)), w=float(np.cos(heading / 2)))


def check_beams(sensor: Sensor) -> tuple[float, float]:
    """``(angle_min, angle_increment)`` [rad] of a sensor's beams; raise ``ConfigError`` when
    they are not evenly spaced (a LaserScan cannot express that)."""
    angles = sensor.beam_angles
    step = float(np.mean(np.diff(angles)))
    if not np.allclose(np.diff(angles), step, rtol=0, atol=1e-9):
        raise ConfigError(f"setup.sensors[{sensor.index}].beam_angles: expected evenly spaced "
                          "beams for a LaserScan")
    return float(angles[0]), step


def laser_scan(types: Mapping[str, Any], stamped: Any, ranges: NDArray, geometry: tuple,
               sensor: Sensor) -> Any:
    """A ``sensor_msgs/LaserScan`` of one scan; ``geometry`` is :func:`check_beams`' output."""
    angle_min, step = geometry
    values = np.asarray(ranges, dtype=np.float32)
    values = np.where(values >= sensor.max_range, np.float32(np.inf), values)
    return types["sensor_msgs/msg/LaserScan"](
        header=stamped, angle_min=angle_min, angle_max=angle_min + step * (len(values) - 1),
        angle_increment=step, time_increment=0.0, scan_time=0.0, range_min=sensor.range_min,
        range_max=sensor.max_range, ranges=values, intensities=np.zeros(0, dtype=np.float32))


def _odometry(types: Mapping[str, Any], header: Any, pose: NDArray) -> Any:
    covariance = np.zeros(36, dtype=np.float64)
    pose_msg = types["geometry_msgs/msg/Pose"](
        position=types["geometry_msgs/msg/Point"](x=float(pose[0]), y=float(pose[1]), z=0.0),
        orientation=_quaternion(types, float(pose[2])))
    zero = types["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
    return types["nav_msgs/msg/Odometry"](
        header=header, child_frame_id=BASE_FRAME,
        pose=types["geometry_msgs/msg/PoseWithCovariance"](pose=pose_msg, covariance=covariance),
        twist=types["geometry_msgs/msg/TwistWithCovariance"](
            twist=types["geometry_msgs/msg/Twist"](linear=zero, angular=zero),
            covariance=covariance.copy()))


class BagSink:
    """One open bag of either ROS version: typed connections and serialised writes."""

    def __init__(self, path: Path, storage: str) -> None:
        from rosbags.typesys import Stores, get_typestore

        self.ros1 = storage == "ros1"
        self.typestore = get_typestore(Stores.ROS1_NOETIC if self.ros1 else Stores.ROS2_HUMBLE)
        if self.ros1:
            from rosbags.rosbag1 import Writer as Writer1
            from rosbags.typesys import get_types_from_msg

            # Noetic's store lacks tf2_msgs; its TFMessage has the same layout as in ROS 2.
            self.typestore.register(get_types_from_msg(
                "geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
            self.writer: Any = Writer1(path)
        else:
            from rosbags.rosbag2 import StoragePlugin, Writer

            plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
            self.writer = Writer(path, version=9, storage_plugin=plugin)
        self.connections: dict[str, Any] = {}

    def __enter__(self) -> BagSink:
        self.writer.open()
        return self

    def __exit__(self, *_: object) -> None:
        self.writer.close()

    def write(self, topic: str, message: Any, t: float) -> None:
        msgtype = message.__msgtype__
        if topic not in self.connections:
            extra = {"latching": 1} if self.ros1 and topic == "/tf_static" else {}
            self.connections[topic] = self.writer.add_connection(
                topic, msgtype, typestore=self.typestore, **extra)
        serialise = self.typestore.serialize_ros1 if self.ros1 else self.typestore.serialize_cdr
        self.writer.write(self.connections[topic], nanoseconds(t), serialise(message, msgtype))


def write_bag(
    path: str | Path,
    setup: SensorSetup,
    times: ArrayLike,
    scans: Mapping[str, ArrayLike],
    truth: ArrayLike | None = None,
    storage: str = "sqlite3",
) -> Path:
    """Write a drive as a ROS bag (see the module docstring); return the path written.

    Args:
        path: the bag directory to create (ROS 2) or the ``.bag`` file (ROS 1); must not exist.
        setup: the sensors' mounts in ``base_link``, beam angles and max range (each its own).
        times: ``(N,)`` strictly increasing observation times [s] (>= 0).
        scans: ``{key: (N, n)}`` ranges [m] for every key of ``setup.keys``.
        truth: ``(N, 3)`` true base poses in ``map`` (x [m], y [m], heading [rad]), or None.
        storage: one of :data:`STORAGES`.
    """
    if storage not in STORAGES:
        raise ConfigError(f"storage: expected one of {', '.join(STORAGES)}, got {storage!r}")
    path = Path(path)
    if path.exists():
        raise ConfigError(f"path: {path} exists; expected a new bag path")
    times = np.asarray(times, dtype=np.float64)
    if times.ndim != 1 or not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0) \
            or np.any(times < 0):
        raise ConfigError("times: expected (N,) finite, >= 0, strictly increasing times [s]")
    arrays = {key: np.asarray(scans[key]) for key in setup.keys if key in scans}
    shapes = {key: (len(times), len(s.beam_angles))
              for key, s in zip(setup.keys, setup.sensors, strict=True)}
    if set(arrays) != set(setup.keys) or any(a.shape != shapes[k] for k, a in arrays.items()):
        raise ConfigError(f"scans: expected keys and shapes {shapes}, got "
                          f"{ {k: a.shape for k, a in arrays.items()} }")
    if setup.world_aligned:
        raise ConfigError("setup.world_aligned: expected scans in each sensor's own frame "
                          "(scan_frame='sensor'); a LaserScan cannot carry world-aligned scans")
    poses = None if truth is None else np.asarray(truth, dtype=np.float64)
    if poses is not None and poses.shape != (len(times), 3):
        raise ConfigError(f"truth: expected shape ({len(times)}, 3), got {poses.shape}")
    geometry = [check_beams(sensor) for sensor in setup.sensors]
    with BagSink(path, storage) as sink:
        types = sink.typestore.types
        ros1 = sink.ros1
        mounts = [_transform(types, header(types, times[0], BASE_FRAME, 0, ros1), sensor.frame,
                             sensor.mount) for sensor in setup.sensors]
        sink.write("/tf_static", types["tf2_msgs/msg/TFMessage"](transforms=mounts), times[0])
        for step, t in enumerate(times):
            for key, sensor, beams in zip(setup.keys, setup.sensors, geometry, strict=True):
                stamp = header(types, t, sensor.frame, step, ros1)
                sink.write(scan_topic(key),
                           laser_scan(types, stamp, arrays[key][step], beams, sensor), t)
            if poses is not None:
                stamp = header(types, t, WORLD_FRAME, step, ros1)
                tf = _transform(types, stamp, BASE_FRAME, poses[step])
                sink.write("/tf", types["tf2_msgs/msg/TFMessage"](transforms=[tf]), t)
                sink.write(TRUTH_TOPIC, _odometry(types, stamp, poses[step]), t)
    return path
