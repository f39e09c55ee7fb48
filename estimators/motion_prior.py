"""How far a constant-velocity prediction of the next scan's pose can miss: the motion prior
that ``lidar_odometry`` and ``pc_fusion`` weigh against the returns. Distances [m], times [s].

Over a scan interval ``dt`` the prediction misses the car's position by about ``a dt^2`` for an
acceleration ``a``, plus ``speed * jitter`` when the clock's stamps wander (a scan stamped early
or late has moved further or less than its interval says).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

#: The prediction's position is never trusted to better than this [m] per scan (about a
#: registration's own precision at 1 cm range noise), however fast and regular the scans.
MIN_PREDICTION_SIGMA = 1e-3


def clock_jitter(intervals: ArrayLike) -> float:
    """The clock's typical jitter [s]: the median deviation of the scan ``intervals`` [s] from
    their median (robust to glitching stamps)."""
    intervals = np.asarray(intervals, dtype=np.float64)
    return float(np.median(np.abs(intervals - np.median(intervals))))


def prediction_sigma(
    dt: float, speed: float, jitter: float, acceleration: float, max_sigma: float
) -> float:
    """Position uncertainty [m] of a constant-velocity prediction over ``dt`` [s] at ``speed``
    [m/s]: ``acceleration * dt^2 + speed * jitter``, clipped to [``MIN_PREDICTION_SIGMA``,
    ``max_sigma``]."""
    return float(
        np.clip(acceleration * dt**2 + speed * jitter, MIN_PREDICTION_SIGMA, max_sigma)
    )
