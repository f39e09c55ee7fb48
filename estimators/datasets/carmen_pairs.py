"""Two Lidars from CARMEN logs: the front and rear laser of one log, or the lasers of two logs
recorded side by side, as one two-Lidar :class:`~estimators.datasets.recording.Recording`.

Either way each laser keeps its own beam geometry, range and mount (from the log's parameters
or its ``ROBOTLASER`` poses: what the log *claims*, which the extrinsic calibration,
``python -m estimators.calibration --carmen``, can check), and each scan of Lidar 1 is paired
with the nearest-in-time scan of Lidar 2 on the chosen clock
(:func:`estimators.datasets.recording.synchronise`); scans with no partner within half a scan
period are dropped and counted. The logged poses and odometry are never part of it.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from estimators.base import Sensor, SensorSetup
from estimators.datasets.carmen import CarmenLog, LaserScan, load_log
from estimators.datasets.real_log import setup_from_log
from estimators.datasets.recording import Recording, check_monotonic, synchronise
from lidar_env.core import LogFormatError


def _stream(log: CarmenLog, scans: list[LaserScan], what: str, clock: str, index: int
            ) -> tuple[np.ndarray, np.ndarray, Sensor]:
    """Stamps [s], ``(N, n)`` ranges [m] and the :class:`Sensor` of one laser's scans."""
    part = CarmenLog(log.source, scans=scans)
    sensor = setup_from_log(part).sensors[0]
    stamps = part.scan_times(clock)
    check_monotonic(stamps, log.source, what)
    ranges = np.minimum(np.stack([scan.ranges for scan in scans]), sensor.max_range)
    return stamps, ranges, Sensor(sensor.mount, sensor.beam_angles, sensor.max_range, index)


def carmen_recording(paths: Sequence[str | Path], clock: str = "ipc",
                     sync_tolerance: float | None = None) -> Recording:
    """The two-Lidar recording of one CARMEN log's front and rear lasers (one path), or of the
    front lasers of two logs (two paths; the first is Lidar 1).

    Args:
        paths: one or two CARMEN logs (plain, ``.gz``, ``.bz2``).
        clock: ``"ipc"`` or ``"logger"``: the stamps the scans are paired and timed on.
        sync_tolerance: largest time gap [s] in a pair, >= 0 (NaN is a ``ConfigError``);
            ``None``: half Lidar 1's median period.

    Raises:
        LogFormatError: a log without the laser it is read for, stamps that do not increase, or
            no pair of scans within the tolerance.
    """
    if not 1 <= len(paths) <= 2:
        raise LogFormatError(f"paths: expected one CARMEN log (front and rear laser) or two "
                             f"(one laser each), got {len(paths)}")
    logs = [load_log(path) for path in paths]
    if len(logs) == 1:
        log = logs[0]
        if not log.rear_scans:
            raise LogFormatError(f"{log.source}: expected RLASER or ROBOTLASER2 lines for a "
                                 "second Lidar (or give a second log)")
        parts = [(log, log.scans, "front laser"), (log, log.rear_scans, "rear laser")]
    else:
        parts = [(log, log.scans, "front laser") for log in logs]
    for log, scans, what in parts:
        if not scans:
            raise LogFormatError(f"{log.source}: expected {what} scans (FLASER/ROBOTLASER1), "
                                 "found none")
    streams = [_stream(log, scans, what, clock, index)
               for index, (log, scans, what) in enumerate(parts)]
    kept, partners = synchronise([stream[0] for stream in streams], sync_tolerance)
    source = " + ".join(dict.fromkeys(log.source for log, _, _ in parts))
    if len(kept) == 0:
        raise LogFormatError(f"{source}: no scan of Lidar 1 has a Lidar 2 scan within the sync "
                             "tolerance")
    setup = SensorSetup(sensors=tuple(stream[2] for stream in streams))
    scans = {key: stream[1][rows]
             for key, stream, rows in zip(setup.keys, streams, partners, strict=True)}
    names = tuple(f"{Path(log.source).name}:{what}" for log, _, what in parts)
    return Recording(source, setup, streams[0][0][kept], scans, names, names, None,
                     len(streams[0][0]) - len(kept))
