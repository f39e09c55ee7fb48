"""The constant-velocity model of ``lidar_odometry``: its guess, its prior's weight, its update.

:class:`ConstantVelocityModel` keeps the estimator's own recent increments (never odometry):
the translation averaged over the last ``velocity_window`` in each increment's midpoint frame,
the turn rate from the last one, counted per scan or, with ``use_timestamps``, per second of
a guarded clock. Its information is the prior :func:`estimators.matching.icp.register` weighs
against the points. Why each choice, with the measurements: the module docstring of
:mod:`estimators.odometry.local_map`; the math is in :mod:`estimators.odometry.motion_prior`.
Distances [m], angles [rad], times [s] or scans.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np
from numpy.typing import NDArray

import estimators.odometry.motion_prior as motion_prior
from estimators.health import BLIND_STRETCH
from estimators.odometry.motion_prior import (
    ScanClock,
    constant_velocity_increment,
    missed_sigma,
    prediction_sigma,
)
from estimators.odometry.no_slip_point import NoSlipCalibration, NoSlipFit

FloatArray = NDArray[np.float64]

try:  # np.linalg.eigh's own LAPACK call (dsyevd, lower triangle) without its per-call checks
    # and error-state context, which cost several times a 2 x 2 decomposition
    from numpy.linalg._umath_linalg import eigh_lo as _symmetric_eigh
except ImportError:  # a numpy that keeps it elsewhere: the public call, the same values
    _symmetric_eigh = np.linalg.eigh


class ConstantVelocityModel:
    """The motion model of :class:`~estimators.odometry.local_map.LocalMapOdometry`, a mixin:
    it reads the front end's settings (``use_timestamps``, ``velocity_window``,
    ``noise_sigma``, ``prior_sigma_translation``, ``prediction_acceleration``,
    ``sideslip_sigma``, ``calibrated_sideslip_sigma``, ``speed_information``),
    ``_prior_information``, ``pose`` and ``speed_unknown``, and keeps ``_velocity``,
    ``_seen_translation``, ``_translations``, ``_misses``, ``_clock``, ``_last_time`` and
    ``_no_slip`` (:class:`~estimators.odometry.no_slip_point.NoSlipCalibration`)."""

    use_timestamps: bool
    velocity_window: int
    noise_sigma: float
    prior_sigma_translation: float
    prediction_acceleration: float
    sideslip_sigma: float
    calibrated_sideslip_sigma: float
    speed_information: float
    speed_unknown: bool
    pose: FloatArray  # the estimator's current pose (``Estimator.pose``)
    _prior_information: FloatArray

    def _reset_motion_model(self) -> None:
        """At rest, no clock seen (called by ``_reset_state``)."""
        self._velocity = np.zeros(3)  # car frame, per second or per scan
        self._seen_translation = np.zeros(2)  # the last increment's, midpoint frame
        self._translations: deque[FloatArray] = deque(maxlen=self.velocity_window)
        self._misses: deque[float] = deque(maxlen=self.velocity_window)
        self._last_time = 0.0
        self._clock = ScanClock()
        self._no_slip = NoSlipCalibration()

    def _no_slip_fit(self) -> NoSlipFit | None:
        """Where the car frame does not slip sideways: at its origin with a finite
        ``sideslip_sigma``; else, with a finite ``calibrated_sideslip_sigma``, the online
        calibration's confident fit (None before, or where no offset explains the steps)."""
        if math.isfinite(self.sideslip_sigma):
            return NoSlipFit(0.0, 0.0, 0.0)
        return self._no_slip.fit if math.isfinite(self.calibrated_sideslip_sigma) else None

    def _sideslip(self) -> float:
        """[m] the slip per step the no-slip constraint allows (``_no_slip_fit`` not None)."""
        known = math.isfinite(self.sideslip_sigma)
        return self.sideslip_sigma if known else self.calibrated_sideslip_sigma

    def _calibrate_no_slip(self, increment: FloatArray, information: FloatArray | None) -> None:
        """One matched step for the no-slip calibration, where it runs (``_no_slip_fit``)."""
        if not math.isfinite(self.sideslip_sigma) and math.isfinite(
                self.calibrated_sideslip_sigma):
            self._no_slip.add(increment, float(self.pose[2]), information)

    def _time_step(self, t: float) -> float:
        """Scans since the last one (1), or with ``use_timestamps`` the time since it [s],
        guarded against glitching stamps."""
        dt = t - self._last_time
        self._last_time = t
        self._clock.add(dt)
        if not self.use_timestamps or not self._clock.steps:
            return 1.0  # count in scans
        typical = self._clock.typical_step
        return min(max(dt, 0.5 * typical), 2.0 * typical) if dt > 0 else typical

    def _predicted(self, dt: float, skipped: int) -> FloatArray:
        """The constant-velocity increment (3,) over ``dt`` (scans, or seconds with
        ``use_timestamps``), but after a long blind stretch (``skipped`` >=
        :data:`~estimators.health.BLIND_STRETCH` scans) turned by one interval's turn only.
        The turn rate is the last match's heading change alone, noisy where a few returns pin
        it; extrapolated over many intervals it is the least known part of the guess (a
        TurtleBot3 driving straight among pillars, blind for 16 s, was guessed 54 degrees
        turned from a 0.7-degree step)."""
        if skipped < BLIND_STRETCH:
            return constant_velocity_increment(self._velocity, dt)
        one = self._clock.typical_step if self.use_timestamps and self._clock.steps else 1.0
        return motion_prior.one_turn_increment(self._velocity, dt, one)

    def _prediction_information(self) -> FloatArray:
        """The motion prior's information (3, 3): none while the start velocity is unknown."""
        return np.zeros((3, 3)) if self.speed_unknown else self._model_information()

    def _model_information(self) -> FloatArray:
        """Information (3, 3, diagonal) of the constant-velocity guess, in the point
        residuals' units. The guess misses by ``prediction_acceleration * dt^2`` over a
        typical scan interval ``dt`` plus, counting scans, speed times the interval's typical
        jitter (a late scan has moved further); clipped to [``motion_prior.MIN_PREDICTION_
        SIGMA``, ``prior_sigma_translation``], which also holds until the clock has been seen
        for a few scans or when it does not run forward. (The no-sideslip constraint is added
        after the match, linearised at it: ``LocalMapOdometry._no_sideslip_match``.)"""
        information = self._prior_information.copy()
        typical = self._clock.median if self._clock.settled else 0.0
        if typical > 0:  # the step over one interval, its speed [m/s]
            x, y = (self._velocity[:2] * (typical if self.use_timestamps else 1.0)).tolist()
            sigma = prediction_sigma(typical, float(np.hypot(x, y)) / typical,
                                     self._clock.jitter, self.prediction_acceleration,
                                     self.prior_sigma_translation)
            sigma = missed_sigma(sigma, self._misses, self.prior_sigma_translation)
            information[:2] = (self.noise_sigma / sigma) ** 2
        return np.diag(information)

    def _updated_velocity(self, increment: FloatArray, dt: float,
                          information: FloatArray | None = None) -> FloatArray:
        """Constant-velocity model after ``increment`` over ``dt`` (scans or seconds): the
        translation in the increment's midpoint frame (``motion_prior.midpoint_velocity``)
        averaged over the last ``velocity_window`` increments (one carries the noise of two
        registrations, ~1-2 % of a step, which a corridor's axis dead-reckons), the turn rate
        from the last one (turn rates change faster than speeds and are rarely unobservable).
        With a finite ``sideslip_sigma`` (the car frame at the wheels' no-slip point) the
        velocity has no sideways part: where the scan leaves an axis free, the increments'
        error along it shows up sideways in the car frame, and carried on in the guess it
        drifted down a corridor while the car rocked back and forth (3.3 m); a frame ahead
        of the no-slip point keeps the sideways velocity of its offset in the increment's turn
        (:meth:`_no_slip_fit`). With the match's
        ``information`` (3, 3, world frame), a direction it pins weakly moves the velocity
        only in proportion (:meth:`_weakly_seen_held`), unless the speed is still unknown;
        ``_seen_translation`` keeps the increment's own."""
        translation = motion_prior.midpoint_velocity(increment, dt)[:2]
        self._seen_translation = translation.copy()
        if information is not None and self._translations and not self.speed_unknown:
            translation = self._weakly_seen_held(translation, information[:2, :2],
                                                 float(self.pose[2] + 0.5 * increment[2]))
        fit = self._no_slip_fit()
        if fit is not None:
            translation[1] = fit.lateral(float(increment[2])) / dt
        self._translations.append(translation)
        return np.array([*motion_prior.mean_translation(self._translations), increment[2] / dt])

    def _weakly_seen_held(self, translation: FloatArray, information: FloatArray,
                          heading: float) -> FloatArray:
        """``translation`` (2, midpoint frame at ``heading`` [rad]) moved from the velocity's
        along each eigendirection of the points' ``information`` (2, 2, world frame) by
        ``lambda / (lambda + speed_information)`` of the way, ``lambda`` that direction's
        information in points' worth: with ``speed_information`` 10, a direction pinned by 2
        points' worth moves the velocity a sixth of the way, one pinned by 200 about 95 %.

        Where a few returns pin the motion along an aisle (the gaps between shelf units, a
        door jamb, the fitted normals' own noise), each match's step along it is mostly their
        noise and the prior's guess; fed back whole into the velocity, that noise walks the
        speed along the aisle (a TurtleBot down a depot's aisles drifted 9-35 % of the path,
        sometimes backwards) where the car kept its speed. The pose still takes the match's
        step; only the speed it carries on with is held.
        """
        c, s = math.cos(heading), math.sin(heading)
        rotation = np.array([[c, -s], [s, c]])
        values, vectors = _symmetric_eigh(rotation.T @ information @ rotation)
        values = np.maximum(values, 0.0)
        gains = values / (values + self.speed_information)
        held = self._velocity[:2]
        return held + vectors @ (gains * (vectors.T @ (translation - held)))
