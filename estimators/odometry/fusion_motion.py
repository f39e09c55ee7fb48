"""The motion model of ``pc_fusion`` (:class:`~estimators.odometry.fusion.FusionEstimator`):
the car's velocity [m/s, m/s, rad/s] (car frame) as the mean of its own steps over a window of
time, and the information of the prediction it makes (:class:`FusedVelocity`, a mixin).
"""

from __future__ import annotations

from collections import deque

import numpy as np
from numpy.typing import NDArray

from estimators.matching.curve_refinement import PRIOR_INFORMATION
from estimators.matching.prediction import PREDICTION_GAP_FACTOR
from estimators.odometry.motion_prior import ScanClock, prediction_information

FloatArray = NDArray[np.float64]

#: Scan intervals the clock's typical jitter is taken over (20 s at 10 Hz).
CLOCK_HISTORY = 200

#: A clock whose intervals deviate from their median by this share of the median step or
#: more (its jitter), or whose mean interval (gaps left out) is ``BUNCHED_MEAN`` times its
#: median step or more, stamps scans in bunches: they run at that mean rate, whatever their
#: stamps say. (ACES's 0.08-0.24 s stamps: jitter at most 0.33 of the median step, mean at most
#: 1.2 times it; Intel's: jitter about the median step, mean 1.2-170 times it.)
BUNCHED_JITTER = 0.5
BUNCHED_MEAN = 2.0


class FusedVelocity:
    """The velocity and prediction of :class:`~estimators.odometry.fusion.FusionEstimator`, a
    mixin: it reads ``velocity_window`` [s] and keeps ``_velocity``, the ``_recent`` steps,
    the ``_clock`` and whether it stamps scans in bunches (``_bunched``)."""

    velocity_window: float
    _velocity: FloatArray
    _recent: deque[tuple[list[float], float]]
    _clock: ScanClock
    _bunched: bool

    def _scan_timing(self, stamped: float) -> tuple[float, list[float]]:
        """The time [s] the car moved over between two scans stamped ``stamped`` [s] apart,
        and the typical scan interval [s] (none before the clock has stepped).

        On a regular clock: ``stamped``, and the median step. On a clock that stamps scans
        in bunches (``BUNCHED_JITTER``, ``BUNCHED_MEAN``: a logger stamping a few scans within
        a millisecond, then none for half a second) the scans still run at one rate: the mean
        interval (:meth:`_mean_interval`) stands for both,
        unless ``stamped`` spans more than ``PREDICTION_GAP_FACTOR`` of them (scans lost or a
        real gap). Counted by their stamps, the car's steps there bear no relation to their
        intervals, and a velocity from them is off many times over."""
        typical = [self._clock.typical_step] if self._clock.steps else []
        if not (typical and self._clock.settled):
            return stamped, typical
        mean = self._mean_interval()
        if not (mean > 0 and (self._clock.jitter >= BUNCHED_JITTER * typical[0]
                              or mean >= BUNCHED_MEAN * typical[0])):
            self._bunched = False
            return stamped, typical
        if not self._bunched:  # the steps timed by their stamps so far: timed by the scans
            self._bunched = True
            self._recent = deque((step, self._bunched_interval(step_dt, mean))
                                 for step, step_dt in self._recent)
            self._average_recent()
        return self._bunched_interval(stamped, mean), [mean]

    @staticmethod
    def _bunched_interval(stamped: float, mean: float) -> float:
        """The time [s] between two scans stamped ``stamped`` [s] apart on a bunched clock of
        ``mean`` interval [s]: that mean, but over a gap (:meth:`_scan_timing`)."""
        return mean if 0 <= stamped <= PREDICTION_GAP_FACTOR * mean else stamped

    def _mean_interval(self) -> float:
        """The mean of the clock's intervals [s], gaps left out: from the longest down, each
        longer than ``PREDICTION_GAP_FACTOR`` times the mean of those shorter than it (a 3 s
        jump among twenty 0.16 s intervals would otherwise double their mean)."""
        ordered = self._clock.intervals.ordered
        count, total = len(ordered), sum(ordered)
        while count > 1 and ordered[count - 1] * (count - 1) > PREDICTION_GAP_FACTOR * (
                total - ordered[count - 1]):
            count -= 1
            total -= ordered[count]
        return total / count

    def _prediction_information(self, stamped: float, dt: float,
                                predicted: bool = True) -> FloatArray:
        """The prediction's information over ``dt`` [s] (:meth:`_scan_timing` of the
        ``stamped`` interval [s], which the clock takes in)
        (:func:`estimators.odometry.motion_prior.prediction_information`), with the clock's
        jitter the median deviation of the last ``CLOCK_HISTORY`` intervals from their median;
        the weak default prior when nothing was ``predicted`` (a clock gap)."""
        if stamped > 0:
            self._clock.add(stamped)
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
        self._average_recent()

    def _average_recent(self) -> None:
        """The velocity as the mean of the ``_recent`` steps, those older than
        ``velocity_window`` [s] dropped."""
        span = sum(step_dt for _, step_dt in self._recent)
        while len(self._recent) > 1 and span - self._recent[0][1] >= self.velocity_window:
            span -= self._recent.popleft()[1]
        if span > 0:
            # the steps summed one by one as numpy summed the arrays, on floats
            total = [0.0, 0.0, 0.0]
            for step, _ in self._recent:
                total = [total[0] + step[0], total[1] + step[1], total[2] + step[2]]
            self._velocity = np.array(total) / span

