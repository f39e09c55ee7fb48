"""Read CARMEN log files (Radish format): laser scans, odometry and parameters.

Supported messages (one per line, fields separated by white space)::

    FLASER n r_1 .. r_n x y theta odom_x odom_y odom_theta ipc_timestamp hostname logger_timestamp
    RLASER  (as FLASER: the rear laser)
    ROBOTLASER1 laser_type start_angle fov angular_res max_range accuracy remission_mode
        n r_1 .. r_n n_remissions e_1 .. e_m laser_x laser_y laser_theta robot_x robot_y
        robot_theta tv rv forward_safety side_safety turn_axis ipc_timestamp hostname logger_ts
    ODOM x y theta tv rv accel ipc_timestamp hostname logger_timestamp
    ROBOTLASER2  (as ROBOTLASER1: the rear laser)
    PARAM name value [hostname logger_timestamp]

Lines starting with ``#`` and blank lines are comments. Any other message type (``NEFF``,
``SYNC``, ``TRUEPOS``, ...) is not parsed but *counted* in
:attr:`CarmenLog.unknown_messages`, so nothing is dropped silently. A truncated or
malformed line of a supported type (a beam count below 2, a negative range, a non-finite
number, ``PARAM robot_frontlaser_offset`` that is not a finite number) and corrupt or
truncated ``.gz``/``.bz2`` data raise :class:`CarmenFormatError` (a
:class:`~lidar_env.core.errors.LogFormatError`) naming the file and line.

Beam geometry of ``FLASER`` (which carries none): CARMEN's front laser covers a 180 degree
field of view starting at -90 degrees, ``n`` beams at ``180 / n`` degrees apart when ``n``
is even (180 beams: -90 .. +89 at 1 degree) and ``180 / (n - 1)`` degrees when ``n`` is odd
(181 beams: -90 .. +90 inclusive, the SICK interlaced convention). The laser sits at
``PARAM robot_frontlaser_offset`` [m] ahead of the robot centre (0 when absent).
``ROBOTLASER1`` states its own start angle and resolution, and its laser pose relative to
the robot pose gives the mount. The rear laser (``RLASER``, ``ROBOTLASER2``) is kept apart, in
:attr:`CarmenLog.rear_scans`; an ``RLASER`` has FLASER's beam geometry and sits at
(``robot_rearlaser_offset``, ``robot_rearlaser_side_offset``, ``robot_rearlaser_angular_offset``)
[m, m, rad], facing backwards (pi) when the angular offset is absent, as CARMEN and GMapping
read it. :func:`estimators.datasets.carmen_pairs.carmen_recording` makes a two-Lidar recording
of the two lasers (or of two logs).

Odometry is kept in the log for completeness; the project's estimators never read it.
"""

from __future__ import annotations

import bz2
import gzip
import io
import zlib
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from lidar_env.core import ConfigError, LogFormatError
from lidar_env.core.se2 import relative

#: Messages this module parses; any other message name is counted, not parsed.
PARSED_MESSAGES: tuple[str, ...] = ("FLASER", "RLASER", "ROBOTLASER1", "ROBOTLASER2", "ODOM",
                                    "PARAM")


#: ``PARAM`` values that must be numbers (checked on their own line, not where they are used).
NUMERIC_PARAMS: tuple[str, ...] = ("robot_frontlaser_offset", "robot_rearlaser_offset",
                                   "robot_rearlaser_side_offset",
                                   "robot_rearlaser_angular_offset")


class CarmenFormatError(LogFormatError):
    """A line of a CARMEN log that does not follow its message's documented layout."""

    def __init__(self, source: str, line_number: int, reason: str) -> None:
        super().__init__(f"{source}, line {line_number}: {reason}")
        self.source = source
        self.line_number = line_number


@dataclass(frozen=True)
class LaserScan:
    """One planar laser scan.

    Attributes:
        ranges: ``(n,)`` [m], beam ``i`` along ``angles[i]``.
        angles: ``(n,)`` [rad] beam directions in the laser frame, CCW from its forward axis.
        max_range: [m] the sensor's nominal maximum (``inf`` when the message states none).
        laser_offset: ``(3,)`` pose of the laser in the robot frame (x [m], y [m], heading [rad]).
        logged_pose: ``(3,)`` robot pose logged with the scan (odometry or corrected; never for
            estimators).
        timestamp: [s] IPC timestamp of the message (the clock of Kümmerle's relation files).
        logger_timestamp: [s] logger clock (seconds since the logger started).
        message: ``"FLASER"``, ``"RLASER"``, ``"ROBOTLASER1"`` or ``"ROBOTLASER2"``.
        line_number: 1-based line in the file.
    """

    ranges: NDArray[np.float64]
    angles: NDArray[np.float64]
    max_range: float
    laser_offset: NDArray[np.float64]
    logged_pose: NDArray[np.float64]
    timestamp: float
    logger_timestamp: float
    message: str
    line_number: int


@dataclass(frozen=True)
class Odometry:
    """One ``ODOM`` record: pose (x [m], y [m], theta [rad]), velocities [m/s], [rad/s]."""

    pose: NDArray[np.float64]
    translational_velocity: float
    rotational_velocity: float
    acceleration: float
    timestamp: float
    logger_timestamp: float
    line_number: int


@dataclass
class CarmenLog:
    """Everything read from one log, in file order."""

    source: str
    scans: list[LaserScan] = field(default_factory=list)
    #: the rear laser's scans (``RLASER``, ``ROBOTLASER2``), apart from the front laser's
    rear_scans: list[LaserScan] = field(default_factory=list)
    odometry: list[Odometry] = field(default_factory=list)
    params: dict[str, str] = field(default_factory=dict)
    #: message name -> number of lines of that type that were not parsed
    unknown_messages: Counter[str] = field(default_factory=Counter)

    def scan_times(self, clock: str = "ipc") -> NDArray[np.float64]:
        """``(N,)`` scan timestamps [s] on the ``"ipc"`` or ``"logger"`` clock."""
        if clock == "ipc":
            return np.array([s.timestamp for s in self.scans], dtype=np.float64)
        if clock == "logger":
            return np.array([s.logger_timestamp for s in self.scans], dtype=np.float64)
        raise ConfigError(f"unknown clock {clock!r}: expected one of ipc, logger")

    def logged_poses(self) -> NDArray[np.float64]:
        """``(N, 3)`` robot poses logged with the scans (odometry, or SLAM output in a
        ``*-corrected`` log)."""
        return np.array([s.logged_pose for s in self.scans], dtype=np.float64).reshape(-1, 3)


def open_text(path: str | Path) -> io.TextIOBase:
    """Open a plain, gzip or bzip2 file as text, recognised by its magic bytes (not its name)."""
    path = Path(path)
    with open(path, "rb") as raw:
        magic = raw.read(3)
    if magic[:2] == b"\x1f\x8b":
        return gzip.open(path, "rt", encoding="ascii", errors="replace")
    if magic == b"BZh":
        return bz2.open(path, "rt", encoding="ascii", errors="replace")
    return open(path, encoding="ascii", errors="replace")


def flaser_beam_angles(n_beams: int) -> NDArray[np.float64]:
    """Beam directions [rad] of an ``n``-beam ``FLASER`` scan (see the module docstring)."""
    if n_beams < 2:
        raise LogFormatError(f"n_beams: expected at least 2 beams, got {n_beams}")
    step = np.pi / (n_beams - 1 if n_beams % 2 else n_beams)
    return -np.pi / 2 + step * np.arange(n_beams)


def _floats(tokens: list[str], what: str, source: str, line_number: int) -> NDArray[np.float64]:
    try:
        values = np.array(tokens, dtype=np.float64)
    except ValueError:
        raise CarmenFormatError(
            source, line_number, f"{what}: expected numbers, got {' '.join(tokens[:12])!r}"
        ) from None
    if not np.all(np.isfinite(values)):
        raise CarmenFormatError(source, line_number, f"{what}: expected finite numbers")
    return values


def _count(token: str, what: str, source: str, line_number: int) -> int:
    if not token.isdigit():
        raise CarmenFormatError(
            source, line_number, f"{what}: expected a non-negative integer, got {token!r}"
        )
    return int(token)


def _beam_count(token: str, what: str, source: str, line_number: int) -> int:
    n = _count(token, what, source, line_number)
    if n < 2:
        raise CarmenFormatError(source, line_number, f"{what}: expected at least 2 beams, got {n}")
    return n


def _ranges(tokens: list[str], what: str, source: str, line_number: int) -> NDArray[np.float64]:
    ranges = _floats(tokens, what, source, line_number)
    negative = np.flatnonzero(ranges < 0)
    if len(negative):
        raise CarmenFormatError(
            source, line_number, f"{what}: expected ranges >= 0 [m], got "
            f"{float(ranges[negative[0]])!r} at beam {int(negative[0])}"
        )
    return ranges


def _check_length(fields: list[str], expected: int, message: str, source: str, number: int) -> None:
    if len(fields) != expected:
        raise CarmenFormatError(
            source,
            number,
            f"{message}: expected {expected} fields for its stated beam count, got {len(fields)}"
            " (truncated or malformed line)",
        )


def _parse_flaser(
    fields: list[str], mount: NDArray[np.float64], source: str, number: int
) -> LaserScan:
    """An ``FLASER`` or ``RLASER`` line; ``mount`` is the laser's pose on the robot."""
    name = fields[0]
    if len(fields) < 2:
        raise CarmenFormatError(source, number, f"{name}: missing the beam count")
    n = _beam_count(fields[1], f"{name} beam count", source, number)
    _check_length(fields, 2 + n + 6 + 3, name, source, number)
    ranges = _ranges(fields[2 : 2 + n], f"{name} ranges", source, number)
    tail = _floats(fields[2 + n : 2 + n + 7] + fields[-1:], f"{name} poses/time", source, number)
    return LaserScan(
        ranges=ranges,
        angles=flaser_beam_angles(n),
        max_range=np.inf,
        laser_offset=mount,
        logged_pose=tail[0:3],
        timestamp=float(tail[6]),
        logger_timestamp=float(tail[7]),
        message=name,
        line_number=number,
    )


def _parse_robotlaser(fields: list[str], source: str, number: int) -> LaserScan:
    """A ``ROBOTLASER1`` or ``ROBOTLASER2`` line."""
    name = fields[0]
    if len(fields) < 9:
        raise CarmenFormatError(source, number, f"{name}: truncated header")
    header = _floats(fields[1:8], f"{name} header", source, number)
    n = _beam_count(fields[8], f"{name} beam count", source, number)
    if len(fields) < 10 + n:
        raise CarmenFormatError(source, number, f"{name}: truncated before the remissions")
    n_remissions = _count(fields[9 + n], f"{name} remission count", source, number)
    _check_length(fields, 10 + n + n_remissions + 11 + 3, name, source, number)
    ranges = _ranges(fields[9 : 9 + n], f"{name} ranges", source, number)
    rest = 10 + n + n_remissions
    tail = _floats(fields[rest : rest + 12] + fields[-1:], f"{name} tail", source, number)
    _, start_angle, _, resolution, max_range = header[:5]
    laser_pose, robot_pose = tail[0:3], tail[3:6]
    return LaserScan(
        ranges=ranges,
        angles=start_angle + resolution * np.arange(n),
        max_range=float(max_range) if max_range > 0 else np.inf,
        laser_offset=relative(robot_pose, laser_pose),
        logged_pose=robot_pose,
        timestamp=float(tail[11]),
        logger_timestamp=float(tail[12]),
        message=name,
        line_number=number,
    )


def _parse_odom(fields: list[str], source: str, number: int) -> Odometry:
    _check_length(fields, 1 + 6 + 3, "ODOM", source, number)
    values = _floats(fields[1:8] + fields[-1:], "ODOM", source, number)
    return Odometry(
        pose=values[0:3],
        translational_velocity=float(values[3]),
        rotational_velocity=float(values[4]),
        acceleration=float(values[5]),
        timestamp=float(values[6]),
        logger_timestamp=float(values[7]),
        line_number=number,
    )


def iter_lines(path: str | Path) -> Iterator[tuple[int, list[str]]]:
    """``(line_number, fields)`` of every non-comment, non-blank line.

    Raises:
        CarmenFormatError: the compressed data is corrupt or truncated (naming the line it
            broke off after).
    """
    number = 0
    try:
        with open_text(path) as text:
            for number, line in enumerate(text, start=1):
                fields = line.split()
                if fields and not fields[0].startswith("#"):
                    yield number, fields
    except (OSError, EOFError, zlib.error) as error:  # gzip.BadGzipFile is an OSError
        raise CarmenFormatError(
            str(path), number + 1,
            f"corrupt or truncated compressed data ({type(error).__name__}: {error})",
        ) from error


def _front_mount(params: dict[str, str]) -> NDArray[np.float64]:
    return np.array([float(params.get("robot_frontlaser_offset", "0")), 0.0, 0.0])


def _rear_mount(params: dict[str, str]) -> NDArray[np.float64]:
    return np.array([float(params.get("robot_rearlaser_offset", "0")),
                     float(params.get("robot_rearlaser_side_offset", "0")),
                     float(params.get("robot_rearlaser_angular_offset", repr(np.pi)))])


def load_log(path: str | Path) -> CarmenLog:
    """Read a whole CARMEN log (plain, ``.gz`` or ``.bz2``); see the module docstring."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"CARMEN log not found: expected a file at {path}")
    log = CarmenLog(source=str(path))
    for number, fields in iter_lines(path):
        name = fields[0]
        if name == "FLASER":
            log.scans.append(_parse_flaser(fields, _front_mount(log.params), log.source, number))
        elif name == "RLASER":
            log.rear_scans.append(_parse_flaser(fields, _rear_mount(log.params), log.source,
                                                number))
        elif name == "ROBOTLASER1":
            log.scans.append(_parse_robotlaser(fields, log.source, number))
        elif name == "ROBOTLASER2":
            log.rear_scans.append(_parse_robotlaser(fields, log.source, number))
        elif name == "ODOM":
            log.odometry.append(_parse_odom(fields, log.source, number))
        elif name == "PARAM":
            if len(fields) < 3:
                raise CarmenFormatError(log.source, number, "PARAM: expected a name and a value")
            if fields[1] in NUMERIC_PARAMS:
                _floats(fields[2:3], f"PARAM {fields[1]}", log.source, number)
            log.params[fields[1]] = fields[2]
        else:
            log.unknown_messages[name] += 1
    return log
