"""The points the ``icp`` estimator matches the next scan against: each beam's latest return
over the last few scans, moved into the newest scan's car frame.

Matched on the previous scan alone, a scan whose beams are lost at random (a dirty window, a
flaky receiver, dark or glancing surfaces) pairs its points with lines fitted through
neighbours that are as sparse as its own: with half the beams lost, successive scans share a
quarter of their beams, a far wall's few returns give noisy lines or none, and the heading
turns by milliradians of noise at every step, a random walk that adds up to metres over a few
hundred scans. A beam without a return (lost, or turned into the open as the car moved) keeps
the return it last had, moved by the matched increments, for up to ``max_age`` scans: the
reference stays nearly as dense as a full scan (with half the beams lost at random, all but 1
in 2^8 of them return within 8 scans) and it is a point of the same static world, seen from a
pose a few centimetres away. A beam that returns replaces its held point, so the reference
holds at most one point per beam, and a full scan is its own reference.

Beams are counted over the setup's Lidars in their order, each in beam order (the order of
:class:`~estimators.matching.scan_matching.CarPoints`' points). Points (N, 2) [m] are in the
car frame of the latest scan.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from numpy.typing import NDArray

from estimators.matching.scan_matching import CarPoints
from lidar_env.core import ConfigError, EstimatorInputError
from lidar_env.core.se2 import inverse, transform_points

#: [scans] how long a beam without a return keeps its last one: with half the beams
#: lost at random on every scan, all but 1 in 2^8 of them return within that many scans.
MAX_AGE = 8


def check_max_age(max_age: int) -> int:
    """``max_age``, a whole number of scans >= 0, as an ``int``; else a ConfigError."""
    if isinstance(max_age, bool) or not isinstance(max_age, (int, np.integer)) or max_age < 0:
        raise ConfigError(f"held scans: expected a whole number of scans >= 0, got {max_age!r}")
    return int(max_age)


class HeldReturns:
    """Each beam's latest return of the last ``max_age`` scans (``0``: the latest
    scan's returns alone) of the Lidars ``car_points`` reads (its beams and returns)."""

    def __init__(self, car_points: CarPoints, max_age: int = MAX_AGE) -> None:
        self.max_age = check_max_age(max_age)
        self._car_points = car_points
        self._points = np.zeros((car_points.beams, 2))
        self._age = np.full(car_points.beams, np.inf)  # [scans] since each beam's held return

    def _returns(self, scans: Mapping[str, NDArray[np.float64]],
                 points: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Which beams (B,) of ``scans`` returned, checked against their ``points`` (M, 2)."""
        hit = self._car_points.returned(scans)
        if np.count_nonzero(hit) != len(points):
            raise EstimatorInputError(
                f"points: expected one per return ({np.count_nonzero(hit)} of {len(hit)} "
                f"beams), got {len(points)}")
        return hit

    def start(self, scans: Mapping[str, NDArray[np.float64]],
              points: NDArray[np.float64]) -> NDArray[np.float64]:
        """Forget every held return and take ``points`` (M, 2) [m], the returns of ``scans``
        (ranges [m] by Lidar key) in the car frame; return them."""
        hit = self._returns(scans, points)
        self._points[hit] = points
        self._age = np.where(hit, 0.0, np.inf)
        return np.array(points, dtype=np.float64)

    def advance(self, scans: Mapping[str, NDArray[np.float64]], points: NDArray[np.float64],
                increment: NDArray[np.float64], scans_since: float = 1.0) -> NDArray[np.float64]:
        """Take the next scans' returns ``points`` (M, 2) [m] (car frame) after the car moved
        by ``increment`` (3,) (the new car frame's pose in the last one's) over ``scans_since``
        scans (the skipped ones counted); return the reference (N, 2) [m], N >= M, in the new
        car frame: the returns, and the held returns of the beams without one, in beam order."""
        hit = self._returns(scans, points)
        self._age += scans_since
        held = ~hit & (self._age <= self.max_age)
        self._points[held] = transform_points(inverse(increment), self._points[held])
        self._points[hit] = points
        self._age[hit] = 0.0
        return self._points[hit | held]
