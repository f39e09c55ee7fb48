"""Kümmerle et al.'s relations metric for SLAM and odometry accuracy.

R. Kümmerle, B. Steder, C. Dornhege, M. Ruhnke, G. Grisetti, C. Stachniss, A. Kleiner,
"On measuring the accuracy of SLAM algorithms", Autonomous Robots 27(4), 2009.

A relation ``(t1, t2, delta*)`` states the true pose at ``t2`` in the frame of the pose at
``t1``. The error of an estimate is the relative pose between the estimated
``delta = x(t1)^-1 (+) x(t2)`` and ``delta*``; we report its translational norm [m] and
its absolute rotation [deg] separately, averaged over relations (their eq. 2 with the two
parts kept apart, as their published tables do).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lidar_env.core import ConfigError, EstimatorInputError, LogFormatError
from lidar_env.core.se2 import relative

#: Relations shorter than this [s] are "local" (scan-matching accuracy, no drift).
LOCAL_RELATION_MAX_DT: float = 2.0
#: A relation whose translational error exceeds this [m] counts as a failure.
FAILURE_THRESHOLD: float = 0.2


@dataclass(frozen=True)
class Relations:
    """``t1``, ``t2``: ``(N,)`` [s]; ``poses``: ``(N, 3)`` pose at t2 in the frame at t1."""

    t1: NDArray[np.float64]
    t2: NDArray[np.float64]
    poses: NDArray[np.float64]

    def __len__(self) -> int:
        return len(self.t1)

    def select(self, mask: NDArray[np.bool_]) -> Relations:
        """The relations where ``mask`` is true."""
        return Relations(self.t1[mask], self.t2[mask], self.poses[mask])

    def local(self, max_dt: float = LOCAL_RELATION_MAX_DT) -> Relations:
        """Relations spanning less than ``max_dt`` [s]."""
        return self.select(np.abs(self.t2 - self.t1) < max_dt)


def load_relations(path: str | Path) -> Relations:
    """Read a relations file: one ``t1 t2 x y z roll pitch yaw`` per line (metres, radians)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"relations file not found: expected a file at {path}")
    rows = []
    with open(path, encoding="ascii") as text:
        for number, line in enumerate(text, start=1):
            fields = line.split()
            if not fields or fields[0].startswith("#"):
                continue
            if len(fields) != 8:
                raise LogFormatError(
                    f"{path}, line {number}: expected 8 fields (t1 t2 x y z roll pitch yaw), "
                    f"got {len(fields)}"
                )
            try:
                rows.append([float(v) for v in fields])
            except ValueError:
                raise LogFormatError(
                    f"{path}, line {number}: expected numbers, got {line!r}") from None
    table = np.array(rows, dtype=np.float64).reshape(-1, 8)
    return Relations(table[:, 0], table[:, 1], table[:, [2, 3, 7]])


def relations_from_trajectory(
    times: ArrayLike, poses: ArrayLike, window: float | None = None
) -> Relations:
    """Relations between reference poses (e.g. a SLAM-corrected log as pseudo ground truth).

    ``window=None`` pairs consecutive poses; otherwise each pose is paired with the first
    later pose at least ``window`` [s] after it.
    """
    times = np.asarray(times, dtype=np.float64)
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    if len(times) != len(poses):
        raise EstimatorInputError(
            f"times and poses: expected equal lengths, got {len(times)}, {len(poses)}")
    if np.any(np.diff(times) <= 0):
        raise EstimatorInputError("times: expected strictly increasing timestamps")
    if window is None:
        first, second = np.arange(len(times) - 1), np.arange(1, len(times))
    else:
        if window <= 0:
            raise ConfigError(f"window: expected a positive duration [s], got {window}")
        second = np.searchsorted(times, times + window, side="left")
        first = np.flatnonzero(second < len(times))
        second = second[first]
    return Relations(times[first], times[second], relative(poses[first], poses[second]))


def match_times(
    times: ArrayLike, queries: ArrayLike, tolerance: float = 1e-3
) -> NDArray[np.intp]:
    """Index into ``times`` of the sample nearest each query time, within ``tolerance`` [s];
    error if any query has no sample that close. ``times`` need not be sorted (logged
    timestamps can glitch backwards)."""
    times = np.asarray(times, dtype=np.float64)
    queries = np.asarray(queries, dtype=np.float64)
    if len(times) == 0:
        raise EstimatorInputError("times: expected at least one timestamp, got none")
    order = np.argsort(times, kind="stable")
    ordered = times[order]
    right = np.clip(np.searchsorted(ordered, queries), 0, len(times) - 1)
    left = np.maximum(right - 1, 0)
    nearest = np.where(
        np.abs(ordered[left] - queries) <= np.abs(ordered[right] - queries), left, right
    )
    gap = np.abs(ordered[nearest] - queries)
    missing = np.flatnonzero(gap > tolerance)
    if len(missing):
        q = queries[missing[0]]
        raise EstimatorInputError(
            f"{len(missing)} relation time(s) have no scan within {tolerance} s, e.g. t={q:.6f} "
            f"(nearest scan at {ordered[nearest[missing[0]]]:.6f}); expected every relation "
            "time to be a scan time"
        )
    return order[nearest]


@dataclass(frozen=True)
class RelationErrors:
    """Per-relation errors: ``translation`` [m] and ``rotation`` [deg], both ``(N,)`` >= 0."""

    translation: NDArray[np.float64]
    rotation: NDArray[np.float64]
    dt: NDArray[np.float64]

    def summary(self) -> RelationSummary:
        """Means, standard deviations and failure rate."""
        if len(self.translation) == 0:
            raise EstimatorInputError("no relations to summarise")
        return RelationSummary(
            count=len(self.translation),
            translation_mean=float(np.mean(self.translation)),
            translation_std=float(np.std(self.translation)),
            rotation_mean=float(np.mean(self.rotation)),
            rotation_std=float(np.std(self.rotation)),
            failure_rate=float(np.mean(self.translation > FAILURE_THRESHOLD)),
        )


@dataclass(frozen=True)
class RelationSummary:
    """Mean ± std of translational [m] and rotational [deg] error; failures = share > 0.2 m."""

    count: int
    translation_mean: float
    translation_std: float
    rotation_mean: float
    rotation_std: float
    failure_rate: float

    def __str__(self) -> str:
        return (
            f"{self.translation_mean:.4f} ± {self.translation_std:.4f} m, "
            f"{self.rotation_mean:.3f} ± {self.rotation_std:.3f} deg, "
            f"failures {100 * self.failure_rate:.1f}% (n={self.count})"
        )


def relation_errors(
    times: ArrayLike, poses: ArrayLike, relations: Relations, tolerance: float = 1e-3
) -> RelationErrors:
    """Errors of an estimated trajectory (``times`` (N,) [s], ``poses`` (N, 3)) on ``relations``.

    Each relation time must match a trajectory time within ``tolerance`` [s].
    """
    times = np.asarray(times, dtype=np.float64)
    poses = np.asarray(poses, dtype=np.float64)
    if poses.ndim != 2 or poses.shape[1] != 3 or len(poses) != len(times):
        raise EstimatorInputError(
            f"poses: expected shape ({len(times)}, 3) to match times, got {poses.shape}"
        )
    i = match_times(times, relations.t1, tolerance)
    j = match_times(times, relations.t2, tolerance)
    estimated = relative(poses[i], poses[j])
    error = relative(relations.poses, estimated)
    return RelationErrors(
        translation=np.hypot(error[:, 0], error[:, 1]),
        rotation=np.degrees(np.abs(error[:, 2])),
        dt=relations.t2 - relations.t1,
    )
