"""Constant-velocity motion prediction from an estimator's own increments (never odometry),
and how far past the last scan it may be trusted: the prior of the phase-correlation
estimators (:mod:`estimators.matching.rotation_pc`, :mod:`estimators.odometry.fusion`).

Times are seconds; motions are ``(x [m], y [m], heading [rad])`` in the car's frame.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]


#: A constant-velocity prediction is trusted over at most this many typical scan intervals
#: (the intervals its velocity was measured over); past that it says nothing.
PREDICTION_GAP_FACTOR = 10.0


def median(values: FloatArray) -> float:
    """``np.median`` of ``values`` (1-D, not empty, no NaN), bit for bit (the middle value, or
    the mean of the middle two), by one partition: ``np.median``'s own checks cost several
    times the work on the few hundred intervals an estimator keeps."""
    half = len(values) // 2
    if len(values) % 2:
        return float(np.partition(values, half)[half])
    middle = np.partition(values, (half - 1, half))
    return (float(middle[half - 1]) + float(middle[half])) / 2


def prediction_horizon(intervals: ArrayLike) -> float:
    """The longest gap [s] a constant-velocity prediction may extrapolate over:
    ``PREDICTION_GAP_FACTOR`` times the median of the recent scan ``intervals`` [s] (positive
    ones; none seen: 0, no prediction)."""
    intervals = np.asarray(intervals, dtype=np.float64).ravel()
    intervals = intervals[np.isfinite(intervals) & (intervals > 0)]
    typical = median(intervals) if len(intervals) else 0.0
    return PREDICTION_GAP_FACTOR * typical


def within_prediction_horizon(dt: float, intervals: ArrayLike) -> bool:
    """True when a constant-velocity prediction over ``dt`` [s] is within what the velocity
    measured over ``intervals`` [s] can tell (:func:`prediction_horizon`); False for a clock
    gap past it (the estimator then predicts no motion and uses its weak default prior)."""
    return 0.0 < dt <= prediction_horizon(intervals)


def constant_velocity(last_motion: FloatArray, last_dt: float, dt: float) -> FloatArray:
    """The motion (3,) over ``dt`` [s] at the velocity of ``last_motion`` over ``last_dt`` [s]
    (a prediction from the estimator's own increments, never from odometry)."""
    return np.asarray(last_motion, dtype=np.float64) * (dt / last_dt if last_dt > 0 else 1.0)
