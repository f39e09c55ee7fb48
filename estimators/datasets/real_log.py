"""Run any registered estimator over a recording and score it with the relations metric.

A recording is a single-Lidar CARMEN log or a K-Lidar :class:`Recording` (a ROS bag). The
pipeline owns the loop, the timing and the metric; the estimator sees only the scans
(``{"lidar_1": ranges, ..., "lidar_K": ranges}``) and the sensor geometry, never the odometry
or the logged poses.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from estimators.base import LIDAR_KEYS, Estimator, SensorSetup
from estimators.datasets.carmen import CarmenLog
from estimators.datasets.recording import Recording
from estimators.evaluation.relations import (
    RelationErrors,
    Relations,
    RelationSummary,
    relation_errors,
    relations_from_trajectory,
)
from lidar_env.core import ConfigError, LogFormatError


def setup_from_log(log: CarmenLog, max_range: float | None = None) -> SensorSetup:
    """The single-Lidar :class:`SensorSetup` of a log: the laser's mount in the robot frame
    (FLASER: ``robot_frontlaser_offset``; ROBOTLASER1: laser pose vs robot pose), its beam
    angles [rad], and ``max_range`` [m].

    ``max_range=None`` takes the sensor's stated maximum, or, for messages that state none
    (FLASER), the largest reading in the log: SICK scanners saturate at a fixed value (50 m or
    81.83 m in the Radish logs) that marks "no return".
    """
    if not log.scans:
        raise LogFormatError(f"{log.source}: expected laser scans, found none")
    first = log.scans[0]
    counts = np.array([len(scan.angles) for scan in log.scans])
    changed = np.flatnonzero(counts != len(first.angles))
    limit = int(changed[0]) if len(changed) else len(counts)  # before the first count change
    tail = len(counts) - limit
    angles = np.stack([scan.angles for scan in log.scans[:limit]])
    offsets = np.stack([scan.laser_offset for scan in log.scans[:limit]])
    bad_beams = np.append(~np.all(np.isclose(angles, first.angles), axis=1), np.ones(tail, bool))
    bad_mount = np.append(~np.all(np.isclose(offsets, first.laser_offset, atol=1e-6), axis=1),
                          np.zeros(tail, bool))
    if np.any(bad_beams | bad_mount):  # the first scan that differs, as a per-scan check would
        index = int(np.argmax(bad_beams | bad_mount))
        scan = log.scans[index]
        if bad_beams[index]:
            raise LogFormatError(
                f"{log.source}, line {scan.line_number}: beam geometry changes within the log "
                f"({len(scan.angles)} beams vs {len(first.angles)}); expected one laser setup"
            )
        raise LogFormatError(f"{log.source}, line {scan.line_number}: laser mount changes within "
                         "the log; expected one fixed mount")
    if max_range is None:
        stated = min(scan.max_range for scan in log.scans)
        max_range = stated if np.isfinite(stated) else max(s.ranges.max() for s in log.scans)
    return SensorSetup(first.laser_offset[None, :], first.angles, float(max_range))


@dataclass(frozen=True)
class LogRun:
    """An estimator's trajectory over a log: ``times`` (N,) [s], ``poses`` (N, 3) in the frame
    of the first scan, and its compute time."""

    times: NDArray[np.float64]
    poses: NDArray[np.float64]
    seconds_per_scan: float

    @property
    def scan_period(self) -> float:
        """Median time between scans [s]."""
        return float(np.median(np.diff(self.times))) if len(self.times) > 1 else float("nan")

    @property
    def realtime_factor(self) -> float:
        """How many times faster than the log's own scan rate the estimator ran."""
        return self.scan_period / self.seconds_per_scan


class BackwardClockWarning(UserWarning):
    """A log's stamps do not run forward; the estimator was fed them nudged forward."""


def forward_clock(times: Iterable[float], step: float = 1e-6) -> NDArray[np.float64]:
    """``times`` [s] made strictly increasing: each at least ``step`` after the one before
    (a stamp that jumps back, or repeats, is moved just past its predecessor; the rest are
    untouched)."""
    result = np.array(list(times), dtype=np.float64)
    for i in range(1, len(result)):
        result[i] = max(result[i], result[i - 1] + step)
    return result


def run_on_log(
    estimator: Estimator,
    log: CarmenLog | Recording,
    clock: str = "ipc",
    limit: int | None = None,
    setup: SensorSetup | None = None,
) -> LogRun:
    """Feed the first ``limit`` scans of ``log`` (all when None) to ``estimator``; the first
    scan is the origin. A CARMEN log is timestamped on ``clock`` (``"ipc"`` for Kümmerle's
    relation files, ``"logger"`` for ``*-corrected`` logs; stamps that run back, as 631 of
    Intel's logger stamps do, reach the estimator nudged forward, with a
    :class:`BackwardClockWarning`); a :class:`Recording` (K Lidars)
    on its own header stamps, with its own setup unless ``setup`` overrides it (e.g.
    self-calibrated mounts)."""
    if isinstance(log, Recording):
        return _run_on_recording(estimator, log, limit, setup)
    setup = setup_from_log(log) if setup is None else setup
    if setup.n_lidars != 1:
        raise ConfigError(f"setup: expected one Lidar for a CARMEN log, got {setup.n_lidars}")
    times = log.scan_times(clock)
    scans = log.scans if limit is None else log.scans[:limit]
    times = times[: len(scans)]
    fed = forward_clock(times)
    moved = int(np.count_nonzero(fed != times))
    if moved:  # estimators refuse a clock that runs back; the run keeps the logged stamps
        warnings.warn(f"{moved} of the log's {len(times)} {clock!r} stamps do not run forward; "
                      "the estimator gets each moved 1 us past the one before, the run "
                      "keeps the logged ones", BackwardClockWarning, stacklevel=2)
    estimator.reset(setup, np.zeros(3))
    start = time.perf_counter()
    for scan, t in zip(scans, fed, strict=True):
        estimator.update({LIDAR_KEYS[0]: scan.ranges}, float(t))
    elapsed = time.perf_counter() - start
    return LogRun(times, estimator.trajectory, elapsed / max(len(scans), 1))


def _run_on_recording(estimator: Estimator, recording: Recording, limit: int | None,
                      setup: SensorSetup | None) -> LogRun:
    setup = recording.setup if setup is None else setup
    if setup.n_lidars != recording.setup.n_lidars:
        raise ConfigError(f"setup: expected {recording.setup.n_lidars} Lidars for "
                         f"{recording.source}, got {setup.n_lidars}")
    count = len(recording) if limit is None else min(limit, len(recording))
    times = recording.times[:count]
    estimator.reset(setup, np.zeros(3))
    start = time.perf_counter()
    for observation, t in zip(recording.observations(count), times, strict=True):
        estimator.update(observation, float(t))
    elapsed = time.perf_counter() - start
    return LogRun(times, estimator.trajectory, elapsed / max(count, 1))


def score_relations(
    run: LogRun, relations: Relations, tolerance: float = 1e-3
) -> dict[str, RelationSummary]:
    """``{"local": ..., "all": ...}`` relation summaries of ``run`` over the relations that
    lie within its time span (local = shorter than 2 s)."""
    start, end = run.times[0] - tolerance, run.times[-1] + tolerance
    ends = np.stack([relations.t1, relations.t2])
    inside = np.all((ends >= start) & (ends <= end), axis=0)
    selected = relations.select(inside)
    errors = relation_errors(run.times, run.poses, selected, tolerance)
    local = np.abs(errors.dt) < 2.0
    return {
        "local": _subset(errors, local).summary(),
        "all": errors.summary(),
    }


def _subset(errors: RelationErrors, mask: NDArray[np.bool_]) -> RelationErrors:
    return RelationErrors(errors.translation[mask], errors.rotation[mask], errors.dt[mask])


def pseudo_truth_relations(
    reference: CarmenLog, windows: tuple[float | None, ...] = (None, 1.0, 5.0)
) -> dict[str, Relations]:
    """Relations from a ``*-corrected`` log's SLAM poses (pseudo ground truth, logger clock):
    ``"consecutive"`` keyframes and one entry per window [s], e.g. ``"1 s"``."""
    times = reference.scan_times("logger")
    # intel-corrected.log.gz lists a few keyframes out of time order; the poses are what count.
    order = np.argsort(times, kind="stable")
    times, poses = times[order], reference.logged_poses()[order]
    return {
        ("consecutive" if w is None else f"{w:g} s"): relations_from_trajectory(times, poses, w)
        for w in windows
    }
