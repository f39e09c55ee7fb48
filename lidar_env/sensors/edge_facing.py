"""Which side of each polygon edge is free space, so the Lidar can skip edges facing away.

Under the even-odd rule (see :class:`~lidar_env.world.world.World`) a beam from a sensor in free
space first meets an edge coming from the edge's free side: arriving from its filled side, it
would already have crossed the boundary, at a nearer edge. So an edge whose free side does not
face the sensor can never give a beam its range (back-face culling), and on a traced map about
half the edges near a sensor are such. :func:`edge_facing` finds each edge's free side once per
world; the ray caster (:func:`lidar_env.sensors.ray_casting.cast_sensor`) skips an edge when the
sensor lies more than :data:`BACK_FACE_TOLERANCE` on its filled side.

An edge gets a side only when that side is the same all along it: no other polygon edge
crosses it, touches it between its end points or runs within :data:`_TOUCH_TOLERANCE` of it
(otherwise, and for every wall, it is two-sided: 0). The code is +1 when the free side is to
the left of the edge walked from ``(x1, y1)`` to ``(x2, y2)``, -1 when to the right. Units:
metres, world frame.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from lidar_env.world.primitive_grid import grid_cell, odd_crossings, point_segment_distance2

#: [m] how far onto an edge's filled side the sensor must be for the edge to be skipped: far
#: above the rounding of the side test, far below any geometry.
BACK_FACE_TOLERANCE = 1e-9
#: [m] edges nearer each other than this (away from a shared end point) count as touching.
_TOUCH_TOLERANCE = 1e-7
#: [m] below this probe offset an edge's sides are not told apart (left two-sided).
_MIN_PROBE = 1e-6


@njit(cache=True, fastmath=False)
def _touch(a: NDArray[np.float64], b: NDArray[np.float64]) -> bool:
    """True when segments ``a`` and ``b`` (rows x1, y1, x2, y2) meet or come within
    :data:`_TOUCH_TOLERANCE` anywhere but at an end point they share exactly."""
    tol2 = _TOUCH_TOLERANCE * _TOUCH_TOLERANCE
    shared = 0
    for p in range(2):
        for q in range(2):
            if a[2 * p] == b[2 * q] and a[2 * p + 1] == b[2 * q + 1]:
                shared += 1
    if shared > 1:
        return True  # the same edge twice
    near = False
    for p in range(2):  # an end point of one near the other, unless it is the shared one
        x, y = a[2 * p], a[2 * p + 1]
        if not (shared and ((x == b[0] and y == b[1]) or (x == b[2] and y == b[3]))):
            near = near or point_segment_distance2(x, y, b[0], b[1], b[2], b[3]) < tol2
        x, y = b[2 * p], b[2 * p + 1]
        if not (shared and ((x == a[0] and y == a[1]) or (x == a[2] and y == a[3]))):
            near = near or point_segment_distance2(x, y, a[0], a[1], a[2], a[3]) < tol2
    if near or shared:
        return near  # two edges from one point meet again only if one runs back along the other
    ex, ey, fx, fy = a[2] - a[0], a[3] - a[1], b[2] - b[0], b[3] - b[1]
    s1 = ex * (b[1] - a[1]) - ey * (b[0] - a[0])
    s2 = ex * (b[3] - a[1]) - ey * (b[2] - a[0])
    s3 = fx * (a[1] - b[1]) - fy * (a[0] - b[0])
    s4 = fx * (a[3] - b[1]) - fy * (a[2] - b[0])
    return (s1 > 0.0) != (s2 > 0.0) and (s3 > 0.0) != (s4 > 0.0)


@njit(cache=True, fastmath=False)
def edge_facing(segments: NDArray[np.float64], first_polygon_edge: int,
                grid: tuple) -> NDArray[np.int64]:
    """``(M,)`` free side of each segment: +1 left, -1 right, 0 two-sided (walls, and edges
    touched by another or too close to one to tell). ``grid`` is the world's
    :class:`~lidar_env.world.primitive_grid.PrimitiveGrid` (or its fields as a tuple)."""
    m = segments.shape[0]
    facing = np.zeros(m, dtype=np.int64)
    if first_polygon_edge >= m:
        return facing
    x0, y0, size, nx, ny, segment_start, segment_ids = (grid[0], grid[1], grid[2], grid[3],
                                                        grid[4], grid[7], grid[8])
    touched = np.zeros(m, dtype=np.bool_)
    for c in range(nx * ny):  # two edges that meet share a cell
        for p in range(segment_start[c], segment_start[c + 1]):
            i = segment_ids[p]
            if i < first_polygon_edge:
                continue
            for q in range(p + 1, segment_start[c + 1]):
                j = segment_ids[q]
                if j >= first_polygon_edge and _touch(segments[i], segments[j]):
                    touched[i] = touched[j] = True
    seen = np.zeros(m, dtype=np.int64)
    stamp = 0
    for i in range(first_polygon_edge, m):
        if touched[i]:
            continue
        x1, y1, x2, y2 = segments[i, 0], segments[i, 1], segments[i, 2], segments[i, 3]
        mx, my = 0.5 * (x1 + x2), 0.5 * (y1 + y2)
        length = math.hypot(x2 - x1, y2 - y1)
        # Probe the two sides at the midpoint, nearer it than any other edge: those within a
        # cell of it are listed in the 3 x 3 cells around it.
        clear2 = min(length, size) ** 2
        sx, sy = grid_cell(mx, x0, size, nx), grid_cell(my, y0, size, ny)
        for iy in range(max(sy - 1, 0), min(sy + 1, ny - 1) + 1):
            for ix in range(max(sx - 1, 0), min(sx + 1, nx - 1) + 1):
                c = iy * nx + ix
                for p in range(segment_start[c], segment_start[c + 1]):
                    j = segment_ids[p]
                    if j != i and j >= first_polygon_edge:
                        clear2 = min(clear2, point_segment_distance2(
                            mx, my, segments[j, 0], segments[j, 1], segments[j, 2], segments[j, 3]))
        probe = 0.25 * math.sqrt(clear2)
        if probe < _MIN_PROBE:
            continue
        lx, ly = -(y2 - y1) / length * probe, (x2 - x1) / length * probe  # left normal
        left = odd_crossings(mx + lx, my + ly, segments, first_polygon_edge, grid, seen,
                             stamp + 1)
        right = odd_crossings(mx - lx, my - ly, segments, first_polygon_edge, grid, seen,
                              stamp + 2)
        stamp += 2
        if left != right:
            facing[i] = -1 if left else 1
    return facing
