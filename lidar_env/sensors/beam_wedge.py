"""A sensor's beam wedge, and the tests that skip what lies wholly outside it (numba).

A Lidar whose field of view leaves a fair part of the circle out (see
:func:`lidar_env.sensors.ray_casting.cast_sensor`) culls grid cells and primitives outside the
angular interval of its beams, widened by :data:`ANGLE_MARGIN`. The wedge is ``(width, ax, ay, bx,
by)``: its width [rad] and the unit vectors of its first and last edge, counter-clockwise from
``a`` to ``b``, in the world frame; points are relative to the sensor, in metres.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

#: Extra angle [rad] each subtended interval is widened by. It covers the error of
#: :func:`lidar_env.sensors.ray_casting._bearing` (< 1.7e-6 rad) so no beam that grazes a
#: primitive is dropped; the exact intersection test then decides the hit, so the margin costs
#: only rare extra tests.
ANGLE_MARGIN = 1e-5
#: [m] how far outside a sensor's widened beam wedge a primitive must lie to be skipped.
WEDGE_TOLERANCE = 1e-9
_COS_MARGIN, _SIN_MARGIN = math.cos(ANGLE_MARGIN), math.sin(ANGLE_MARGIN)


@njit(cache=True, fastmath=False)
def beam_wedge(sorted_angles: NDArray[np.float64], order: NDArray[np.int64],
           dir_x: NDArray[np.float64], dir_y: NDArray[np.float64]) -> tuple:
    """The beams' angular interval widened by the margin, ``(width, ax, ay, bx, by)``: its
    width [rad] and the unit vectors of its first and last edge (the first and last beam's
    directions turned out by the margin, so no trigonometry)."""
    first, last = order[0], order[-1]
    c, s = _COS_MARGIN, _SIN_MARGIN
    return (sorted_angles[-1] - sorted_angles[0] + 2.0 * ANGLE_MARGIN,
            c * dir_x[first] + s * dir_y[first], c * dir_y[first] - s * dir_x[first],
            c * dir_x[last] - s * dir_y[last], c * dir_y[last] + s * dir_x[last])


@njit(cache=True, fastmath=False)
def outside_wedge(wedge: tuple, px: float, py: float, qx: float, qy: float,
                   r: float) -> bool:
    """True when the segment p-q (relative to the sensor) thickened by ``r`` [m] lies wholly
    outside the beam ``wedge`` (for a circle, p = q = its centre)."""
    width, ax, ay, bx, by = wedge
    tol = WEDGE_TOLERANCE + r
    left_of_first = max(ax * py - ay * px, ax * qy - ay * qx) < -tol
    right_of_last = max(px * by - py * bx, qx * by - qy * bx) < -tol
    if width <= math.pi:
        return left_of_first or right_of_last
    return left_of_first and right_of_last


@njit(cache=True, fastmath=False)
def box_outside_wedge(wedge: tuple, x0: float, y0: float, x1: float, y1: float) -> bool:
    """True when the box ``[x0, x1] x [y0, y1]`` (relative to the sensor) lies wholly outside
    the beam ``wedge``: its four corners beyond the same edge line (both, for a wide wedge)."""
    width, ax, ay, bx, by = wedge
    left_of_first = right_of_last = True
    for px, py in ((x0, y0), (x1, y0), (x0, y1), (x1, y1)):
        left_of_first = left_of_first and ax * py - ay * px < -WEDGE_TOLERANCE
        right_of_last = right_of_last and px * by - py * bx < -WEDGE_TOLERANCE
    if width <= math.pi:
        return left_of_first or right_of_last
    return left_of_first and right_of_last
