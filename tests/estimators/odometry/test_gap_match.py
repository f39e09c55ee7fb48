"""After a clock gap, ``lidar_odometry`` keeps the guess whose place across a corridor the scan
bears out: lost scans (the car drove on) or a stamp that jumped alone (it did not)."""

from __future__ import annotations

import numpy as np

from estimators.matching.icp import ICPParams, register
from estimators.matching.point_to_line import PointToLineReference
from estimators.odometry.gap_match import across_gap
from tests.estimators.corridor_scans import corridor

#: The corridor (walls at y = +-2 from x = 0 to 40) and a weak prior, as after a clock gap.
WALLS = corridor(40.0)
WEAK = np.full(3, 1e-4)


def test_the_guess_that_predicted_the_crossing_keeps_its_place_along_the_axis() -> None:
    """0.1 m along and 0.065 m across per interval from (10, -0.3): after 11 intervals the car
    is at (11.1, 0.415) when scans were lost, at (10.1, -0.235) when only the stamp jumped.
    The scan of bare walls pins y alone."""
    reference = PointToLineReference(WALLS)
    start, step = np.array([10.0, -0.3, 0.0]), np.array([0.1, 0.065, 0.0])
    guess, longer = start + step, start + 11.0 * step
    longer[2] = 0.0
    params = ICPParams(min_information=2.0)  # lidar_odometry's
    for car in (longer, guess):
        x = np.arange(-6.0, 6.0, 0.05)
        points = np.concatenate([np.column_stack([x, 2.0 - np.full_like(x, car[1])]),
                                 np.column_stack([x, -2.0 - np.full_like(x, car[1])])])
        found = register(reference, points, guess, params, guess, WEAK)
        kept = across_gap(reference, points, found, guess, longer, 11.0, float(np.hypot(
            step[0], step[1])), params, WEAK)
        assert np.hypot(*(kept.pose[:2] - car[:2])) < 0.02


def test_where_the_scan_pins_every_direction_the_guess_matches_stand() -> None:
    """A wall across the corridor pins its axis too: no second match is made."""
    y = np.arange(-2.0, 2.0, 0.05)
    reference = PointToLineReference(np.concatenate([WALLS, np.column_stack(
        [np.full_like(y, 16.0), y])]))
    car = np.array([11.1, 0.4, 0.0])
    points = reference.points[np.abs(reference.points[:, 0] - car[0]) < 6.0] - car[:2]
    params = ICPParams(min_information=2.0)
    found = register(reference, points, car, params, car, WEAK)
    longer = car + [3.0, 0.0, 0.0]  # a match from here would land elsewhere, or not at all
    assert across_gap(reference, points, found, car, longer, 11.0, 0.1, params, WEAK) is found


def test_a_stamp_that_jumped_alone_keeps_the_one_interval_match() -> None:
    """Driving straight along the corridor, 0.05 m per interval from (10, 0.2): the scan pins
    y alone, both guesses put the car within a centimetre of it across the axis, and the
    stamp jumped alone (bursty stamps). The guess over 9 intervals fits per interval by
    chance; the car stays a step on."""
    reference = PointToLineReference(WALLS)
    start, step = np.array([10.0, 0.2, 0.0]), np.array([0.05, 0.0, 0.0])
    guess, longer = start + step, start + 9.0 * step
    params = ICPParams(min_information=2.0)
    car = guess + [0.0, 0.01, 0.0]
    x = np.arange(-6.0, 6.0, 0.05)
    points = np.concatenate([np.column_stack([x, 2.0 - np.full_like(x, car[1])]),
                             np.column_stack([x, -2.0 - np.full_like(x, car[1])])])
    found = register(reference, points, guess, params, guess, WEAK)
    kept = across_gap(reference, points, found, guess, longer, 9.0, 0.05, params, WEAK)
    assert np.hypot(*(kept.pose[:2] - car[:2])) < 0.02
