"""Where ``lidar_odometry`` puts the car after a clock gap: scans lost on the way, or only the
stamp jumped.

The scans alone cannot tell the two apart along a direction they leave free (a featureless
corridor's axis): matched from the one-interval guess (the stamp jumped alone) the car stays
there along the axis, matched from the guess over every interval of the gap (scans lost while
it drove on) it stays there instead, and both explain the scan alike. The directions the scans
pin do tell them apart: a car weaving down the corridor for eleven intervals has crossed it by
eleven intervals' sideways motion, where one interval moves it by a tenth of that. So where
the scan leaves a direction free the scan is matched from both guesses, each held by the same
weak prior at its guess, and of two matches that explain the scan alike the one its guess
predicted better is kept (:func:`~estimators.matching.scan_recovery.most_likely_match`, the
``icp`` estimator's test of a lost scan): its pinned directions agree with it, and along the
free one the guess that agrees is the best there is.

A guess over ``n`` intervals spreads ``n`` times wider than the one-interval guess, so it
agrees with a pose that does not tell the two apart (a car driving straight along the
corridor, or one that stopped) about as well per interval, by chance. The whole-gap match
therefore also has to be the likelier where each guess misses by a Gaussian of one step's
standard deviation per interval it spans (:func:`gap_more_likely`): its miss ``m_n``
against the one-interval miss ``m_1``, in steps, ``log n + m_n^2 / (2 n^2) < m_1^2 / 2``.
The one-interval guess then has to miss by about two steps (``sqrt(2 log n)``: 2.2 for 11
intervals) before the gap is taken for lost scans: bursty stamps (Intel's: 29 % of
intervals over five times the median, the car a step on at each) keep their one-interval
matches. Poses in the world frame: x, y [m], heading [rad].
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from estimators.matching.icp import ICPParams, MatchResult, register
from estimators.matching.point_to_line import PointToLineReference
from estimators.matching.scan_recovery import lost_scan_surprise, most_likely_match
from estimators.odometry.blind_resume import free_direction

FloatArray = NDArray[np.float64]


def gap_more_likely(found: FloatArray, guess: FloatArray, other: FloatArray,
                    longer: FloatArray, intervals: float, step: float) -> bool:
    """Whether the pose ``other`` (3,) from the ``longer`` guess (3,) over ``intervals`` scan
    intervals is likelier than ``found`` (3,) from the one-interval ``guess`` (3,), each
    guess's miss (:func:`~estimators.matching.scan_recovery.lost_scan_surprise` over one
    interval, in units of the last ``step`` [m]) a Gaussian of one step's standard deviation
    per interval it spans (module docstring)."""
    miss_found = lost_scan_surprise(found, guess, 1.0, step)
    miss_other = lost_scan_surprise(other, longer, intervals, step)
    return math.log(intervals) + 0.5 * miss_other**2 < 0.5 * miss_found**2


def across_gap(reference: PointToLineReference, points: FloatArray, found: MatchResult,
               guess: FloatArray, longer: FloatArray, intervals: float, step: float,
               params: ICPParams, prior_information: FloatArray) -> MatchResult:
    """``found``, the match of ``points`` (M, 2, car frame) from the one-interval ``guess``
    (3,), or the match from the ``longer`` guess (3,) over ``intervals`` scan intervals (held
    by ``prior_information`` at it, as ``found`` was at ``guess``) where it explains the scan
    as well and its guess predicted it better, the last per-interval ``step`` [m] the unit of
    a miss, and the likelier of the two (:func:`gap_more_likely`).
    ``found`` where the scan pins every direction (with ``params.min_information`` points at
    least): the guesses' matches then agree."""
    if free_direction(found.information, params.min_information) is None:
        return found
    other = register(reference, points, longer, params, longer, prior_information)
    kept = most_likely_match([found, other], [guess, longer], [1.0, intervals], step,
                             len(points))
    return other if kept == 1 and gap_more_likely(found.pose, guess, other.pose, longer,
                                                  intervals, step) else found
