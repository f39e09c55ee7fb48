"""Where ``icp`` and ``pc_fusion`` look for the car after a blind stretch in which it turned
on the spot: every turn the gap allows is searched, and a match out of the motion model's
reach gives way to one within it."""

from __future__ import annotations

import math

import numpy as np

from estimators.matching.match_result import MatchResult
from estimators.matching.scan_recovery import (
    MAX_SEARCH_TURN,
    most_likely_match,
    search_starts,
    turn_between,
)
from lidar_env.core.se2 import compose
from tests.estimators.room_scans import scan_points


def test_a_turn_on_the_spot_beyond_the_near_window_is_searched_for() -> None:
    """ACES: the robot stops and turns 113 degrees in 3 s blind (19 scans)."""
    rng = np.random.default_rng(0)
    start, motion = np.array([4.0, 5.0, 0.3]), np.array([0.1, 0.05, math.radians(115.0)])
    reference = scan_points(start, rng)
    query = scan_points(compose(start, motion), rng)
    starts = search_starts(reference, query, np.zeros(3), 20.0, 3.0)
    turned = [s for s in starts if abs(s[2]) > MAX_SEARCH_TURN]
    assert len(turned) == 1
    assert np.hypot(*(turned[0][:2] - motion[:2])) < 0.1
    assert abs(turned[0][2] - motion[2]) < math.radians(3.0)
    # over two intervals the car cannot have turned that far: the near window alone
    assert all(abs(s[2]) <= MAX_SEARCH_TURN for s in search_starts(
        reference, query, np.zeros(3), 2.0, 0.3))


def test_a_match_out_of_the_guess_reach_is_judged_only_where_none_is_within() -> None:
    """A corridor seen turned round fits 2 m down it (61 %) as well as the turn on the spot
    fits (54 %): a robot at a standstill cannot have driven 2 m in 3 s."""
    far = MatchResult(np.array([1.9, 0.6, -1.16]), 0.61, 0.01, 5, True, None)
    near = MatchResult(np.array([0.2, 0.1, 1.98]), 0.54, 0.01, 5, True, None)
    guess = np.zeros(3)
    args = ([far, near], [guess, guess], [20.0, 20.0], 0.01, 180)
    assert most_likely_match(*args) == 0
    assert most_likely_match(*args, seconds=3.0) == 1
    # none within reach: all are judged
    assert most_likely_match([far], [guess], [20.0], 0.01, 180, seconds=3.0) == 0


def test_a_turn_between_two_headings_is_the_shorter_way_round() -> None:
    assert math.isclose(turn_between(3.0, -3.0), 2.0 * math.pi - 6.0)  # across +-pi
    assert math.isclose(turn_between(-0.5, 0.25), 0.75)
    assert turn_between(0.2, 0.2 + 4.0 * math.pi) < 1e-12  # whole turns apart
