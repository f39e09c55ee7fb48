"""Dropped returns: a no-return reading among returns is a beam the surface did not send back
(a dark or glancing surface, a blinded beam), not a look into the open. The moving-point
filter (:mod:`estimators.odometry.free_space`) counts such a beam as free only as far as the
nearer of the nearest returns on either side. How far from a return a no-return beam is still
taken for a dropped one follows the scan's own dropout rate: a Lidar dropping half its beams
at random hides a surface's edge beside open space (a wall's end seen past a door, the far
end of a corridor) behind a run of no-returns several beams long, and that run, taken for a
look into the open, sees through the surface: the filter then drops it from the scan and the
map, though it is often what pins the car's motion along a corridor. Ranges [m], angles
[rad].
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

#: [rad] a no-return beam with a return this close on either side was dropped (a dark or
#: glancing surface, a blinded beam) rather than cast into open space: 3 degrees, three
#: beams of a 1-degree Lidar, over which half the beams dropped at random leave a return
#: on one side of all but 1 in 64 dropped beams. Wider, it bounds the views into the open
#: the filter needs beside walkers (at 7 degrees it loses walkers in ``hallway``, ATE 3 mm
#: to 28 cm: ``benchmarks/bench_movers_estimators.py``).
DROPOUT_WINDOW = math.radians(3.0)
#: Where a scan drops beams, a no-return beam within ``w`` beams of a return is a dropped one,
#: ``w`` the shortest run of beams that drops whole, at the scan's dropout rate, with at
#: most this chance: 6 beams either side at half the beams dropped (a dropped beam escapes being
#: bounded 1 time in 4096); :data:`DROPOUT_WINDOW` (3 beams of a 1-degree Lidar) on a scan
#: dropping a quarter of its beams or fewer.
#: The wider window also bounds the views into the open beside walkers, but only on scans
#: that drop beams at such rates.
DROPPED_RUN_CHANCE = 1.0 / 64.0


@numba.njit(cache=True)
def dropout_window(ranges: NDArray[np.float64], a: int, n: int, order: NDArray[np.int64],
                   max_range: float, full_turn: bool, least: int, min_range: float) -> int:
    """How many beams either side of a return a no-return reading of one sensor (``n``
    readings from ``a`` of ``ranges``, in angular order through ``order``) is taken for a
    dropped return: ``least``, or more where the sensor drops beams, until a run that long
    drops with at most :data:`DROPPED_RUN_CHANCE`. The dropout rate is the share of
    no-returns among the beams whose both neighbours returned: inside a surface, where a
    no-return is a dropped beam, not the edge of a view into the open."""
    flanked = dropped = 0
    for j in range(n):
        before, after = j - 1, j + 1
        if full_turn:
            before, after = (before + n) % n, after % n
        elif before < 0 or after >= n:
            continue
        left, right = ranges[a + order[a + before]], ranges[a + order[a + after]]
        if min_range <= left < max_range and min_range <= right < max_range:
            flanked += 1
            dropped += ranges[a + order[a + j]] >= max_range
    if dropped == 0:
        return least
    rate = dropped / flanked
    if rate >= 1.0:
        return max(least, n)
    return max(least, math.ceil(math.log(DROPPED_RUN_CHANCE) / math.log(rate)))


@numba.njit(cache=True)
def bound_dropped_returns(ranges: NDArray[np.float64], starts: NDArray[np.int64],
                          order: NDArray[np.int64], sensor_params: NDArray[np.float64],
                          windows: NDArray[np.int64], min_range: float) -> NDArray[np.float64]:
    """``ranges`` (K sensors' readings, packed as
    :class:`~estimators.odometry.free_space.BeamGeometry` packs them: ``starts``, ``order``,
    ``sensor_params``) with each no-return reading (at or beyond the max range) that has a
    return (from ``min_range`` up) within ``windows[k]`` beams (more where the sensor drops
    beams: :func:`dropout_window`) on either side, in angular order, replaced by the nearer
    of the nearest such returns on each side: a beam dropped among returns saw free space
    only as far as its neighbours did (the nearer: between two beams, a wall seen at a
    glancing angle runs nearer than the farther one's return)."""
    out = ranges.copy()
    for k in range(len(starts) - 1):
        a, n = starts[k], starts[k + 1] - starts[k]
        max_range, full_turn = sensor_params[k, 1], sensor_params[k, 3] > 0.5
        w = dropout_window(ranges, a, n, order, max_range, full_turn, windows[k], min_range)
        for j in range(n):
            if not ranges[a + order[a + j]] >= max_range:
                continue
            bound = np.inf
            for side in (-1, 1):
                for d in range(1, w + 1):
                    m = j + side * d
                    if full_turn:
                        m = (m + n) % n
                    elif m < 0 or m >= n:
                        break
                    reading = ranges[a + order[a + m]]
                    if min_range <= reading < max_range:
                        bound = min(bound, reading)
                        break
            if bound < np.inf:
                out[a + order[a + j]] = bound
    return out
