"""Ground truth that covers only some scans, matched to the scans it belongs to.

Truth rarely comes at the scan rate: a SLAM-corrected log holds keyframes only, a motion-capture
topic runs on its own clock. :func:`match_truth` pairs each truth pose with the nearest scan in
time, within a tolerance (by default half the median scan period, so a truth pose belongs to
the sweep it was taken in); truth poses with no scan that close are left out, and where several
truth poses fall to one scan the closest in time is kept. The pose is taken as it is, not
interpolated: within the tolerance the scan and the truth pose are the same instant.

:func:`read_truth_file` reads truth from a TUM file (``t x y z qx qy qz qw``,
:mod:`estimators.evaluation.tum`) or from a ``*-corrected`` CARMEN log, whose logged poses are
another SLAM system's output (pseudo ground truth, stamped on the logger clock).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lidar_env.core import ConfigError, EstimatorInputError, LogFormatError

#: File endings :func:`read_truth_file` reads as TUM; anything else is tried as a CARMEN log.
TUM_SUFFIXES: tuple[str, ...] = (".tum", ".txt")


@dataclass(frozen=True)
class TruthMatch:
    """Truth poses matched to scans.

    Attributes:
        rows: ``(M,)`` increasing indices of the scans that have a truth pose.
        poses: ``(M, 3)`` their truth poses (x [m], y [m], heading [rad]) in the truth's frame.
        offsets: ``(M,)`` truth stamp minus scan stamp [s], each within ``tolerance``.
        given: truth poses offered (matched or not).
        tolerance: the largest accepted stamp gap [s].
    """

    rows: NDArray[np.int64]
    poses: NDArray[np.float64]
    offsets: NDArray[np.float64]
    given: int
    tolerance: float

    @property
    def matched(self) -> int:
        """Scans with a truth pose."""
        return len(self.rows)

    @property
    def left_out(self) -> int:
        """Truth poses with no scan within the tolerance, or beaten to their scan by a closer
        one."""
        return self.given - self.matched

    def on_scans(self, n_scans: int) -> NDArray[np.float64]:
        """``(n_scans, 3)`` truth per scan, NaN where a scan has none."""
        full = np.full((n_scans, 3), np.nan)
        full[self.rows] = self.poses
        return full

    def describe(self) -> str:
        """One line: how many truth poses found a scan, how many were left out, and why."""
        return (f"{self.matched} of {self.given} truth poses matched to a scan within "
                f"{self.tolerance:.3g} s ({self.left_out} left out)")


def default_tolerance(scan_times: ArrayLike) -> float:
    """Half the median period [s] of ``scan_times`` (inf for a single scan)."""
    times = np.asarray(scan_times, dtype=np.float64)
    if len(times) < 2:
        return float("inf")
    return 0.5 * float(np.median(np.abs(np.diff(times))))


def match_truth(scan_times: ArrayLike, truth_times: ArrayLike, truth_poses: ArrayLike,
                tolerance: float | None = None) -> TruthMatch:
    """Pair each truth pose with the nearest scan within ``tolerance`` [s] (see the module
    docstring); ``None`` takes :func:`default_tolerance`. Neither time array needs to be
    sorted (logged stamps can glitch backwards)."""
    scans = np.asarray(scan_times, dtype=np.float64).reshape(-1)
    times = np.asarray(truth_times, dtype=np.float64).reshape(-1)
    poses = np.asarray(truth_poses, dtype=np.float64)
    if poses.ndim != 2 or poses.shape != (len(times), 3):
        raise EstimatorInputError(f"truth_poses: expected shape ({len(times)}, 3), one per "
                                  f"truth time, got {poses.shape}")
    if len(scans) == 0:
        raise EstimatorInputError("scan_times: expected at least one scan, got none")
    finite = np.isfinite(times) & np.all(np.isfinite(poses), axis=1)
    tolerance = default_tolerance(scans) if tolerance is None else float(tolerance)
    if not tolerance >= 0:
        raise ConfigError(f"tolerance: expected a time gap >= 0 [s], got {tolerance}")
    order = np.argsort(scans, kind="stable")
    ordered = scans[order]
    right = np.clip(np.searchsorted(ordered, times), 0, len(scans) - 1)
    left = np.maximum(right - 1, 0)
    nearest = np.where(np.abs(ordered[left] - times) <= np.abs(ordered[right] - times),
                       left, right)
    gaps = np.abs(ordered[nearest] - times)
    candidates = np.flatnonzero(finite & (gaps <= tolerance))
    rows = order[nearest[candidates]]
    # the closest truth pose per scan: sort by (row, gap) and keep each row's first
    ranked = np.lexsort((gaps[candidates], rows))
    first = np.ones(len(ranked), dtype=bool)
    first[1:] = rows[ranked][1:] != rows[ranked][:-1]
    chosen = candidates[ranked[first]]
    kept_rows = rows[ranked[first]]
    return TruthMatch(kept_rows.astype(np.int64), poses[chosen],
                      times[chosen] - scans[kept_rows], len(times), tolerance)


def read_truth_file(path: str | Path) -> tuple[NDArray[np.float64], NDArray[np.float64], str]:
    """``times`` (T,) [s], ``poses`` (T, 3) and the clock they are on, from a TUM file
    (:data:`TUM_SUFFIXES`; clock ``"tum"``) or a ``*-corrected`` CARMEN log (its logged poses
    on the ``"logger"`` clock)."""
    from estimators.datasets.carmen import load_log
    from estimators.evaluation.tum import read_tum

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"truth file not found: expected a TUM file or a corrected "
                                f"CARMEN log at {path}")
    if path.suffix.lower() in TUM_SUFFIXES:
        times, poses = read_tum(path)
        return times, poses, "tum"
    log = load_log(path)
    if not log.scans:
        raise LogFormatError(f"{path}: expected a TUM file (ending in "
                             f"{', '.join(TUM_SUFFIXES)}) or a CARMEN log with poses, found no "
                             "FLASER/ROBOTLASER1 lines")
    return log.scan_times("logger"), log.logged_poses(), "logger"
