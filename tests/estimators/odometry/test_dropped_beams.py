"""A no-return beam among returns is taken for a dropped return as far from them as the scan's
own dropout rate makes a run of dropped beams likely, and no farther."""

from __future__ import annotations

import numpy as np

from estimators.odometry.dropped_beams import bound_dropped_returns

#: One full-turn Lidar of 360 beams (1 degree apart), 10 m max range, seeing a wall 5 m round.
BEAMS, MAX_RANGE, WALL = 360, 10.0, 5.0
STARTS = np.array([0, BEAMS], dtype=np.int64)
ORDER = np.arange(BEAMS, dtype=np.int64)
PARAMS = np.array([[0.0, MAX_RANGE, np.radians(1.0), 1.0]])
WINDOWS = np.array([3], dtype=np.int64)  # DROPOUT_WINDOW at 1 degree a beam
RUN = slice(100, 107)  # seven no-returns in a row: the middle one four beams from a return


def bounded(ranges: np.ndarray) -> np.ndarray:
    return bound_dropped_returns(ranges, STARTS, ORDER, PARAMS, WINDOWS, 0.0)


def test_a_run_of_dropped_beams_in_a_scan_dropping_half_of_them_stays_on_the_wall() -> None:
    """Half the beams dropped at random: seven in a row is a 1-in-128 run among the scan's
    360 beams, not a view into the open through the wall."""
    ranges = np.full(BEAMS, WALL)
    ranges[np.random.default_rng(0).random(BEAMS) < 0.5] = MAX_RANGE
    ranges[RUN] = MAX_RANGE
    ranges[[RUN.start - 1, RUN.stop]] = WALL
    assert np.all(bounded(ranges)[RUN] == WALL)


def test_a_run_of_no_returns_in_a_scan_that_drops_none_is_a_view_into_the_open() -> None:
    """A door in the wall: the beams more than three from a return see free space."""
    ranges = np.full(BEAMS, WALL)
    ranges[RUN] = MAX_RANGE
    out = bounded(ranges)
    assert out[RUN.start + 3] == MAX_RANGE
    assert out[RUN.start] == WALL
