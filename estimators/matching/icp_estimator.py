"""The ``icp`` estimator: scan-to-previous-scan point-to-line ICP (:mod:`estimators.matching.icp`)
with a constant-velocity guess, and the recovery starts of :mod:`estimators.matching.scan_recovery`
after skipped or lost scans."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from estimators.base import Estimator
from estimators.health import (
    BLIND_STRETCH,
    CLOCK_HISTORY,
    CLOCK_JUMP_FACTOR,
    evident_time_step,
    evident_turn_time,
    intervals_since_used,
)
from estimators.matching.held_returns import MAX_AGE, HeldReturns, check_max_age
from estimators.matching.icp import ICPParams, register
from estimators.matching.neighbourhood_fits import check_neighbours
from estimators.matching.normal_equations import prior_information
from estimators.matching.scan_matching import DEFAULT_MIN_RANGE, CarPoints
from estimators.matching.scan_recovery import (
    MIN_SEARCH_POINTS,
    UNPLACED_BELOW,
    lost_after_blind,
    most_likely_match,
    off_seen_through,
    one_turn_guess,
    reach,
    search_starts,
)
from estimators.matching.surface_fits import surface_reference
from estimators.paper.pc import MIN_MATCH_RETURNS
from lidar_env.core import ConfigError
from lidar_env.core.se2 import compose

#: [s] the shortest scan interval a clock gap is counted in (100 Hz, beyond planar Lidars'
#: scan rates): Intel's logger repeats stamps, moved 1 us apart to run forward, and a run
#: starting on a few of them would count a 0.6 s step as 600 000 lost intervals and search
#: for the car kilometres away.
MIN_SCAN_INTERVAL = 0.01

def held_where_free(new: NDArray[np.float64], old: NDArray[np.float64],
                    information: NDArray[np.float64], least: float) -> NDArray[np.float64]:
    """``new`` (2,) with its part along each direction ``information`` (2, 2, in points'
    worth) holds with fewer than ``least`` points replaced by ``old``'s (2,) part."""
    values, vectors = np.linalg.eigh(information)
    held = new.copy()
    for value, vector in zip(values, vectors.T, strict=True):
        if value < least:
            held += vector * float((old - new) @ vector)
    return held


@dataclass
class ICPEstimator(Estimator):
    """Scan-to-previous-scan point-to-line ICP (no odometry): the baseline a user would pick.
    Both Lidars' points are merged in the car frame first.

    Each match starts from the last increment (a constant-velocity guess, as KISS-ICP and
    rf2o seed theirs) rather than from the identity: ICP's nearest-point pairs pull towards
    its starting pose, most where a corridor leaves its axis to a few points, and from the
    identity it needs about twice the iterations.

    The reference is the previous scan with, at each beam that lost its return, the return it
    had within ``held_scans`` scans, moved by the matches since
    (:mod:`estimators.matching.held_returns`): a scan with beams lost at random is matched onto
    a reference nearly as dense as a full scan; over a gap of more intervals the match reads the
    last scan's own returns, as the recovery does, and the held returns age by the intervals the
    match bears out. Its lines are the curves fitted through each point's ``normal_neighbours``
    (up to ``max_normal_neighbours`` along a noisy wall), with their midpoints where they bend
    (:mod:`estimators.matching.surface_fits`): a line through two returns of a wall at a grazing
    angle tilts with their noise and pulls the match off a corridor's axis. Directions the pairs
    pin down with less than ``min_information`` fully weighted points follow the
    constant-velocity guess alone (:func:`register`'s ``min_information``), held by a weak prior
    (``prior_sigma_*`` against ``noise_sigma``, widening with the scan intervals it spans),
    where the guess spans only observations that came (a clock gap may be a stamp that jumped
    alone). Over a clock gap the next guess takes the match's translation over the intervals the
    speed held bears out (:func:`~estimators.health.evident_time_step`) and its turn over those
    the turn rate held bears out (:func:`~estimators.health.evident_turn_time`), at least the
    former.

    After skipped or lost scans the match also starts from the translation extrapolated with one
    interval's turn and from a correlative search on the last scan; of the matches explaining
    nearly the most points the least surprising is kept, after skipped ones moved off where it
    sees through the last scan (:mod:`estimators.matching.scan_recovery`). After a blind stretch
    the car is reported lost (``health.lost_scans``) where the kept match sees through the last
    scan and explains under half the scan (its pose is then the guess), or explains under
    :data:`UNPLACED_BELOW` of it.

    Parameters: see :class:`ICPParams` (distances [m]); ``min_range`` [m] drops near returns;
    ``held_scans`` (0: the previous scan's returns alone).
    """

    max_iterations: int = 30
    max_correspondence_distance: float = 1.0
    loss: str = "cauchy"
    loss_scale: float = 0.1
    trim_ratio: float = 1.0
    min_range: float = DEFAULT_MIN_RANGE
    normal_neighbours: int = 9
    max_normal_neighbours: int = 72
    min_information: float = 2.0
    noise_sigma: float = 0.02
    prior_sigma_translation: float = 0.03
    prior_sigma_rotation: float = 0.1
    held_scans: int = MAX_AGE

    def __post_init__(self) -> None:
        self.params = ICPParams(
            max_iterations=self.max_iterations,
            max_correspondence_distance=self.max_correspondence_distance,
            loss=self.loss,
            loss_scale=self.loss_scale,
            trim_ratio=self.trim_ratio,
        )
        for name in ("noise_sigma", "prior_sigma_translation", "prior_sigma_rotation"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"{name}: expected a positive value, got {getattr(self, name)}")
        check_neighbours(self.normal_neighbours, self.max_normal_neighbours)
        check_max_age(self.held_scans)
        self._held_params = replace(self.params, min_information=self.min_information)
        self._prior_information = prior_information(
            self.noise_sigma, self.prior_sigma_translation, self.prior_sigma_rotation)

    def _reset_state(self) -> None:
        self._previous: NDArray[np.float64] | None = None
        self._increment = np.zeros(3)
        assert self.setup is not None
        self._points = CarPoints(self.setup, self.min_range)
        self._held = HeldReturns(self._points, self.held_scans)
        self._reference: NDArray[np.float64] | None = None

    def _start(self, scans: dict[str, NDArray[np.float64]], t: float) -> None:
        self._previous = self._points(scans)
        self._reference = self._held.start(scans, self._previous)

    def _intervals_lost(self, t: float) -> float:
        """Scan intervals since the last scan used when the clock jumped before ``t`` [s]: the
        time step over the median of the last positive ones (at least
        :data:`MIN_SCAN_INTERVAL`), if :data:`CLOCK_JUMP_FACTOR` or more (less, as Intel's
        bursty stamps jump at most scans, is no loss); else 1."""
        steps = np.diff(self._times[-CLOCK_HISTORY:])
        steps = steps[steps > 0]
        lost = intervals_since_used(0, self.clock_jumped, t - self._times[-1], max(
            float(np.median(steps)), MIN_SCAN_INTERVAL) if len(steps) else 0.0)
        return lost if lost >= CLOCK_JUMP_FACTOR else 1.0

    def _recovery_starts(self, current: NDArray[np.float64], span: float, seconds: float
                         ) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
        """Starts of :mod:`estimators.matching.scan_recovery` over a gap of ``span`` intervals
        and ``seconds`` [s], each with the guess its match is judged against: the last
        increment's translation with one turn, and the searches' (far turns: skipped only)."""
        assert self._previous is not None
        kept = one_turn_guess(self._increment, span)
        return [(kept, kept)] + [(found, kept) for found in search_starts(
            self._previous, current, kept, span, seconds, self.skipped_before > 0)]

    def _step(self, scans: dict[str, NDArray[np.float64]], t: float) -> NDArray[np.float64]:
        current = self._points(scans)
        increment = np.zeros(3)
        # too few points on either side: no update (a fit of 3 points can land metres away),
        # and the last scan with enough points stays the reference
        if len(current) < MIN_MATCH_RETURNS:
            return compose(self.pose, increment)
        if self._previous is not None and len(self._previous) >= MIN_MATCH_RETURNS:
            observations = 1 + self.skipped_before  # skipped ones count (Estimator.update)
            guesses = [self._increment * observations]
            lost = self._intervals_lost(t)
            if lost > observations:  # scans lost on the way (the car drove on), or the stamp
                guesses.append(self._increment * lost)  # alone jumped (the scans ran on)
            spans = [float(observations), lost][:len(guesses)]
            starts = list(guesses)
            # after skipped or lost scans (told from a stamp that jumped alone by the matches)
            # the turn is the least known part of the guess; a search needs enough points
            span = float(max(observations, lost))
            if span > 1 and min(len(current), len(self._previous)) >= MIN_SEARCH_POINTS:
                for start, guess in self._recovery_starts(current, span, t - self._times[-1]):
                    starts.append(start)
                    guesses.append(guess)
                    spans.append(span)
            # over a longer gap, the last scan's own returns, which the recovery reasons on
            # (the held ones carry on where the match bears out no more intervals: a stamp
            # that jumped alone)
            reference = surface_reference(self._reference if span <= self.held_scans else
                                          self._previous,
                                          self.normal_neighbours, self.max_normal_neighbours)
            # free directions follow a guess over observations that came (not a clock gap's,
            # whose stamp may have jumped alone, nor the search's); priors weaken with the span
            results = [register(reference, current, start, self._held_params if (
                start is guess and span <= observations) else self.params, guess,
                                self._prior_information / span**2)
                       for start, guess, span in zip(starts, guesses, spans, strict=True)]
            best = most_likely_match(results, guesses, spans, float(np.hypot(
                *self._increment[:2])), len(current), t - self._times[-1] if span > 1 else None)
            chosen = results[best]
            increment = chosen.pose
            if observations > BLIND_STRETCH:
                kept, seen, place = off_seen_through(lambda start: register(  # a blind stretch
                    reference, current, start, self.params, start, self._prior_information
                    / span**2), results[best], lambda m: (m.pose, m.quality), self._previous,
                    current, reach(guesses[best], span, t - self._times[-1])[0])
                chosen, starts = kept, starts + ([] if place is None else [place])
                increment = chosen.pose
                if lost_after_blind(kept.quality, seen):  # the scans cannot tell: the guess
                    self.health.note_lost(len(self._observations))
                    increment = one_turn_guess(self._increment, span)
                elif kept.quality < UNPLACED_BELOW:  # the best placement, not vouched for
                    self.health.note_lost(len(self._observations))
            if min(np.hypot(*(increment[:2] - start[:2])) for start in starts) > (
                    self.params.max_correspondence_distance):
                # no pair is accepted beyond this distance, so no solution this far from the
                # guesses is backed by the points (a few sparse returns slid away): the guess
                self.health.note_unusable(len(self._observations))
                return compose(self.pose, guesses[best])
            turns = observations
            if lost > observations:  # per interval the scans bear out at the rates held
                observations = max(observations, evident_time_step(
                    float(np.hypot(*increment[:2])), float(np.hypot(*self._increment[:2])),
                    lost, 1.0))
                turns = evident_turn_time(float(increment[2]), float(self._increment[2]),
                                          lost, observations)
            velocity = increment / np.array([observations, observations, turns])
            if lost > observations and chosen.information is not None:
                # the gap's match says nothing of the speed along what its scans leave free
                velocity[:2] = held_where_free(velocity[:2], self._increment[:2],
                                               chosen.information[:2, :2], self.min_information)
            self._increment = velocity
            # held returns age by the scan intervals the match bears out (not a stamp's jump)
            self._reference = self._held.advance(scans, current, increment, observations)
        else:
            self._reference = self._held.start(scans, current)
        self._previous = current
        return compose(self.pose, increment)
