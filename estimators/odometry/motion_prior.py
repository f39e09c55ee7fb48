"""How far a constant-velocity prediction of the next scan's pose can miss: the motion prior
that ``lidar_odometry`` and ``pc_fusion`` weigh against the returns. Distances [m], times [s].

Over a scan interval ``dt`` the prediction misses the car's position by about ``a dt^2`` for an
acceleration ``a``, plus ``speed * jitter`` when the clock's stamps wander (a scan stamped early
or late has moved further or less than its interval says). :func:`prediction_information`
turns that into the weight of the prior relative to one return's.

A prediction is only as good as the velocity it extrapolates, which was measured over the
recent scan intervals: over a clock gap far longer than those (a dropped sensor, a paused
log) the car may have stopped, turned or driven anywhere, so :func:`within_prediction_horizon`
(defined beside :func:`estimators.matching.prediction.constant_velocity`, the matching
layer's own prediction) says when an estimator must fall back to "no prior" instead.

The velocity itself is kept in the frame halfway through each increment's turn
(:func:`midpoint_velocity`, :func:`constant_velocity_increment`: the midpoint, or second-order
Runge-Kutta, rule of differential-drive odometry). A car on an arc moves along the chord, which
points half the heading change off its start heading; in the midpoint frame that chord is
straight ahead whatever the turn rate, so averaging recent translations there does not mix
past turn rates into the prediction's direction. Where the scan leaves a direction
unconstrained (a corridor's axis seen by one forward Lidar) the registration keeps the
prediction there (degeneracy-aware remapping, :func:`estimators.matching.point_to_line.
gauss_newton_step`) and nothing corrects it, so an error in the chord's direction feeds back
into the speed along the corridor: averaged in the car frame, the translations of a zigzag
lagged the turn rate and cost 4-6 % of the speed over 8 m of the closed_to_open corridor.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Iterable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimators.health import SortedWindow
from estimators.matching.curve_refinement import PRIOR_SIGMA, RANGE_NOISE
from estimators.matching.prediction import median, prediction_horizon, within_prediction_horizon
from lidar_env.core import EstimatorInputError
from lidar_env.core.se2 import wrap_float

FloatArray = NDArray[np.float64]

__all__ = [
    "ScanClock",
    "clock_jitter",
    "median",
    "constant_velocity_increment",
    "mean_translation",
    "midpoint_velocity",
    "no_sideslip_information",
    "no_sideslip_prior",
    "prediction_horizon",
    "prediction_information",
    "prediction_sigma",
    "within_prediction_horizon",
]

#: The prediction's position is never trusted to better than this [m] per scan (about a
#: registration's own precision at 1 cm range noise), however fast and regular the scans.
MIN_PREDICTION_SIGMA = 1e-3


def clock_jitter(intervals: ArrayLike, centre: float | None = None) -> float:
    """The clock's typical jitter [s]: the median deviation of the scan ``intervals`` [s] from
    their median (robust to glitching stamps); ``centre``: that median [s], when known."""
    intervals = np.asarray(intervals, dtype=np.float64)
    return median(np.abs(intervals - (median(intervals) if centre is None else centre)))


def _kth_deviation(ordered: Sequence[float], split: int, centre: float, k: int) -> float:
    """The ``k``-th smallest (from 0) of the deviations ``|x - centre|`` of sorted ``ordered``
    with the values before ``split`` below ``centre`` and the rest not: two runs that rise
    outward from ``split``, bisected on how many of the ``k + 1`` smallest lie below it."""
    lo, hi = max(0, k + 1 - (len(ordered) - split)), min(split, k + 1)
    while lo < hi:  # the fewest i below with the i-th's deviation >= the (k - i)-th's above
        i = (lo + hi) // 2
        if abs(ordered[split - 1 - i] - centre) < abs(ordered[split + k - i] - centre):
            lo = i + 1
        else:
            hi = i
    return max(abs(ordered[split - lo] - centre) if lo > 0 else -math.inf,
               abs(ordered[split + k - lo] - centre) if k >= lo else -math.inf)


def sorted_median_deviation(ordered: Sequence[float], centre: float) -> float:
    """:func:`clock_jitter` of values already sorted (not empty, no NaN) about ``centre``, bit
    for bit: the deviations rise outward from ``centre`` on either side, so the middle ones
    are read off the two runs by bisection (:func:`_kth_deviation`), a few dozen float
    operations where a partition of a few hundred intervals took several numpy calls."""
    split = bisect.bisect_left(ordered, centre)
    half = len(ordered) // 2
    upper = _kth_deviation(ordered, split, centre, half)
    if len(ordered) % 2:
        return upper
    return (_kth_deviation(ordered, split, centre, half - 1) + upper) / 2


#: Intervals a clock must have shown before its median stands for it.
SETTLED_INTERVALS = 5


class ScanClock:
    """The last scan intervals [s] of a logged clock and their robust statistics, each
    computed once per new interval (a median of a few hundred stamps costs tens of
    microseconds, and a scan of ``lidar_odometry`` asks for them several times); the
    intervals and steps are kept in sorted windows
    (:class:`~estimators.health.SortedWindow`), so that their medians are read, not computed.

    ``intervals`` holds the last ``max_intervals`` finite ones, ``steps`` the last
    ``max_steps`` positive ones (a glitching clock's zero or negative stamps are no step);
    the clock is ``settled`` once it has seen :data:`SETTLED_INTERVALS` intervals.
    """

    def __init__(self, max_intervals: int = 201, max_steps: int = 21) -> None:
        self.intervals = SortedWindow(max_intervals)
        self.steps = SortedWindow(max_steps)
        self._jitter: float | None = None  # of the intervals, until they change

    def add(self, dt: float) -> None:
        """One more interval ``dt`` [s]; a non-finite one is ignored."""
        if math.isfinite(dt):
            self.intervals.push(dt)
            if dt > 0:
                self.steps.push(dt)
            self._jitter = None

    def extend(self, intervals: Iterable[float]) -> None:
        """More finite intervals [s], as the clock's history only (not as steps)."""
        for dt in intervals:
            self.intervals.push(dt)
        self._jitter = None

    @property
    def settled(self) -> bool:
        """Whether enough intervals were seen for their median to describe the clock."""
        return len(self.intervals) >= SETTLED_INTERVALS

    @property
    def median(self) -> float:
        """The median interval [s] (needs one)."""
        return self.intervals.median

    @property
    def jitter(self) -> float:
        """:func:`clock_jitter` of the intervals [s], read off their sorted window
        (:func:`sorted_median_deviation`) once per new interval."""
        if self._jitter is None:
            self._jitter = sorted_median_deviation(self.intervals.ordered, self.median)
        return self._jitter

    @property
    def typical_step(self) -> float:
        """The median step [s] (needs one)."""
        return self.steps.median


def prediction_sigma(
    dt: float, speed: float, jitter: float, acceleration: float, max_sigma: float
) -> float:
    """Position uncertainty [m] of a constant-velocity prediction over ``dt`` [s] at ``speed``
    [m/s]: ``acceleration * dt^2 + speed * jitter``, clipped to [``MIN_PREDICTION_SIGMA``,
    ``max_sigma``]."""
    return float(min(max(acceleration * dt**2 + speed * jitter, MIN_PREDICTION_SIGMA), max_sigma))


#: A prediction that missed by more than this many times its assumed sigma in one of the last
#: few scans is trusted no better than its largest recent miss (:func:`missed_sigma`).
MISS_RATIO = 2.0


def missed_sigma(sigma: float, misses: Iterable[float], max_sigma: float) -> float:
    """The prediction's position sigma [m] after its recent ``misses`` [m] (how far each of the
    last scans' matches landed from its constant-velocity guess): ``sigma`` while none exceeds
    ``MISS_RATIO * sigma``, else the largest miss, at most ``max_sigma``.

    A fixed ``acceleration * dt^2`` holds for smooth driving; a car that brakes or starts from one
    scan to the next (an emergency stop for a pedestrian) misses it by its whole change of speed
    times ``dt``, and where the scan leaves a direction nearly free, the over-confident guess then
    drags the estimate along that direction scan after scan (steering by ``lidar_odometry`` through
    ``closed_to_open``: up to 0.4 m off at the end). Widening the prior after a large miss, as
    adaptive Kalman filters widen their process noise on large innovations, lets the scan correct
    it.
    """
    worst = max(misses, default=0.0)
    return min(max(worst, sigma), max_sigma) if worst > MISS_RATIO * sigma else sigma


#: A constant-velocity prediction over a scan interval ``dt`` misses the car's position by
#: about ``PREDICTION_ACCELERATION dt^2`` [m] (an indoor robot's brisk 0.5 m/s^2: 5 mm at 10 Hz,
#: 2 cm at 5 Hz), never trusted to better than ``motion_prior.MIN_PREDICTION_SIGMA`` [m] (a
#: match's own precision) nor worse than ``PRIOR_SIGMA``; see :func:`prediction_information`.
PREDICTION_ACCELERATION = 0.5


def prediction_information(dt: float, speed: float = 0.0, jitter: float = 0.0) -> FloatArray:
    """Information (3,) of a constant-velocity prediction over ``dt`` [s], relative to one
    return's (as ``PRIOR_INFORMATION``): its position good to ``PREDICTION_ACCELERATION dt^2``
    plus ``speed`` [m/s] times the clock's ``jitter`` [s] (a scan stamped early or late has
    moved further or less than its interval says), clipped to
    [``motion_prior.MIN_PREDICTION_SIGMA``, ``PRIOR_SIGMA``]; its heading to ``PRIOR_SIGMA``.

    Where the returns pin the pose down, hundreds of them outweigh it; where they leave a
    direction nearly open (the exit of a corridor, a hall with a few posts in range), it
    keeps the step from following the noise of a handful of returns.
    """
    if not dt > 0:
        raise EstimatorInputError(f"dt: expected a positive scan interval [s], got {dt}")
    if not (speed >= 0 and jitter >= 0):
        raise EstimatorInputError(f"speed and jitter: expected values >= 0, got {speed}, {jitter}")
    sigma = prediction_sigma(dt, speed, jitter, PREDICTION_ACCELERATION, PRIOR_SIGMA[0])
    return (RANGE_NOISE / np.array([sigma, sigma, PRIOR_SIGMA[2]])) ** 2


def midpoint_velocity(increment: ArrayLike, dt: float = 1.0) -> FloatArray:
    """Velocity (3,) of a pose ``increment`` (x [m], y [m], heading [rad], in the frame of its
    start) over ``dt`` (scans or [s]): the translation per ``dt`` turned into the frame halfway
    through the increment's turn, and the turn rate. The inverse of
    :func:`constant_velocity_increment`; a car on an arc of any curvature has velocity
    ``(chord / dt, 0, turn / dt)``."""
    increment = np.asarray(increment, dtype=np.float64)
    if increment.shape != (3,) or not dt > 0:
        raise EstimatorInputError(
            f"increment, dt: expected a pose (3,) and a positive interval, got shape "
            f"{increment.shape} and {dt}")
    x, y, turn = increment.tolist()  # lidar_env.core.se2.rotate's operations, on Python floats
    c, s = math.cos(-0.5 * turn), math.sin(-0.5 * turn)
    return np.array([(c * x - s * y) / dt, (s * x + c * y) / dt, turn / dt])


def constant_velocity_increment(velocity: ArrayLike, dt: float = 1.0) -> FloatArray:
    """Pose increment (3,) over ``dt`` of a body keeping ``velocity`` (3,) (translation in the
    midpoint frame per ``dt`` unit, turn rate; :func:`midpoint_velocity`): the translation
    ``velocity[:2] * dt`` turned by half the turn ``velocity[2] * dt``."""
    vx, vy, rate = np.asarray(velocity, dtype=np.float64).tolist()
    turn = rate * dt
    x, y = vx * dt, vy * dt  # lidar_env.core.se2.rotate's operations, on Python floats
    c, s = math.cos(0.5 * turn), math.sin(0.5 * turn)
    return np.array([c * x - s * y, s * x + c * y, turn])


def one_turn_increment(velocity: ArrayLike, dt: float, interval: float = 1.0) -> FloatArray:
    """:func:`constant_velocity_increment` over ``dt`` with the translation of ``velocity``
    (3,) but one ``interval``'s turn only (``velocity[2] * interval``, in ``dt``'s unit): over
    a gap of many intervals the extrapolated turn is the least known part of the guess (one
    noisy match's heading change; a car weaving down a corridor has turned back by the time
    the scans return)."""
    return constant_velocity_increment([velocity[0], velocity[1], velocity[2] * interval / dt],
                                       dt)


def mean_translation(translations: Sequence[FloatArray]) -> tuple[float, float]:
    """``np.mean(translations, axis=0)`` of a few translations (2,) [m], bit for bit (the
    rows summed in order, then divided by their number), on Python floats."""
    sx, sy = translations[0].tolist()
    for row in range(1, len(translations)):
        x, y = translations[row].tolist()
        sx, sy = sx + x, sy + y
    return sx / len(translations), sy / len(translations)



def no_sideslip_information(
    information: ArrayLike, heading: float, forward: float, sideslip_information: float,
    offset: float = 0.0, turn: float = 0.0,
) -> FloatArray:
    """Information (3, 3) of a motion prior: ``diag(information)`` (3,) plus the linearised
    non-holonomic constraint of a wheeled car, which does not slip sideways (Dissanayake et al.
    2001, "The aiding of a low-cost strapdown IMU using vehicle model constraints"): the step's
    translation has no component across the car's heading halfway through the step, held with
    ``sideslip_information`` (same units as ``information[:2]``).

    The constraint's residual ``n(phi) . d``, with ``d`` the translation, ``phi`` = ``heading``
    [rad] (the predicted midpoint heading) and the predicted ``forward`` step [m], changes with
    the pose as ``J = (-sin phi, cos phi, -forward / 2)``: turning further lets the chord turn
    by half as much. Where the scan leaves one world direction free (a corridor's axis) and the
    car moves at an angle to it, this ties the free motion to the seen one: how fast the car
    closes on the walls and its heading say how far it went along them. 0 leaves the prior
    diagonal (a holonomic base). A frame ``offset`` [m] ahead of the no-slip point moves
    sideways by ``2 offset sin(turn / 2)`` over a step turning ``turn`` [rad]
    (:mod:`estimators.odometry.no_slip_point`), which adds ``-offset cos(turn / 2)`` to the
    heading's term.
    """
    information = np.asarray(information, dtype=np.float64)
    if information.shape != (3,) or not sideslip_information >= 0:
        raise EstimatorInputError(
            f"information, sideslip_information: expected shape (3,) and a value >= 0, got "
            f"{information.shape} and {sideslip_information}")
    if sideslip_information == 0 and math.isfinite(heading) and math.isfinite(forward):
        return np.diag(information)  # the same as adding 0 times the outer product
    jacobian = np.array([-np.sin(heading), np.cos(heading), _heading_term(forward, offset, turn)])
    return np.diag(information) + sideslip_information * np.outer(jacobian, jacobian)


def _heading_term(forward: float, offset: float, turn: float) -> float:
    """The no-sideslip residual's derivative by the heading (:func:`no_sideslip_information`)."""
    return -0.5 * forward if offset == 0 else -0.5 * forward - offset * math.cos(0.5 * turn)


def no_sideslip_prior(
    diagonal: ArrayLike, guess: ArrayLike, previous: ArrayLike, pose: ArrayLike,
    sideslip_information: float, offset: float = 0.0,
) -> tuple[FloatArray, FloatArray]:
    """The motion prior ``diag(diagonal)`` (3,) at ``guess`` (3,) plus the no-sideslip
    constraint of the step from ``previous`` to ``pose`` (3,) (world frame; its translation
    along the midpoint heading, but for ``2 offset sin(turn / 2)`` across it with the frame
    ``offset`` [m] ahead of the no-slip point, :func:`no_sideslip_information`) linearised at
    ``pose``, as one quadratic: its centre (3,) and information (3, 3).

    Linearised at the matched pose rather than at the constant-velocity guess: where the turn
    rate jumps between two scans (a robot that stops to turn), the guess's heading is a whole
    interval's turn off, and so is the direction the constraint holds still; the match's
    heading is what the scans show. The constraint ``c(x) ~ c(pose) + J (x - pose)`` and the
    prior combine as ``(x - m)^T H (x - m)`` with ``H = D + s J J^T`` and
    ``m = guess + H^-1 s J (J (pose - guess) - c(pose))``."""
    diagonal = np.asarray(diagonal, dtype=np.float64)
    guess, previous, pose = (np.asarray(v, dtype=np.float64) for v in (guess, previous, pose))
    if diagonal.shape != (3,) or not sideslip_information >= 0:
        raise EstimatorInputError(
            f"diagonal, sideslip_information: expected shape (3,) and a value >= 0, got "
            f"{diagonal.shape} and {sideslip_information}")
    turn = wrap_float(float(pose[2] - previous[2]))
    heading = previous[2] + 0.5 * turn
    step = pose[:2] - previous[:2]
    normal = np.array([-math.sin(heading), math.cos(heading)])
    forward = float(step @ np.array([math.cos(heading), math.sin(heading)]))
    jacobian = np.array([normal[0], normal[1], _heading_term(forward, offset, turn)])
    information = no_sideslip_information(diagonal, heading, forward, sideslip_information,
                                          offset, turn)
    lateral = 0.0 if offset == 0 else 2.0 * offset * math.sin(0.5 * turn)
    moved = pose - guess
    moved[2] = wrap_float(float(moved[2]))
    pull = sideslip_information * jacobian * (jacobian @ moved - (float(normal @ step) - lateral))
    centre = guess + np.linalg.lstsq(information, pull, rcond=None)[0]  # D = 0: any point
    # on the constraint's line
    centre[2] = wrap_float(float(centre[2]))
    return centre, information
