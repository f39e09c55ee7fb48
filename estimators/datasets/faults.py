"""Sensor faults for recorded logs: the faults of :mod:`lidar_env.faults` applied to a
:class:`~estimators.datasets.recording.Recording`, so any estimator can be tested against a
blinded, dropped, frozen, noisy or lost scan or a faulty clock on real data.

``with_faults(recording, [Blind(every=2)], seed=0)`` is a new recording: the same setup, the
faulted scans and stamps, the lost scans left out (their truth rows too). A CARMEN log becomes
a recording first (:func:`recording_from_log`). Same seed, same faults.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from estimators.base import LIDAR_KEYS
from estimators.datasets.carmen import CarmenLog
from estimators.datasets.real_log import forward_clock, setup_from_log
from estimators.datasets.recording import Recording
from lidar_env.core import ConfigError
from lidar_env.faults import Fault, Frame, apply_faults


def recording_from_log(log: CarmenLog, clock: str = "ipc", limit: int | None = None,
                       max_range: float | None = None) -> Recording:
    """The first ``limit`` scans of a single-Lidar CARMEN log as a :class:`Recording` on its
    ``clock`` (stamps that run back moved 1 us past their predecessor, as
    :func:`~estimators.datasets.real_log.run_on_log` feeds them); readings at or over the max
    range read ``max_range``."""
    setup = setup_from_log(log, max_range)
    scans = log.scans if limit is None else log.scans[:limit]
    if not scans:
        raise ConfigError(f"limit: expected at least one scan of {log.source}, got {limit}")
    ranges = np.minimum(np.stack([scan.ranges for scan in scans]), setup.max_range)
    times = forward_clock(log.scan_times(clock)[: len(scans)])
    return Recording(source=log.source, setup=setup, times=times,
                     scans={LIDAR_KEYS[0]: ranges}, topics=("laser",), frames=("laser",))


def with_faults(recording: Recording, faults: Sequence[Fault], seed: int = 0) -> Recording:
    """``recording`` as the faulty sensors would have delivered it (``faults`` applied in
    order to each observation, generators spawned from ``seed``).

    Returns:
        a :class:`Recording` with the same setup, topics and frames; ``times`` [s] and
        ``scans`` [m] faulted, lost observations left out (and their ``truth`` rows), and
        ``dropped`` raised by their number.
    """
    keys = recording.setup.keys
    max_ranges = {key: sensor.max_range
                  for key, sensor in zip(keys, recording.setup.sensors, strict=True)}
    frames = (Frame({key: recording.scans[key][step] for key in keys},
                    float(recording.times[step]), step) for step in range(len(recording)))
    kept = list(apply_faults(frames, faults, seed, max_ranges))
    if not kept:
        raise ConfigError(f"faults: every observation of {recording.source} was lost")
    steps = np.array([frame.step for frame in kept])
    scans = {key: np.stack([np.asarray(frame.scans[key], dtype=np.float64) for frame in kept])
             for key in keys}
    truth = None if recording.truth is None else recording.truth[steps]
    return replace(recording, times=np.array([frame.time for frame in kept]), scans=scans,
                   truth=truth, dropped=recording.dropped + len(recording) - len(kept))
