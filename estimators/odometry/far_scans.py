"""Scans far apart: where the ``lidar_odometry`` front end searches before ICP refines.

ICP converges from a guess within its pairing gate; a constant-velocity guess is that good when
scans come a few centimetres apart (10 Hz), not when they come a metre and tens of degrees
apart (keyframe-only logs, 1-2 Hz scanners, dropped scans). Two searches give ICP its start
on the likelihood field of the local map (Olson 2009):

* **Far-apart search.** When the motion prior is weak (over the clock's typical interval ``dt``
  the constant-velocity guess can miss by ``prediction_acceleration * dt^2``, more than the
  weakest prior the ordinary path allows, ``prior_sigma_translation``: scans at 4 Hz or
  slower; a 1 Hz car braking at 0.5 m/s^2 is 0.5 m off), or when the guess moves the car a
  keyframe spacing per scan or turns it by more than the fallback's heading window, ICP runs
  twice, from
  the guess and from the exact best pose of a multi-resolution branch-and-bound search
  (:mod:`estimators.matching.branch_and_bound`) over every pose the car can have reached:
  within ``max_speed * dt`` of the guess, turned by up to ``max_turn_rate * dt`` (every
  heading beyond 180 deg), ``dt`` the scan interval or the typical one when the stamp says
  less (stamps glitch). A stalled clock does not move the car further, so the window is
  also held to twice the longest step and turn of the last few scans plus ICP's pairing gate
  and the fallback's heading window (keyframe-only logs: scans ~1 m apart, stamps up to 20 s
  apart). The result explaining more points is kept; the motion prior weighs what the
  guess is worth over the interval (``prediction_acceleration * dt^2``, unclipped).
* **Fallback** (:func:`fallback_match`), when a match explains too few points: a correlative
  search in a small window around the guess, then over every heading the car can have
  turned to (twice ``max_turn_rate`` times the interval: a turn rate reversed at full rate;
  every heading over a gap in the scans), then over the far-apart window. A turn faster than
  the motion model, or one spanning a gap in the scans, lies outside any small window around
  the guess (an 80-degree turn between two scans 3 s apart looks like a few degrees and a
  sideways step from there). Headings no turn reaches are left out: where a scan holds a
  handful of returns (a short-range Lidar among pillars), one turned half round can explain
  a point or two more by chance.

A match that still explains less than ``min_quality`` of the scan (no overlap with the map:
the car was carried off, a scan of a new room through a door) is kept as the best there is
and *flagged*: the scan's index goes to the estimator's ``poor_matches``. Whichever search
placed it (or where it explains less than ``CHECKED_BELOW`` of the scan), the match is then
checked against the scan's match to the previous scan
(:mod:`estimators.odometry.scan_check`): the widest windows are where a wrong pose explains a
few points more than the right one. After a long blind stretch the match is placed anew
along the direction it pins least, or the guess is kept and the scan flagged lost
(:mod:`estimators.odometry.blind_resume`); where every heading was searched, a placement
turning the car more than a quarter turn from the guess is flagged lost too (a place
symmetric under a half turn fits as well as the car turned round).

Over skipped scans the far-apart prior weakens the whole constant-velocity guess,
heading with position: a heading held as firmly as over one scan against a position held by next to
nothing pulls ICP along whatever direction the scan leaves free (along a gently curving
corridor, a turn is a move along it).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Sized

import numpy as np
from numpy.typing import NDArray

from estimators.health import BLIND_STRETCH, CLOCK_JUMP_FACTOR, Health, intervals_since_used
from estimators.matching.correlative import correlative_search
from estimators.matching.icp import ICPParams, MatchResult, register
from estimators.matching.point_to_line import PointToLineReference
from estimators.odometry.blind_resume import resumed_match
from estimators.odometry.gap_match import across_gap
from estimators.odometry.global_search import GlobalSearch, SearchWindow
from estimators.odometry.motion_prior import ScanClock, one_turn_increment
from estimators.odometry.moving_points import MovingPointFilter
from estimators.odometry.scan_check import check_against_scan
from lidar_env.core.se2 import compose, relative_floats, wrap_angle

FloatArray = NDArray[np.float64]
#: The share of car-frame points (M, 2) that a car pose (3,) puts in space the last scans saw
#: as free (:meth:`~estimators.odometry.moving_points.MovingPointFilter.seen_free_share`).
SeenFree = Callable[[FloatArray, FloatArray], float]

#: Map matches from the guess (no search) explaining at least this share of their scan are not
#: checked against the previous scan: the check replaces a match only where the scan-to-scan
#: match explains at least as much of its scan. Over the first 3000 scans of ACES and of Intel
#: and the fast-turn drives (``benchmarks/bench_fast_turns.py``) it replaced no match at all,
#: and checking every scan took a quarter of the CPU.
CHECKED_BELOW = 0.9

def reach_window(max_speed: float, max_turn_rate: float, interval: float,
                 typical: float) -> SearchWindow:
    """Every pose reachable since the last scan: ``max_speed`` [m/s] and ``max_turn_rate``
    [rad/s] times the larger of the scan ``interval`` and the ``typical`` one [s] (a stamp
    that glitches short must not shrink the window; a non-finite one counts as typical)."""
    dt = max(interval if math.isfinite(interval) else 0.0,
             typical if math.isfinite(typical) else 0.0)
    return SearchWindow(max_speed * dt, min(max_turn_rate * dt, np.pi))


def one_turn_start(pose: FloatArray, step: FloatArray, intervals: float) -> FloatArray:
    """Where the car is after ``intervals`` scan intervals (> 1: scans skipped or lost) from
    ``pose`` (3,) if it kept the speed and direction of its last per-interval ``step`` (3,)
    but turned only once: over a gap the extrapolated turn is the least known part of the
    guess (a car weaving down a corridor has turned back by the time the scans return)."""
    return compose(pose, one_turn_increment(step, intervals))


def far_apart(increment: FloatArray, keyframe_distance: float, turn_window: float) -> bool:
    """Whether scans come far apart: the predicted increment (3,) per scan moves the car at
    least a keyframe spacing ``keyframe_distance`` [m], or turns it by at least
    ``turn_window`` [rad], the fallback's heading window: the change of turn rate a
    constant-velocity guess is trusted with. (Turning on the spot at 6 Hz, ACES's robot
    turns up to 20 deg per scan, which ICP from the guess follows.)"""
    return bool(np.hypot(increment[0], increment[1]) >= keyframe_distance
                or abs(increment[2]) >= turn_window)


def far_match(
    search: GlobalSearch, reference: PointToLineReference, points: FloatArray,
    guess: FloatArray, window: SearchWindow, params: ICPParams,
    prior_information: FloatArray, seen_free: SeenFree | None = None,
    min_quality: float = 0.5, near_starts: tuple[FloatArray, ...] = (),
) -> MatchResult:
    """ICP of ``points`` from the guess and from the branch-and-bound's best pose in
    ``window`` around it, both held by the weak prior ``prior_information`` (3,) at ``guess``.

    The result explaining the larger share of the points wins (a tie: the search's; where
    neither explains a point, the guess's, unless the search's pose itself scored
    ``min_quality``: then ICP from it failed, not the scan, and the near half is searched
    as below). Keeping
    the guess's result unless the search's explained more by the count's own noise (one
    standard error of the share), on the grounds that along a corridor's axis every pose
    scores about the same, is worse: the guess is as lost as the search there once one step
    went wrong.

    Where the search's pose turns the car into the far half of the heading window, the near
    half is searched too, and its match is kept when it explains as many points within the
    share's standard error: a stretch of corridor seen turned round (or any place symmetric
    under a half turn) fits the scan as well, and of two such poses the one the car reaches
    by the smaller turn from the guess is the likelier (after 3 s of blind scans the window
    holds every heading). ICP from each of ``near_starts`` (poses (3,), each another guess,
    the prior held at it) competes with the near half's match. A near match is kept too
    where it explains at least ``min_quality`` of the points and puts no larger share of them
    (within the same error) in space the last scans saw as free (``seen_free(points,
    pose)``): the points it leaves unexplained lie beyond the map, not against it. The true
    pose at the end of a blind stretch looks past the mapped part of a corridor, and
    explains less of its scan than the corridor seen turned round, which the map covers
    whole."""
    from_guess = register(reference, points, guess, params, guess, prior_information)
    found = search.search(points, guess, window)
    if not found.found:
        return from_guess
    from_search = register(reference, points, found.pose, params, guess, prior_information)
    if from_search.quality == from_guess.quality == 0.0 and found.score < min_quality:
        return from_guess  # a handful of returns beyond the map: every pose scores nothing
    best = from_search if from_search.quality >= from_guess.quality > 0.0 or (
        from_search.quality > from_guess.quality) else from_guess
    if abs(wrap_angle(found.pose[2] - guess[2])) <= 0.5 * window.angular:
        return best
    near = search.search(points, guess, SearchWindow(window.linear, 0.5 * window.angular))
    if not near.found:
        return best
    options = [register(reference, points, near.pose, params, guess, prior_information)] + [
        register(reference, points, start, params, start, prior_information)
        for start in near_starts]
    options = [option for option in options
               if abs(wrap_angle(option.pose[2] - guess[2])) <= 0.5 * window.angular] or options[:1]
    tie = max(np.sqrt(best.quality * (1.0 - best.quality) / len(points)), 1.0 / len(points))
    as_good = [option for option in options if option.quality >= best.quality - tie]
    if as_good:
        chosen = max(as_good, key=lambda option: option.quality)
        return chosen if chosen.quality > 0.0 else best
    if seen_free is None:
        return best
    against_best = seen_free(points, best.pose) + tie
    uncontradicted = [(free, -option.quality, k, option) for k, option in enumerate(options)
                      if option.quality >= min_quality
                      and (free := seen_free(points, option.pose)) <= against_best]
    return min(uncontradicted)[3] if uncontradicted else best


def fallback_match(
    search: GlobalSearch, reference: PointToLineReference, points: FloatArray,
    guess: FloatArray, near: SearchWindow, turn: float, far: SearchWindow | None,
    params: ICPParams, min_quality: float,
) -> MatchResult:
    """The best-explaining ICP match of ``points`` from correlative searches around ``guess``
    in ever wider windows, until one explains ``min_quality`` of the points: exhaustive
    (:func:`~estimators.matching.correlative.correlative_search`) in the ``near`` window,
    then over headings up to ``turn`` [rad] either side at its translations (skipped when
    the near window covers them), then (if given) branch-and-bound in the ``far`` window."""
    best: MatchResult | None = None
    wide = SearchWindow(near.linear, min(turn, np.pi)) if turn > near.angular else None
    for window in (near, wide, far):
        if window is None:
            continue
        if window is far:
            start = search.search(points, guess, window).pose
        else:
            start, _ = correlative_search(search.field, points, guess, window.linear,
                                          window.angular)
        result = register(reference, points, start, params)
        if best is None or result.quality > best.quality:
            best = result
        if best.quality >= min_quality:
            break
    assert best is not None
    return best


class FarScanMatching:
    """The matching step of :class:`~estimators.odometry.local_map.LocalMapOdometry`, a mixin:
    ICP from the guess, from the far-apart search, or through the fallback. It reads the
    front end's settings (``params``, ``min_quality``, ``keyframe_*``, ``max_speed``,
    ``max_turn_rate``, ``search_*``, ``noise_sigma``, ``prior_sigma_translation``,
    ``prediction_acceleration``) and state (``_reference``, ``_search``, ``_clock``)."""

    params: ICPParams
    min_quality: float
    keyframe_distance: float
    max_speed: float
    max_turn_rate: float
    search_linear_window: float
    search_angular_window: float
    search_resolution: float
    noise_sigma: float
    prior_sigma_translation: float
    prediction_acceleration: float
    _reference: PointToLineReference | None
    _search: GlobalSearch | None
    _clock: ScanClock
    _far_steps: deque[tuple[float, float]]  # the last few steps' lengths [m] and turns [rad]
    _prior_information: FloatArray
    _poses: list[FloatArray]
    _prediction_information: Callable[[], FloatArray]
    fallbacks: int
    far_searches: int
    scan_corrections: int
    _previous_scan: tuple[int, FloatArray] | None  # the last matched scan: (index, points)
    poor_matches: list[int]
    skipped_before: int
    clock_jumped: bool
    match_information: FloatArray
    _moving: MovingPointFilter | None
    _velocity: FloatArray  # car frame, per scan or per second (use_timestamps)
    use_timestamps: bool
    health: Health
    _observations: Sized  # the observations so far (the next one's index: its length)

    def _checked_against_scan(self, result: MatchResult, points: FloatArray, guess: FloatArray,
                              predicted: FloatArray, searched: bool) -> MatchResult:
        """``result`` checked against the match of ``points`` to the previous scan's
        (:mod:`estimators.odometry.scan_check`) where a search placed it (``searched``) or it
        explains less than :data:`CHECKED_BELOW` of the scan; counted in ``scan_corrections``
        when the check replaced it. Keeps ``points`` as the next scan's previous one."""
        assert self._reference is not None
        index = len(self._poses)
        previous = self._previous_scan
        previous_points = previous[1] if previous is not None and previous[0] == index - 1 else None
        self._previous_scan = (index, points)
        if not searched and result.quality >= CHECKED_BELOW:
            return result
        checked = check_against_scan(
            result, self._reference, points, previous_points, self._poses[-1], predicted,
            self.params, guess, self.match_information, self.min_quality)
        self.scan_corrections += checked.replaced
        return checked.result

    def _global_search(self) -> GlobalSearch:
        assert self._reference is not None
        if self._search is None:
            self._search = GlobalSearch(self._reference.points, self.search_resolution)
        return self._search

    def _far_prior(self, window: SearchWindow, missed: bool) -> FloatArray:
        """Prior information (3,) of a constant-velocity guess over the window's interval
        ``dt``: its position good to ``prediction_acceleration * dt^2`` (never better than
        ``prior_sigma_translation``); where scans were ``missed`` (skipped: a blind Lidar) its
        heading weakened by the same factor (module docstring), else as firm as the ordinary
        per-scan prior holds it (over a clock gap, whose stamp may have jumped alone, and over
        a slow or bursty clock's longer interval, it holds: Intel's 1 s relations 0.0303 m
        with it, 0.0314 m weakened there too)."""
        dt = window.linear / self.max_speed
        sigma = max(self.prediction_acceleration * dt**2, self.prior_sigma_translation)
        information = self._prior_information.copy()
        information[:2] = (self.noise_sigma / sigma) ** 2
        if missed:
            information[2] *= (self.prior_sigma_translation / sigma) ** 2
        return information

    def _slow_clock(self, typical: float) -> bool:
        """Whether over the clock's typical interval (the median of the last ones, else
        ``typical`` [s]) the constant-velocity guess can miss by more than the weakest prior
        the ordinary path allows (scans 4 Hz and slower)."""
        clock = self._clock.median if self._clock.settled else typical
        return self.prediction_acceleration * clock**2 > self.prior_sigma_translation

    def _match(self, points: FloatArray, guess: FloatArray, predicted: FloatArray,
               interval: float) -> MatchResult:
        """The registration of ``points`` (M, 2, car frame) near ``guess`` (3,), the car
        having moved ``predicted`` (3,) over the scan ``interval`` [s] if its velocity held.
        ``match_information`` is left at the motion prior the match was held by (the weak
        far-apart one where the scans came far apart), for any later registration of the
        scan to use."""
        assert self._reference is not None
        typical = self._clock.typical_step if self._clock.steps else interval
        window = reach = reach_window(self.max_speed, self.max_turn_rate, interval, typical)
        intervals = intervals_since_used(self.skipped_before, self.clock_jumped, interval,
                                         typical)
        if self._far_steps:  # a stalled clock does not mean the car drove or turned further
            longest = max(length for length, _ in self._far_steps)
            sharpest = max(turn for _, turn in self._far_steps)
            window = SearchWindow(
                min(window.linear,
                    2.0 * longest * intervals + self.params.max_correspondence_distance),
                min(window.angular, 2.0 * sharpest * intervals + self.search_angular_window))
        # A guess worse than the weakest prior the ordinary path allows (slow scans: 4 Hz and
        # below), a predicted step of a keyframe spacing, or scans skipped or lost since the
        # last one used: scans far apart. (Lost: a clock gap of CLOCK_JUMP_FACTOR typical
        # intervals or more; bursty stamps, as Intel's, jump by less at most scans.)
        lost = self.clock_jumped and intervals >= CLOCK_JUMP_FACTOR
        if self.skipped_before or lost or self._slow_clock(typical) or far_apart(
                predicted, self.keyframe_distance, self.search_angular_window):
            self.far_searches += 1
            searched = True
            missed = bool(self.skipped_before)
            self.match_information = self._far_prior(window, missed)
            seen_free = None if self._moving is None else self._moving.seen_free_share
            step = self._velocity * (typical if self.use_timestamps else 1.0)
            starts = (one_turn_start(self._poses[-1], step, intervals),) if (
                intervals > 1) else ()
            result = far_match(self._global_search(), self._reference, points, guess, window,
                               self.params, self.match_information, seen_free,
                               self.min_quality, starts)
            if result.quality < self.min_quality and window.angular < np.pi:
                self.fallbacks += 1
                retry = far_match(self._global_search(), self._reference, points, guess,
                                  SearchWindow(window.linear, np.pi), self.params,
                                  self.match_information, seen_free, self.min_quality,
                                  starts)
                result = retry if retry.quality > result.quality else result
            if lost and starts and not self.skipped_before:
                result = across_gap(self._reference, points, result, guess, starts[0],
                                    intervals, float(np.hypot(step[0], step[1])), self.params,
                                    self.match_information)
            if self.skipped_before >= BLIND_STRETCH:
                resumed, lost = resumed_match(self._global_search(), self._reference, points,
                                              guess, result, window.linear, self.params,
                                              self.min_quality)
                if resumed is not None:  # placed anew: the guess holds no direction
                    self.match_information, result = np.zeros(3), resumed
                # with every heading in the window, a placement nearer the half turn than
                # the guess's heading is as likely a place symmetric under a half turn (a
                # corridor seen turned round) as a car that turned round blind
                if lost or (window.angular >= np.pi and abs(
                        wrap_angle(result.pose[2] - guess[2])) > 0.5 * np.pi):
                    self.health.note_lost(len(self._observations))
        else:
            self.match_information = self._prediction_information()
            result = register(self._reference, points, guess, self.params, guess,
                              self.match_information)
            searched = result.quality < self.min_quality
            if searched:
                self.fallbacks += 1
                near = SearchWindow(self.search_linear_window, self.search_angular_window)
                # headings the car can reach: its turn rate may have changed by up to twice
                # the fastest turn over the interval (a turn the other way at full rate); the
                # reach itself, not held to the last steps' turns (a car at rest may turn)
                retry = fallback_match(self._global_search(), self._reference, points, guess,
                                       near, 2.0 * reach.angular,
                                       window if window.linear > near.linear else None,
                                       self.params, self.min_quality)
                result = retry if retry.quality > result.quality else result
        result = self._checked_against_scan(result, points, guess, predicted, searched)
        if result.quality < self.min_quality:
            self.poor_matches.append(len(self._poses))
        step = relative_floats(self._poses[-1].tolist(), result.pose.tolist())
        self._far_steps.append((float(np.hypot(step[0], step[1])), abs(step[2])))
        return result
