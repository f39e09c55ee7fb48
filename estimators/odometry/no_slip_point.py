"""Where a wheeled robot does not slip sideways, found online from its own well-seen steps.

A car or a differential-drive robot moves, at the point between its fixed wheels (its no-slip
point), only along its heading. A frame ``offset`` [m] ahead of that point along the car's x
axis (a CARMEN log's laser frame, a Lidar mounted ahead of the rear axle) moves sideways in a
turn: over a step that turns by ``turn`` [rad] its translation, in the frame halfway through
the turn (``motion_prior.midpoint_velocity``), is ``(chord, 2 offset sin(turn / 2))``.

:class:`NoSlipCalibration` fits ``offset`` to the steps a scan pins across the car (lateral
translation against ``2 sin(turn / 2)``, a line through the origin, each step weighed by its
match's information across the car) by iteratively reweighted least squares with a Cauchy loss
at the residuals' robust scale, so the rare wrong match or a walker's pull does not drag it,
and says whether the fit holds: a holonomic base that strafes, or a skid-steered one whose
slide in the turns varies, leaves sideways steps no offset explains (a slide in proportion to
the turn moves the no-slip point, and the fit places it there). Only while the fit is confident
and consistent does ``lidar_odometry`` hold the steps a scan leaves free (a corridor's axis) to
the constraint (:func:`estimators.odometry.motion_prior.no_sideslip_prior`); the steps it held
are no evidence for it and do not join the fit. What it cannot tell: a base that strafes in
fewer than ``MAX_OUTLIER_SHARE`` of its well-seen steps, or slides by less than
``MAX_SIDESLIP_SHARE`` of its step, passes as a car.
Distances [m], angles [rad].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: [points] a step joins the calibration where its match pins the direction across the car
#: with at least this many points squarely facing it, the other directions free (a corridor's
#: axis: a few at most).
MIN_STEP_INFORMATION = 5.0
#: Steps the fit is taken over: the latest ones (a few minutes at 5-10 Hz of driving).
WINDOW = 400
#: Fewest turning steps (``|2 sin(turn / 2)|`` over ``MIN_TURN``) the fit needs.
MIN_TURNING_STEPS = 10
#: [rad] a step turning less than this tells nothing of the offset.
MIN_TURN = math.radians(2.0)
#: [m] the largest offset's standard error the constraint is applied with.
MAX_OFFSET_ERROR = 0.02
#: The largest share of the steps' forward travel their residual sideways steps may have
#: (robust scale over the median forward step): registration noise is 1-3 % of a step
#: (simulated drives at 4-5 Hz, Intel); a sliding base's sideways steps, more.
MAX_SIDESLIP_SHARE = 0.05
#: The largest share of steps whose residual exceeds ``OUTLIER`` robust scales (a matcher's
#: rare wrong step, a walker dragging the match: up to ~6 % in the simulated drives with
#: walkers): a base that strafes now and then, between straight runs that look like a car's,
#: has more.
MAX_OUTLIER_SHARE = 0.1
OUTLIER = 5.0
#: Cauchy loss scale in robust scales, and reweighting iterations.
CAUCHY_SCALE = 2.0
ITERATIONS = 5
#: The fit is taken again every this many new steps (it moves little from one to the next).
REFIT_EVERY = 5
#: ``|2 sin(turn / 2)|`` of a step turning ``MIN_TURN``.
MIN_CHORD = 2.0 * math.sin(0.5 * MIN_TURN)


@dataclass(frozen=True)
class NoSlipFit:
    """A confident fit: the no-slip point ``offset`` [m] behind the frame along its x axis,
    its standard error ``offset_error`` [m], and the robust scale of the residual sideways
    steps ``residual`` [m]."""

    offset: float
    offset_error: float
    residual: float

    def lateral(self, turn: float) -> float:
        """The sideways translation [m] (midpoint frame) of a step turning ``turn`` [rad]."""
        return 0.0 if self.offset == 0 else 2.0 * self.offset * math.sin(0.5 * turn)

    def sigma(self, turn: float, sideslip_sigma: float) -> float:
        """[m] how far a step turning ``turn`` [rad] may miss :meth:`lateral`: the slip a
        no-slip base allows, ``sideslip_sigma``, and the offset's error over that turn."""
        return math.hypot(sideslip_sigma, 2.0 * self.offset_error * math.sin(0.5 * turn))


class NoSlipCalibration:
    """The offset of the no-slip point from the steps seen so far (module docstring):
    :meth:`add` a matched step, read :attr:`fit` (None until confident and consistent)."""

    def __init__(self) -> None:
        # the latest WINDOW steps, a ring: forward, lateral [m] in the midpoint frame,
        # 2 sin(turn / 2), lateral variance [1 / points]
        self._ring = np.empty((WINDOW, 4))
        self._count = 0  # steps added since the start (or restart)
        self.fit: NoSlipFit | None = None

    @property
    def steps(self) -> FloatArray:
        """The steps the fit is taken over (n, 4), in no particular order (a view)."""
        return self._ring[:min(self._count, WINDOW)]

    def add(self, increment: FloatArray, heading: float, information: FloatArray | None
            ) -> None:
        """One step: its ``increment`` (3,) (x, y [m], heading [rad], frame of its start), the
        world ``heading`` [rad] it starts from, and its match's ``information`` (3, 3, world
        frame, in points), None for a step not matched from the last one (after skipped scans
        or a jumping clock). Steps the match does not pin across the car, or whose information
        is not finite, are not used (a corridor's axis lies across a car turned towards a
        wall)."""
        if information is None or not _added(self._ring, self._count % WINDOW, increment,
                                             heading, information):
            return
        self._count += 1
        if self._count % REFIT_EVERY == 0:
            outcome, offset, error, residual = _fit(self.steps, MIN_TURNING_STEPS)
            if outcome != TOO_FEW_TURNS:  # else too few to judge: the last fit stands
                self.fit = NoSlipFit(offset, error, residual) if outcome == FIT else None

    def restart(self) -> None:
        """Forget the steps but keep the fit (the same robot, its steps about to be matched
        again: ``lidar_odometry``'s start replay)."""
        self._count = 0


@njit(cache=True)
def _added(ring: FloatArray, slot: int, increment: FloatArray, heading: float,
           information: FloatArray) -> bool:
    """Write the step into ``ring[slot]`` (forward, lateral [m] in the midpoint frame,
    ``2 sin(turn / 2)``, the variance [1 / points] across the car there, of ``information``
    inverted by LAPACK's ``dgesv`` as ``np.linalg.inv`` does, the other directions unknown)
    where the match pins the car's sideways direction; else (also for a singular or not
    finite ``information``) False, the ring untouched."""
    x, y, turn = increment[0], increment[1], increment[2]
    c, s = math.cos(0.5 * turn), math.sin(0.5 * turn)
    try:
        covariance = np.linalg.solve(information, np.eye(3))
    except Exception:  # singular or not finite: nothing pinned
        return False
    across = heading + 0.5 * turn
    normal = np.array([-math.sin(across), math.cos(across)])
    variance = np.dot(np.dot(normal, np.ascontiguousarray(covariance[:2, :2])), normal)
    if not 0 < variance <= 1.0 / MIN_STEP_INFORMATION:
        return False
    ring[slot, 0] = c * x + s * y
    ring[slot, 1] = c * y - s * x
    ring[slot, 2] = 2.0 * s
    ring[slot, 3] = variance
    return True


@njit(cache=True)
def _sum(values: FloatArray) -> float:
    """``np.sum`` of a contiguous ``values`` (n,) bit for bit: :func:`_pairwise_sum` added to
    the sum's start, 0.0 (so that a sum of -0.0 is 0.0)."""
    return 0.0 + _pairwise_sum(values)


@njit(cache=True)
def _pairwise_sum(values: FloatArray) -> float:
    """numpy's pairwise summation: eight running sums over blocks of at most 128 values, the
    halves of longer runs summed apart."""
    n = len(values)
    if n < 8:
        total = 0.0
        for value in values:
            total += value
        return total
    if n > 128:
        half = n // 2
        half -= half % 8
        return _pairwise_sum(values[:half]) + _pairwise_sum(values[half:])
    partial = values[:8].copy()
    i = 8
    while i < n - n % 8:
        for j in range(8):
            partial[j] += values[i + j]
        i += 8
    total = ((partial[0] + partial[1]) + (partial[2] + partial[3])) + (
        (partial[4] + partial[5]) + (partial[6] + partial[7]))
    for k in range(i, n):
        total += values[k]
    return total


#: Outcomes of :func:`_fit`.
FIT, REFUSED, TOO_FEW_TURNS = 0, 1, 2


@njit(cache=True)
def _fit(steps: FloatArray, min_turning: int) -> tuple[int, float, float, float]:
    """The fit of :func:`fitted` as (outcome, offset, offset_error, residual): ``FIT``,
    ``REFUSED`` (not confident or not consistent), or ``TOO_FEW_TURNS`` (fewer than
    ``min_turning`` steps turning ``MIN_TURN``); the arithmetic of numpy's array operations
    in their order (sums by :func:`_sum`), so the same numbers bit for bit."""
    n = len(steps)
    forward, lateral, chord = steps[:, 0], steps[:, 1], steps[:, 2]
    precision = 1.0 / steps[:, 3]
    if np.count_nonzero(np.abs(chord) > MIN_CHORD) < min_turning:
        return TOO_FEW_TURNS, 0.0, 0.0, 0.0
    root_precision = np.sqrt(precision)
    weights = precision.copy()
    moment, spread, normalised = np.empty(n), np.empty(n), np.empty(n)
    offset = scale = 0.0
    for _ in range(ITERATIONS):
        for i in range(n):
            moment[i] = weights[i] * chord[i] * lateral[i]
            spread[i] = weights[i] * (chord[i] * chord[i])
        offset = _sum(moment) / _sum(spread)
        for i in range(n):  # [m sqrt(points)]
            normalised[i] = (lateral[i] - offset * chord[i]) * root_precision[i]
        scale = 1.4826 * np.median(np.abs(normalised))
        if scale <= 0:
            return REFUSED, 0.0, 0.0, 0.0
        for i in range(n):
            ratio = normalised[i] / (CAUCHY_SCALE * scale)
            weights[i] = precision[i] / (1.0 + ratio * ratio)
    inliers = np.count_nonzero(np.abs(normalised) <= OUTLIER * scale)
    for i in range(n):
        spread[i] = weights[i] * (chord[i] * chord[i])
    error = scale / math.sqrt(_sum(spread))
    residual = scale * math.sqrt(np.median(steps[:, 3]))  # [m], a typical step
    if (error > MAX_OFFSET_ERROR or residual > MAX_SIDESLIP_SHARE * np.median(np.abs(forward))
            or 1.0 - inliers / n > MAX_OUTLIER_SHARE):
        return REFUSED, 0.0, 0.0, 0.0
    return FIT, offset, error, residual


def fitted(steps: FloatArray) -> NoSlipFit | None:
    """The fit of ``steps`` (N, 4: forward [m], lateral [m], ``2 sin(turn / 2)``, the
    lateral step's variance [1 / points]; some turning) when it is confident
    (``MAX_OFFSET_ERROR``) and consistent (residuals within ``MAX_SIDESLIP_SHARE`` of the
    forward steps, outliers within ``MAX_OUTLIER_SHARE``), else None. Each step weighs by the
    inverse of its variance; the residuals are judged in units of their own spread."""
    outcome, offset, error, residual = _fit(np.ascontiguousarray(steps, dtype=np.float64), 1)
    return NoSlipFit(offset, error, residual) if outcome == FIT else None
