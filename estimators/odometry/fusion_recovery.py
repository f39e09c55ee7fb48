"""Where ``pc_fusion`` looks for the car after scans it could not use or never got: blind
scans skipped, or a clock jump (scans lost on the way, or only the stamp jumped). Times [s].

Past the prediction horizon a constant-velocity guess over the whole gap is no better known
than one over a single interval: the car may have kept its speed (scans lost or blind while it
drove on) or the stamp alone may have jumped (scans kept coming). Both are matched and the
one whose matches explain more of the scans is kept (the longer guess turns the car by one
interval's turn only: over seconds the extrapolated turn is the least known part of it, and
the correlation measures the turn). Where both explain the scans alike, each match stays at
its guess along what the scans leave free (a corridor's axis, which the prior decides), and
the directions they pin say which guess was right: after a clock jump the longer guess wins
where it predicted its match better than the one-interval guess did its own (a car weaving
down a corridor has crossed it by every interval's sideways motion;
:func:`likelier_longer`). After skipped scans, which prove the time passed, it wins where its
matches explain the scans within the share's standard error of the other's (down a corridor
the keyframe saw more of near itself, a stopped car's match explains a few percent more).

After skipped scans (a blinded Lidar) where both scans hold enough points, a third start is
the exact best pose of a branch-and-bound search of the new scan on the latest keyframe's
points over the poses the car can have reached (:meth:`BlindScans.searched`, the ``icp``
estimator's :func:`~estimators.matching.scan_recovery.search_start`): the car may have turned
or stopped while blind, out of reach of either guess. It runs where neither guess's matches
explain half of the scans, and is kept where its matches explain clearly more. After a blind
stretch the kept match is judged by the space the new scans see free: placed short of the car
along a corridor, whose walls it fits as well or better, they see through the walls the car
drove past, and the match starts again from the place that sees through the fewest
(:func:`~estimators.matching.scan_recovery.off_seen_through`). A kept match that explains
under a quarter of the new scans stands, but the car is reported lost (:meth:`BlindScans.unplaced`).

Either guess may be a metre or more from the car after a turn, and the correlation that seeds
the matches is ambiguous across such a gap (it may land a metre off too); a few ICP
iterations from there stop short of the fit. So the kept motion is matched again from itself
(:func:`recovered`) while that explains more of the scans: each round starts closer.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from estimators.health import BLIND_STRETCH
from estimators.matching.scan_recovery import (
    MIN_SEARCH_POINTS,
    UNPLACED_BELOW,
    lost_after_blind,
    lost_scan_surprise,
    off_seen_through,
    reach,
    search_starts,
    within_reach,
)
from estimators.matching.seen_through import seen_through_count
from lidar_env.core.se2 import transform_points

#: A car motion (3,) from the latest keyframe, its edges and their mean share explained.
Solution = tuple[NDArray[np.float64], Any, float]

#: Two candidate motions whose matches explain shares of the scans within this of each other
#: are equally good fits (``rotation_pc.QUALITY_TOLERANCE``'s reading of a share).
SCORE_TOLERANCE = 0.02


#: Most rounds of matching a recovered motion again from itself (each converges further;
#: two or three reach the fit).
POLISH_ROUNDS = 5
#: Mean share of the scans explained below which the guesses' matches are lost and the search
#: runs (``lidar_odometry``'s ``min_quality``): where the guesses fit, a search over a
#: corridor finds a place along it that explains a little more because the keyframe saw
#: more of it.
POOR_SCORE = 0.5


@dataclass
class BlindScans:
    """The points (N, 2) and (M, 2) of the latest keyframe's and the new scans on the car
    (each sensor's ``PreparedScan.points`` moved by its mount; the keyframe's car frame and
    the new one's), after a gap of ``intervals`` scan intervals and ``seconds`` [s] in which
    the car is guessed to have moved ``guess`` (3,, from the keyframe)."""

    reference: NDArray[np.float64]
    query: NDArray[np.float64]
    guess: NDArray[np.float64]
    intervals: float
    seconds: float

    @classmethod
    def of(cls, mounts: Sequence[NDArray[np.float64]], keyframe_scans: Sequence[Any],
           scans: Sequence[Any], guess: NDArray[np.float64], intervals: float,
           seconds: float) -> BlindScans:
        reference, query = (np.concatenate([transform_points(mount, scan.points) for mount, scan
                                            in zip(mounts, prepared, strict=True)])
                            for prepared in (keyframe_scans, scans))
        return cls(reference, query, guess, intervals, seconds)

    def searched(self) -> list[NDArray[np.float64]]:
        """The car motions (3,) from the keyframe the search finds around the guess
        (:func:`~estimators.matching.scan_recovery.search_starts`: turned little, and turned
        further where the gap allows); none with too few points on either side."""
        if min(len(self.reference), len(self.query)) < MIN_SEARCH_POINTS:
            return []
        return search_starts(self.reference, self.query, self.guess, self.intervals,
                             self.seconds)

    def within_reach(self, found: Solution) -> bool:
        """Whether ``found``'s motion lies within the guess's reach over the gap
        (:func:`~estimators.matching.scan_recovery.within_reach`)."""
        return within_reach(found[0], self.guess, self.intervals, self.seconds)

    def likelier(self, other: Solution, found: Solution) -> bool:
        """Whether ``other`` is likelier than ``found``: within reach where ``found`` is not,
        else, both alike in reach, explaining clearly more of the scans."""
        near, far = self.within_reach(other), self.within_reach(found)
        return (near and not far) or (near == far and other[2] > found[2] + SCORE_TOLERANCE)

    def share_error(self, share: float) -> float:
        """The standard error of a ``share`` of the new scans' points explained, at least
        :data:`SCORE_TOLERANCE`: two matches explaining shares within it fit alike."""
        return max(SCORE_TOLERANCE, math.sqrt(share * (1.0 - share) / max(len(self.query), 1)))

    def seen_through(self, motion: NDArray[np.float64]) -> int:
        """Keyframe points the new scans see through with the car moved ``motion`` (3,)."""
        return seen_through_count(self.reference, self.query, motion)

    def lost(self, found: Solution) -> bool:
        """Whether ``found`` leaves the car lost
        (:func:`~estimators.matching.scan_recovery.lost_after_blind` of its matches' mean
        share and the keyframe points the new scans see through there)."""
        return lost_after_blind(found[2], self.seen_through(found[0]))

    def unplaced(self, share: float) -> bool:
        """Whether a match explaining ``share`` of the new scans after a blind stretch leaves
        the car's place unknown, though it stands as the best the scans give
        (:data:`~estimators.matching.scan_recovery.UNPLACED_BELOW`)."""
        return self.intervals > BLIND_STRETCH and share < UNPLACED_BELOW

    def off_seen_through(self, match_from: Callable[[NDArray[np.float64]], Solution],
                         found: Solution) -> tuple[Solution, int]:
        """``found`` or the match from a place whose new scans see through fewer keyframe
        points, within the search's reach
        (:func:`~estimators.matching.scan_recovery.off_seen_through`), and the count."""
        linear, _ = reach(self.guess, self.intervals, self.seconds)
        return off_seen_through(match_from, found, lambda solution: (solution[0], solution[2]),
                                self.reference, self.query, linear)[:2]


def likelier_longer(found: Solution, other: Solution, guess: list[float], longer: list[float],
                    intervals: float, step_to: Callable[[NDArray[np.float64]], list[float]]
                    ) -> bool:
    """Whether ``other``, matched from the ``longer`` guess over ``intervals`` scan intervals,
    is likelier than ``found``, matched from the one-interval ``guess`` (both car frame, from
    the last pose used; ``step_to`` turns a solution's motion into one), where they explain
    the scans alike: its guess predicted it better
    (:func:`~estimators.matching.scan_recovery.lost_scan_surprise` in units of the guess's
    step). Along a direction the scans leave free (a corridor's axis) each match stays at its
    guess; the directions they pin tell lost scans from a stamp that jumped alone."""
    step = math.hypot(guess[0], guess[1])
    return (lost_scan_surprise(np.array(step_to(other[0])), np.array(longer), intervals, step)
            < lost_scan_surprise(np.array(step_to(found[0])), np.array(guess), 1.0, step))


def recovered(solve: Callable[[list[float]], Solution], found: Solution, guess: list[float],
              longer: list[float], intervals: float, skipped: bool,
              step_to: Callable[[NDArray[np.float64]], list[float]],
              blind: BlindScans | None = None) -> tuple[Solution, bool]:
    """The motion found after scans lost or skipped: ``found`` (matched from the one-interval
    ``guess``) or the match from the ``longer`` guess over ``intervals`` (car frame, from the
    last pose used) where it explains more of the scans, or as much after ``skipped`` scans
    or where its guess predicted it better (:func:`likelier_longer`); where neither explains
    :data:`POOR_SCORE` of the scans, the match from the motion the ``blind`` scans' search
    finds (None: no search) where it explains clearly more. After a blind stretch (more
    than :data:`~estimators.health.BLIND_STRETCH` intervals), where the new scans see
    through keyframe points from there (placed short of the car, the walls it drove past),
    the match from a place that sees through fewer (:meth:`BlindScans.off_seen_through`).
    Then matched again from itself (``step_to``: a motion from the keyframe as a guess from
    the last pose used) while that explains more and sees through no more. ``solve``: the
    matches from a guess. Also whether the motion found after a blind stretch leaves the car
    lost (:meth:`BlindScans.lost`): the scans cannot tell where it is, and the guess stands."""
    other = solve(longer)
    tie = SCORE_TOLERANCE if blind is None else blind.share_error(found[2])
    if other[2] > found[2] + SCORE_TOLERANCE or (other[2] >= found[2] - tie and (
            skipped or likelier_longer(found, other, guess, longer, intervals, step_to))):
        found = other
    if blind is not None and (found[2] < POOR_SCORE or not blind.within_reach(found)):
        for searched in blind.searched():  # turned further only where still poor or far
            other = solve(step_to(searched))
            if blind.likelier(other, found):
                found = other
            if found[2] >= POOR_SCORE and blind.within_reach(found):
                break
    seen = 0
    if blind is not None and blind.intervals > BLIND_STRETCH:
        found, seen = blind.off_seen_through(lambda place: solve(step_to(place)), found)
    for _ in range(POLISH_ROUNDS):
        again = solve(step_to(found[0]))
        if not again[2] > found[2] or (
                blind is not None and blind.seen_through(again[0]) > seen):
            break
        found = again
    return found, blind is not None and blind.intervals > BLIND_STRETCH and blind.lost(found)
