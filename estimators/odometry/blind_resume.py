"""Where ``lidar_odometry`` puts the car when its scans come back after a long blind stretch.

After :data:`~estimators.health.BLIND_STRETCH` scans or more skipped in a row, the
constant-velocity guess is worth next to nothing (a car weaving down a corridor for 10 s is
metres off it), and the far-apart search (:mod:`estimators.odometry.far_scans`) places the
scan wherever the local map explains most of it. Two things can go wrong there:

* **A free axis.** Down a corridor the map explains the scan about as well anywhere along its
  axis, where the far-apart match follows the guess. Only one place along it agrees with
  what the new scan sees, though: placed short of where the car is, the scan's beams pass
  through walls the map holds (the last metres of the corridor it has driven out of).
  :func:`along_least_pinned` moves the match along the direction it pins least, to where
  the scan sees through the fewest map points
  (:func:`~estimators.matching.seen_through.seen_through_counts`; the ray consistency
  test of occupancy-grid scan matching: a beam ending beyond a mapped surface says the
  surface is not where the pose puts it) and its points score as high as anywhere on the
  map's likelihood field. The two bound the place from either side: placed short, the scan
  sees through the walls' ends it passed, but only once its beams end
  :data:`~estimators.matching.seen_through.SEEN_THROUGH_MARGIN` behind them; placed past
  it, its points run off the mapped walls' ends and score less, a few points per step. The
  car lies between, and the middle of that run of places is the least far off whichever
  bound is the looser (past a corridor's open end, the nearest place free of contradiction
  is 0.1-0.3 m short of the car). Where the scan pins that direction with less than
  ``min_information`` points (a bare corridor), no place along it is evidence, though one
  nearer the mapped part scores a little higher: :func:`toward_guess` puts the car at the
  motion model's guess along it, where the scan sees through no more map points there.
* **No place explains the scan.** Where the best placement explains less than the front
  end's ``min_quality`` and the scan still sees through map points there, the car faces
  what the map never saw (it turned towards it while blind) and the placement is as likely
  metres off as right: the motion model's pose is kept and the scan is flagged lost
  (``Health.lost``), so a back end can look for the pose in its whole map. (A scan of a
  place half new, driven into while blind, explains as little, 15-35 %, but its placement
  sees through none of the map: it is kept.) Where the map contradicted the far-apart match
  and the better place along its line still explains less than ``min_quality``, that place
  is kept but the scan is flagged lost too: nothing vouches for it, and a wrong place whose
  walls lie beyond the scan's reach sees through nothing either.

Frames: map points in the world frame, scan points in the car frame. Distances [m], angles
[rad].
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from estimators.matching.icp import ICPParams, MatchResult, register
from estimators.matching.point_to_line import PointToLineReference
from estimators.matching.scan_matching import LikelihoodField
from estimators.matching.seen_through import (
    SEEN_THROUGH_SLACK,
    seen_through_count,
    seen_through_counts,
)
from estimators.odometry.global_search import GlobalSearch
from lidar_env.core.se2 import transform_points

FloatArray = NDArray[np.float64]

#: Places along the line compete on seen-through map points where their points score at
#: least this share of the best place's on the likelihood field (a place the scan sees
#: through nothing of, only because its points fall beyond the map, is no candidate; the
#: true place past a corridor's mapped end scores ~0.9 of the places short of it).
NEAR_BEST = 0.8


def least_pinned_direction(information: FloatArray | None) -> FloatArray:
    """The unit translation direction (2,) the match's information (3, 3) pins least
    (world frame); the x axis where it is unknown."""
    if information is None or not np.any(information[:2, :2]):
        return np.array([1.0, 0.0])
    _, vectors = np.linalg.eigh(information[:2, :2])
    return vectors[:, 0]


def free_direction(information: FloatArray | None, min_information: float
                   ) -> FloatArray | None:
    """The match's least pinned translation direction (2,, unit; :func:`least_pinned_direction`)
    where its ``information`` (3, 3) pins it less than ``min_information`` points squarely
    facing it do (the directions ICP leaves to a prior: a corridor's axis); else None."""
    if information is None:
        return None
    direction = least_pinned_direction(information)
    return direction if float(direction @ information[:2, :2] @ direction) < (
        min_information) else None


def along_least_pinned(field: LikelihoodField, map_points: FloatArray, points: FloatArray,
                       match: MatchResult, reach: float, step: float) -> FloatArray:
    """The pose (3,) on the line through ``match.pose`` along its least pinned direction,
    within ``reach`` [m] either side in ``step`` [m] steps, where the scan's ``points``
    (M, 2, car frame) see through the fewest ``map_points`` (N, 2, world) of the places
    scoring at least :data:`NEAR_BEST` of the best on ``field``, and of those the ones
    scoring highest (the mean score, within its standard error): the middle of the run of
    such places next to each other that holds the one nearest the match (module docstring).
    Only a contradiction moves the match: ``match.pose`` itself where the scan sees through
    at most :data:`SEEN_THROUGH_SLACK` map points more there."""
    direction = least_pinned_direction(match.information)
    offsets = np.arange(-np.floor(reach / step), np.floor(reach / step) + 1) * step
    poses = np.repeat(match.pose[None], len(offsets), axis=0)
    poses[:, :2] += offsets[:, None] * direction
    counts = seen_through_counts(map_points, points, poses)
    scores = np.array([float(field.score(transform_points(pose, points)).mean())
                       for pose in poses])
    candidates = scores >= NEAR_BEST * scores.max()
    fewest = counts[candidates].min()
    if counts[offsets == 0.0][0] <= fewest + SEEN_THROUGH_SLACK:  # the match stands
        return match.pose.copy()
    consistent = candidates & (counts == fewest)
    best = float(scores[consistent].max())
    # scores within the mean's standard error tie (along a bare corridor the field's noise
    # alone ranks them)
    tie = max(np.sqrt(best * max(1.0 - best, 0.0) / len(points)), 1.0 / len(points))
    tied = consistent & (scores >= best - tie)
    first, last = tied_run(tied, int(np.flatnonzero(tied)[np.argmin(np.abs(offsets[tied]))]))
    moved = match.pose.copy()
    moved[:2] += 0.5 * (offsets[first] + offsets[last]) * direction
    return moved


def tied_run(tied: NDArray[np.bool_], start: int) -> tuple[int, int]:
    """The first and last index of the run of ``tied`` places (P,) holding ``start``."""
    first = last = start
    while first > 0 and tied[first - 1]:
        first -= 1
    while last < len(tied) - 1 and tied[last + 1]:
        last += 1
    return first, last


def toward_guess(map_points: FloatArray, points: FloatArray, match: MatchResult,
                 guess: FloatArray, min_information: float, step: float) -> FloatArray | None:
    """``match.pose`` (3,) moved along its least pinned direction to the ``guess``'s (3,)
    place on that line, where its ``information`` pins that direction less than
    ``min_information`` points do (the directions ICP leaves to a prior), the move is at
    least ``step`` [m] and the scan's ``points`` (M, 2, car frame) see through no more
    ``map_points`` (N, 2, world) there (within :data:`SEEN_THROUGH_SLACK`); else None.
    Along a direction the scan does not pin, the motion model's guess is the best there is;
    a place that scores a little better on the map there is one the map saw more of (the
    end of a corridor the car drove on past while blind), not evidence."""
    direction = free_direction(match.information, min_information)
    if direction is None:
        return None
    offset = float(np.dot(guess[:2] - match.pose[:2], direction))
    if abs(offset) < step:
        return None
    moved = match.pose.copy()
    moved[:2] += offset * direction
    if seen_through_count(map_points, points, moved) > (
            seen_through_count(map_points, points, match.pose) + SEEN_THROUGH_SLACK):
        return None
    return moved


def held_along(direction: FloatArray, information: FloatArray | None) -> FloatArray:
    """Prior information (3, 3) holding a pose along ``direction`` (2,, unit) only, as
    firmly as the match's ``information`` (3, 3) pins its best pinned direction (nothing
    where that is unknown)."""
    strength = 0.0 if information is None else float(np.linalg.eigvalsh(information[:2, :2])[-1])
    held = np.zeros((3, 3))
    held[:2, :2] = strength * np.outer(direction, direction)
    return held


def resumed_match(search: GlobalSearch, reference: PointToLineReference, points: FloatArray,
                  guess: FloatArray, match: MatchResult, reach: float, params: ICPParams,
                  min_quality: float) -> tuple[MatchResult | None, bool]:
    """The far-apart ``match`` of ``points`` (M, 2, car frame) after a long blind stretch,
    and whether the scan is lost. None where the match stands: along the least pinned
    direction of its ICP on the map alone (the guess held it), within ``reach`` [m] (in two
    search cells' steps), no place is better (:func:`along_least_pinned`) and the scan
    leaves the guess's (3,) place on that line open (:func:`toward_guess`). Else ICP from the better
    place, held by nothing in the directions the scan leaves free, or from the guess's,
    held there along the line; or, where the placement explains less than ``min_quality`` of
    the scan and the scan still sees through map points there, the ``guess``, lost. A
    better place explaining less than ``min_quality`` is kept but the scan is lost too: the
    map contradicted the far-apart match, and a place that sees through nothing yet explains
    little may be a half-new place driven into while blind or a wrong one whose walls lie
    beyond the scan's reach; the scan cannot tell which."""
    unheld = register(reference, points, match.pose, params, match.pose, np.zeros(3))
    start = along_least_pinned(search.field, search.map_points, points, unheld, reach,
                               2.0 * search.resolution)
    moved = not np.array_equal(start, unheld.pose)
    placed = register(reference, points, start, params, start, np.zeros(3)) if moved else match
    if placed.quality < min_quality and seen_through_count(search.map_points, points,
                                                           placed.pose) > 0:
        return MatchResult(guess.copy(), placed.quality, placed.rmse, 0, False, None), True
    guessed = toward_guess(search.map_points, points, placed if moved else unheld, guess,
                           params.min_information, 2.0 * search.resolution)
    if guessed is not None:
        held = held_along(least_pinned_direction(unheld.information), unheld.information)
        kept = register(reference, points, guessed, params, guessed, held)
        return kept, moved and kept.quality < min_quality
    return (placed if moved else None), moved and placed.quality < min_quality
