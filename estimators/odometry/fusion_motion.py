"""The motion model of ``pc_fusion`` (:class:`~estimators.odometry.fusion.FusionEstimator`):
the car's velocity [m/s, m/s, rad/s] (car frame) as the mean of its own steps over a window of
time, and the information of the prediction it makes (:class:`FusedVelocity`, a mixin).
"""

from __future__ import annotations

from collections import deque

import numpy as np
from numpy.typing import NDArray

from estimators.matching.curve_refinement import PRIOR_INFORMATION
from estimators.odometry.motion_prior import ScanClock, prediction_information

FloatArray = NDArray[np.float64]

#: Scan intervals the clock's typical jitter is taken over (20 s at 10 Hz).
CLOCK_HISTORY = 200


class FusedVelocity:
    """The velocity and prediction of :class:`~estimators.odometry.fusion.FusionEstimator`, a
    mixin: it reads ``velocity_window`` [s] and keeps ``_velocity``, the ``_recent`` steps
    and the ``_clock``."""

    velocity_window: float
    _velocity: FloatArray
    _recent: deque[tuple[list[float], float]]
    _clock: ScanClock

    def _prediction_information(self, dt: float, predicted: bool = True) -> FloatArray:
        """The prediction's information over ``dt`` [s]
        (:func:`estimators.odometry.motion_prior.prediction_information`), with the clock's
        jitter the median deviation of the last ``CLOCK_HISTORY`` intervals from their median;
        the weak default prior when nothing was ``predicted`` (a clock gap)."""
        if dt > 0:
            self._clock.add(dt)
        if not predicted or not dt > 0 or not self._clock.settled:
            # Until a few intervals are seen, neither the clock nor the velocity is known (and
            # a clock that does not run forward predicts nothing).
            return PRIOR_INFORMATION
        speed = float(np.hypot(self._velocity[0], self._velocity[1]))
        return prediction_information(dt, speed, self._clock.jitter)


    def _update_velocity(self, motion: list[float], dt: float) -> None:
        """Keep the car's velocity [m/s, m/s, rad/s] (car frame) as the mean of the steps of
        the last ``velocity_window`` [s].

        The prediction it makes decides what the scans leave open (a featureless corridor's
        axis): from one step, the match noise of that step (~1 mm at 1 cm range noise, i.e.
        1 cm/s at 10 Hz) would be carried through the whole corridor; the window's mean carries
        that of its two ends over its length. Steps inside such a corridor take their open
        component from the prediction, so they keep the velocity the scans last measured.
        """
        self._recent.append((motion, dt))
        span = sum(step_dt for _, step_dt in self._recent)
        while len(self._recent) > 1 and span - self._recent[0][1] >= self.velocity_window:
            span -= self._recent.popleft()[1]
        if span > 0:
            # the steps summed one by one as numpy summed the arrays, on floats
            total = [0.0, 0.0, 0.0]
            for step, _ in self._recent:
                total = [total[0] + step[0], total[1] + step[1], total[2] + step[2]]
            self._velocity = np.array(total) / span

