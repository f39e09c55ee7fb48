"""Which reference points a scan sees through from a pose: none where it was taken, the walls
the car drove past where it is placed short of that."""

from __future__ import annotations

import math

import numpy as np

from estimators.matching.seen_through import (
    BEARING_BIN,
    NEAREST_JUDGED,
    nearest_by_bearing,
    seen_through_count,
    seen_through_counts,
)
from tests.estimators.corridor_scans import corridor, scan_at


def test_a_scan_placed_short_of_where_it_was_taken_sees_through_the_walls_passed() -> None:
    scan = scan_at(8.0, 10.0)  # the car at x = 8, the walls ending at x = 10
    walls = corridor(14.0)  # the reference saw them on to x = 14
    counts = seen_through_counts(walls, scan, np.array([[8.0, 0, 0], [12.0, 0, 0],
                                                        [4.0, 0, 0]]))
    assert counts[0] > 20 and counts[1] <= 3  # placed 4 m on: the walls lie behind
    assert seen_through_count(walls, scan, np.array([12.0, 0, 0])) == counts[1]
    walls = corridor(10.0)
    assert seen_through_counts(walls, scan, np.array([[8.0, 0, 0]]))[0] == 0
    assert seen_through_counts(walls, scan, np.array([[4.0, 0, 0]]))[0] > 20


def test_bearings_without_a_return_and_near_points_judge_nothing() -> None:
    scan = np.array([[5.0, 0.0]])  # one return, straight ahead
    nearest = nearest_by_bearing(scan)
    assert np.count_nonzero(np.isfinite(nearest)) == 1 and nearest.size == round(
        2 * math.pi / BEARING_BIN)
    reference = np.array([[2.0, 0.0], [0.5 * NEAREST_JUDGED, 0.0], [0.0, 2.0]])
    # ahead at 2 m: seen through; too near the car: not judged; to the left: no return there
    assert seen_through_counts(reference, scan, np.zeros((1, 3)), nearest)[0] == 1
