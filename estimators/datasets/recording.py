"""A recording of K Lidars read from a file: the sensor setup, one clock, synchronised scans.

:class:`Recording` is what :func:`estimators.datasets.load_bag` returns and what
:func:`estimators.datasets.run_on_log` drives an estimator over, next to the single-Lidar
:class:`estimators.datasets.carmen.CarmenLog`. :func:`synchronise` pairs the scans of K
topics that each run on their own clock into one observation per scan of ``lidar_1``.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from estimators.base import SensorSetup
from lidar_env.core import ConfigError, LogFormatError


@dataclass(frozen=True)
class Recording:
    """K synchronised Lidar streams and what is known about their sensors.

    Attributes:
        source: the file it was read from.
        setup: the sensors' mounts [m, m, rad] in the base frame, beam angles [rad], max range.
        times: ``(N,)`` observation times [s] (header stamps of ``lidar_1``).
        scans: ``{key: (N, n_k) float64}`` ranges [m] in each sensor's frame, keyed by
            ``setup.keys``; the sensor's ``max_range`` marks "no return" (NaN, inf and
            out-of-range readings of the file all read ``max_range``).
        topics: the file's topic behind each key, in key order.
        frames: the sensor frame (``header.frame_id``) behind each key.
        truth: ``(N, 3)`` ground-truth base poses (x [m], y [m], heading [rad]) at ``times``
            when the file holds them, else ``None``; a row of NaN where no truth pose lies near
            the scan (truth at keyframes only); never for estimators.
        dropped: scans of ``lidar_1`` left out because another Lidar had no scan near them.
    """

    source: str
    setup: SensorSetup
    times: NDArray[np.float64]
    scans: dict[str, NDArray[np.float64]]
    topics: tuple[str, ...]
    frames: tuple[str, ...]
    truth: NDArray[np.float64] | None = None
    dropped: int = 0

    def __len__(self) -> int:
        return len(self.times)

    def observations(self, limit: int | None = None) -> Iterator[dict[str, NDArray[np.float64]]]:
        """One ``{key: ranges}`` observation per time, in time order (the first ``limit``)."""
        count = len(self) if limit is None else min(limit, len(self))
        for step in range(count):
            yield {key: scans[step] for key, scans in self.scans.items()}


def check_monotonic(stamps: NDArray[np.float64], source: str, topic: str) -> None:
    """Raise :class:`LogFormatError` unless ``stamps`` [s] strictly increase."""
    steps = np.diff(stamps)
    if np.any(steps <= 0):
        index = int(np.argmax(steps <= 0)) + 1
        raise LogFormatError(
            f"{source}, topic {topic}: header stamps must increase strictly; message {index} is "
            f"stamped {stamps[index]:.9f} s after {stamps[index - 1]:.9f} s"
        )


def synchronise(
    stamps: Sequence[NDArray[np.float64]], tolerance: float | None = None
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Pair each scan of stream 0 with the nearest-in-time scan of every other stream.

    Args:
        stamps: K strictly increasing ``(N_k,)`` stamp arrays [s].
        tolerance: largest time gap [s] accepted in a pair; ``None`` takes half the median
            period of stream 0 (a scan is paired with the one taken in the same sweep).

    Returns:
        ``kept`` (M,) indices into stream 0 that found a partner in every stream, and
        ``partners`` (K, M) the index of the partner scan in each stream (row 0 = ``kept``).
    """
    first = stamps[0]
    if tolerance is not None and (isinstance(tolerance, bool) or not isinstance(
            tolerance, (int, float, np.number)) or np.isnan(tolerance) or tolerance < 0):
        raise ConfigError(f"sync_tolerance: expected a number of seconds >= 0 or None, got "
                          f"{tolerance!r:.60}")
    if tolerance is None:
        tolerance = 0.5 * float(np.median(np.diff(first))) if len(first) > 1 else np.inf
    partners = [np.arange(len(first))]
    ok = np.ones(len(first), dtype=bool)
    for other in stamps[1:]:
        right = np.clip(np.searchsorted(other, first), 0, len(other) - 1)
        left = np.maximum(right - 1, 0)
        nearest = np.where(np.abs(other[left] - first) <= np.abs(other[right] - first), left, right)
        ok &= np.abs(other[nearest] - first) <= tolerance
        partners.append(nearest)
    kept = np.flatnonzero(ok)
    return kept, np.stack([p[kept] for p in partners]).astype(np.int64)
