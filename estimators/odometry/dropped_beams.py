"""Dropped returns: a no-return reading among returns is a beam the surface did not send back
(a dark or glancing surface, a blinded beam), not a look into the open. The moving-point
filter (:mod:`estimators.odometry.free_space`) counts such a beam as free only as far as the
nearer of the nearest returns on either side. Ranges [m], angles [rad].
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


@numba.njit(cache=True)
def bound_dropped_returns(ranges: NDArray[np.float64], starts: NDArray[np.int64],
                          order: NDArray[np.int64], sensor_params: NDArray[np.float64],
                          windows: NDArray[np.int64], min_range: float) -> NDArray[np.float64]:
    """``ranges`` (K sensors' readings, packed as
    :class:`~estimators.odometry.free_space.BeamGeometry` packs them: ``starts``, ``order``,
    ``sensor_params``) with each no-return reading (at or beyond the max range) that has a
    return (from ``min_range`` up) within ``windows[k]`` beams on either side, in angular
    order, replaced by the nearer of the nearest such returns on each side: a beam dropped
    among returns saw free space only as far as its neighbours did (the nearer: between two
    beams, a wall seen at a glancing angle runs nearer than the farther one's return)."""
    out = ranges.copy()
    for k in range(len(starts) - 1):
        a, n = starts[k], starts[k + 1] - starts[k]
        max_range, full_turn, w = sensor_params[k, 1], sensor_params[k, 3] > 0.5, windows[k]
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
