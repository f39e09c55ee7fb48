"""Where the ``icp`` estimator looks for the car after scans it could not use (a blinded Lidar)
or never got (a clock gap): starting guesses beyond its constant-velocity one.

Over a gap of ``n`` scan intervals the guess ``n x`` the last increment extrapolates the last
turn rate for the whole gap, the least known part of it: a car that turned 45 degrees while
blind, or stopped turning, lies outside ICP's basin from there. Two more starts cover it: the
translation extrapolated with one interval's turn, and the exact best pose of a multi-
resolution branch-and-bound correlative search (Olson 2009; Hess et al. 2016) of the new scan
on the likelihood grid of the last one used, over every pose the car can have reached
(:func:`reach`) turned at most :data:`MAX_SEARCH_TURN` from the guess, and after skipped
scans also over every turn the gap allows (:func:`search_starts`: a robot that stopped and
turned into a side corridor). Of the matches from all starts within the motion model's reach
(:func:`within_reach`), :func:`most_likely_match` keeps the one explaining clearly more of
the scan, else the one the motion model finds least surprising (:func:`lost_scan_surprise`);
one turned past the near window only where none within it explains half the scan. After
skipped scans, where the kept match has the new scan see through the last one's points
(placed short of the car along a corridor, which fits its walls as well, it sees through the
walls the car drove past), it is matched again from the place that sees through the fewest
and still explains the scan (:func:`off_seen_through`). Poses are in the last used scan's
car frame: x [m] forward, y [m] left, heading [rad].
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TypeVar

import numpy as np
from numpy.typing import NDArray

from estimators.matching.match_result import MatchResult
from estimators.matching.scan_matching import LikelihoodField
from estimators.matching.seen_through import (
    SEEN_THROUGH_SLACK,
    seen_through_count,
    seen_through_counts,
)
from estimators.matching.window_search import search_in_box, thinned_for_search

FloatArray = NDArray[np.float64]

#: Grid cell [m] of the search: the translation step it lands within, well inside ICP's basin.
SEARCH_RESOLUTION = 0.05
#: Turn [rad] the car may add per scan interval beyond the one it held (ACES's robot turns up
#: to 20 degrees a scan on the spot at 6 Hz).
TURN_PER_INTERVAL = math.radians(20.0)
#: Slack [m] of the search window beyond the distance the guess extrapolates.
REACH_MARGIN = 0.5
#: Acceleration [m/s^2] the car may have held over the gap beyond the speed it had (the
#: ``lidar_odometry`` motion model's): a robot that turned on the spot drives off.
ACCELERATION = 0.5
#: Most [m] the acceleration widens the window by: over a gap of seconds a wider one holds
#: places elsewhere that explain more of a scan-to-scan match than the right one.
MAX_SPEED_CHANGE_REACH = 1.0
#: [rad] the near search turns the car at most this far from the guess: matched to the last
#: scan alone, with no map to tell the space it saw free from space it never saw, a corridor
#: seen turned round fits the new scan as well as the way the car faces, and better where the
#: last scan saw more of it (the fault matrix's hallway after 3 s blind: 29 m off). Farther
#: turns are searched apart and believed only where the near window holds no fit.
MAX_SEARCH_TURN = 0.5 * math.pi


def turn_between(heading: float, other: float) -> float:
    """[rad] in ``[0, pi]``: how far ``heading`` [rad] lies from ``other`` [rad] either way."""
    return abs(math.remainder(heading - other, 2.0 * math.pi))


def one_turn_guess(increment: FloatArray, intervals: float) -> FloatArray:
    """The last per-interval ``increment`` (3,) over ``intervals`` with its turn taken once:
    the car kept its speed and direction and the gap's turn is left to the match."""
    guess = increment * intervals
    guess[2] = increment[2]
    return guess


def reach(guess: FloatArray, intervals: float, seconds: float,
          max_turn: float = MAX_SEARCH_TURN) -> tuple[float, float]:
    """The search window ``(linear [m], angular [rad])`` around ``guess`` (3,) after a gap of
    ``intervals`` scan intervals and ``seconds`` [s]: as far again as the guess moves the car
    (it may have stopped, or turned off the line), plus what :data:`ACCELERATION` adds over
    the gap (at most :data:`MAX_SPEED_CHANGE_REACH`) and :data:`REACH_MARGIN`;
    :data:`TURN_PER_INTERVAL` per interval either side, at most ``max_turn``."""
    return (float(np.hypot(guess[0], guess[1]))
            + min(0.5 * ACCELERATION * seconds**2, MAX_SPEED_CHANGE_REACH) + REACH_MARGIN,
            min(TURN_PER_INTERVAL * intervals, max_turn))


def search_start(reference_points: FloatArray, query_points: FloatArray, guess: FloatArray,
                 intervals: float, seconds: float,
                 max_turn: float = MAX_SEARCH_TURN) -> FloatArray | None:
    """The best pose (3,) of ``query_points`` (M, 2, their car frame) on the likelihood grid
    of ``reference_points`` (N, 2, the last used scan's car frame) within :func:`reach` of
    ``guess`` (3,), turned at most ``max_turn`` [rad], or None when nothing scores above
    :data:`~estimators.matching.window_search.MIN_SEARCH_SCORE`."""
    thinned = thinned_for_search(query_points)
    linear, angular = reach(guess, intervals, seconds, max_turn)
    low = reference_points.min(axis=0) - 0.5
    high = reference_points.max(axis=0) + 0.5
    found = search_in_box(reference_points, low, high, thinned, guess, linear, angular,
                          SEARCH_RESOLUTION)
    return found.pose if found.found else None


def search_starts(reference_points: FloatArray, query_points: FloatArray, guess: FloatArray,
                  intervals: float, seconds: float, blind: bool = True) -> list[FloatArray]:
    """The starts :func:`search_start` gives after a gap: its best pose turned at most
    :data:`MAX_SEARCH_TURN` from ``guess`` (3,) and, after ``blind`` scans (skipped: the
    time passed, the car unseen; a clock gap may be a stamp that jumped alone) where the car
    can have turned further (:data:`TURN_PER_INTERVAL` per interval, a half turn at most
    either way), its best over every such turn where that lies beyond: a robot that stopped
    and turned into a side corridor while blind. Of the two, a corridor seen turned round by
    the near one is told from the turn by :func:`most_likely_match` (share explained, and
    reach)."""
    near = search_start(reference_points, query_points, guess, intervals, seconds)
    starts = [] if near is None else [near]
    if not blind or TURN_PER_INTERVAL * intervals <= MAX_SEARCH_TURN:
        return starts
    wide = search_start(reference_points, query_points, guess, intervals, seconds, math.pi)
    if wide is not None and turn_between(float(wide[2]), float(guess[2])) > MAX_SEARCH_TURN:
        starts.append(wide)
    return starts


#: Share of points a match from the guess over a clock gap's every interval must explain
#: beyond the one-interval match's to be taken (a stamp that jumped while the scans ran on
#: fits the one-interval guess as well or better).
LOST_SCANS_MARGIN = 0.05


def lost_scan_surprise(pose: NDArray[np.float64], guess: NDArray[np.float64], intervals: float,
                       step: float) -> float:
    """How far a match ``pose`` (3,) lands from its constant-velocity ``guess`` (3,) per scan
    interval of the ``intervals`` the guess spans: its turn off the guess [rad] plus its
    translation off it in units of the last ``step`` [m] (at least 5 cm). Of two matches of
    a clock gap that explain the scan alike, the one the motion model finds less surprising
    is the likelier: a one-interval guess that has to turn 40 degrees more, or a whole-gap
    guess that has to undo its extrapolated turn, says which of the two it was."""
    off = pose - guess
    turn = turn_between(float(off[2]), 0.0)
    return (turn + math.hypot(float(off[0]), float(off[1])) / max(step, 0.05)) / intervals


#: Fewest points on each scan for the search after a gap (a pillar or two of a short-range
#: Lidar fit anywhere: TurtleBot drives through sparse halls, 10-30 returns a scan, drifted
#: 1.6 -> 23 % with it, ``benchmarks/bench_sparse_halls.py``).
MIN_SEARCH_POINTS = 50


#: Share of its scan the kept match after a blind stretch explains below which the car may
#: be lost (``lidar_odometry``'s ``min_quality``).
LOST_BELOW = 0.5
#: Share of the scan below which the match kept after a blind stretch is reported lost
#: whatever it sees through (its pose stands, as the best the scans give): at the car's place
#: a match explains about the share of the scan the last one saw too, and under a quarter is
#: too little of the scan to tell the place (ACES from scan 6000 after 100 blind scans: 12 %
#: explained 9 m off the car, a sixth of the scan seen).
UNPLACED_BELOW = 0.25


def within_reach(pose: FloatArray, guess: FloatArray, intervals: float, seconds: float) -> bool:
    """Whether ``pose`` (3,) lies within the translation :func:`reach` allows around ``guess``
    (3,) after ``intervals`` scan intervals and ``seconds`` [s]: farther, the car would have
    had to speed up beyond :data:`ACCELERATION` to get there."""
    return bool(np.hypot(*(pose[:2] - guess[:2])) <= reach(guess, intervals, seconds)[0])


def most_likely_match(results: list[MatchResult], guesses: list[NDArray[np.float64]],
                      spans: list[float], step: float, points: int,
                      seconds: float | None = None) -> int:
    """Index of the match in ``results`` to keep, each judged against the constant-velocity
    ``guesses[k]`` (3,) over ``spans[k]`` scan intervals: of those explaining within
    :data:`LOST_SCANS_MARGIN` of the largest share of the scan's ``points`` (or within that
    share's standard error, where a scan of few points leaves it noisy), the one the motion
    model finds least surprising (:func:`lost_scan_surprise` with the last ``step`` [m]; the
    first on a tie). Given the gap's ``seconds`` [s], matches out of the guess's reach
    (:func:`within_reach`) are judged only where none is within (a corridor seen turned round
    fits a scan taken after a turn on the spot as well, metres down the corridor), and of
    those, matches turned more than :data:`MAX_SEARCH_TURN` off their guess only where none
    turned less explains :data:`LOST_BELOW` of the scan (the car turned out of the window a
    corridor's reversed view cannot enter)."""
    judged = list(range(len(results)))
    if seconds is not None:
        judged = [k for k in judged if within_reach(
            results[k].pose, guesses[k], spans[k], seconds)] or judged
        near = [k for k in judged if turn_between(
            float(results[k].pose[2]), float(guesses[k][2])) <= MAX_SEARCH_TURN]
        if any(results[k].quality >= LOST_BELOW for k in near):
            judged = near
    top = max(results[k].quality for k in judged)
    margin = max(LOST_SCANS_MARGIN, math.sqrt(top * (1.0 - top) / max(points, 1)))
    surprise = [lost_scan_surprise(r.pose, g, n, step) if k in judged and r.quality >= top - margin
                else math.inf
                for k, (r, g, n) in enumerate(zip(results, guesses, spans, strict=True))]
    return int(np.argmin(surprise))


#: [m] grid step of :func:`least_seen_through_place`: well inside a refinement's basin.
PLACE_STEP = 0.2
#: [m] reach and grid step of the place search that settles a match off a contradiction:
#: along a corridor a scan fits as well a few decimetres short of the car, where it still
#: sees through the last walls it passed.
SETTLE_REACH, SETTLE_STEP = 1.0, 0.05


def least_seen_through_place(reference_points: FloatArray, query_points: FloatArray,
                             pose: FloatArray, linear: float, step: float = PLACE_STEP,
                             slack: int = SEEN_THROUGH_SLACK) -> FloatArray:
    """The place (3,, ``pose``'s heading) within ``linear`` [m] of ``pose`` (3,) on a
    ``step`` [m] grid where ``query_points`` (M, 2) see through the fewest
    ``reference_points`` (N, 2; :func:`seen_through_counts`, within ``slack``), and of
    those the one whose points score highest on the
    reference's likelihood field (the ray consistency test of occupancy-grid matching: a
    place short of the car, which a corridor's walls fit as well, sees through the walls the
    car has driven past)."""
    steps = np.arange(-math.floor(linear / step), math.floor(linear / step) + 1)
    offsets = np.stack(np.meshgrid(steps, steps), axis=-1).reshape(-1, 2) * step
    offsets = offsets[np.hypot(offsets[:, 0], offsets[:, 1]) <= linear]
    poses = np.repeat(pose[None], len(offsets), axis=0)
    poses[:, :2] += offsets
    counts = seen_through_counts(reference_points, query_points, poses)
    free = poses[counts <= counts.min() + slack]
    field = LikelihoodField(reference_points, resolution=SEARCH_RESOLUTION)
    c, s = np.cos(free[:, 2]), np.sin(free[:, 2])
    x, y = query_points[:, 0], query_points[:, 1]
    placed = np.stack([free[:, :1] + c[:, None] * x - s[:, None] * y,
                       free[:, 1:2] + s[:, None] * x + c[:, None] * y], axis=-1)
    return free[int(np.argmax(field.score(placed).mean(axis=1)))].copy()


def lost_after_blind(quality: float, seen: int) -> bool:
    """Whether the match kept after a blind stretch leaves the car lost: it explains less
    than :data:`LOST_BELOW` of the scan (``quality``) and the scan sees through more than
    :data:`SEEN_THROUGH_SLACK` reference points there (``seen``): the car faces what the
    reference never saw (it turned towards it while blind), and the best placement is as
    likely metres off as right. A place driven into while blind explains as little but
    contradicts nothing."""
    return quality < LOST_BELOW and seen > SEEN_THROUGH_SLACK


Match = TypeVar("Match")

#: Least part of the share of the scan the match it replaces explains that a match from a
#: place seeing through fewer reference points must explain: short of the car along a
#: corridor a scan fits the walls about as well, or better where the reference saw more of
#: them (closed_to_open after 100 blind scans: 62 % short of the car, 50 % at it); a place
#: where it explains a fraction of that fits nothing (ACES after 3 s blind: 60 % -> 18 %)
#: and sees through little because it overlaps little.
SEEN_THROUGH_SHARE_KEPT = 0.5


def off_seen_through(match_from: Callable[[FloatArray], Match], found: Match,
                     judge: Callable[[Match], tuple[FloatArray, float]],
                     reference_points: FloatArray, query_points: FloatArray, linear: float
                     ) -> tuple[Match, int, FloatArray | None]:
    """``found`` or, where its place (``judge``: a match's pose (3,) and share of the scan
    explained) has ``query_points`` (M, 2) see through more than
    :data:`SEEN_THROUGH_SLACK` ``reference_points`` (N, 2), the match (``match_from`` a
    start pose) from :func:`least_seen_through_place` within ``linear`` [m] where that sees
    through clearly fewer and explains at least :data:`SEEN_THROUGH_SHARE_KEPT` of its share,
    settled from the place within :data:`SETTLE_REACH` that sees through the fewest exactly,
    on a finer grid, where that sees through no more and explains enough (the coarse grid's
    place, held along a corridor by the weak prior, lands up to a step off); with the count
    its place sees through and the start it was matched from (None: ``found``); ``found``
    where either side holds under :data:`MIN_SEARCH_POINTS`. A scan placed short of the car
    along a corridor fits its walls as well as at the car, and better where the reference saw
    more of them, but sees through the walls it has passed."""
    def seen(match: Match) -> int:
        return seen_through_count(reference_points, query_points, judge(match)[0])

    def explains(match: Match) -> bool:
        return judge(match)[1] >= SEEN_THROUGH_SHARE_KEPT * judge(found)[1]

    if min(len(reference_points), len(query_points)) < MIN_SEARCH_POINTS:
        return found, 0, None
    count = seen(found)
    if count <= SEEN_THROUGH_SLACK:
        return found, count, None
    start = least_seen_through_place(reference_points, query_points, judge(found)[0], linear)
    other = match_from(start)
    fewer = seen(other)
    if fewer + SEEN_THROUGH_SLACK >= count or not explains(other):
        return found, count, None
    near = least_seen_through_place(reference_points, query_points, judge(other)[0],
                                    SETTLE_REACH, SETTLE_STEP, 0)
    settled = match_from(near)
    least = seen(settled)
    return (settled, least, near) if least <= fewer and explains(settled) else (
        other, fewer, start)
