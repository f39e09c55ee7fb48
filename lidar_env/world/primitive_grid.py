"""The uniform spatial grid over a world's primitives, and its compiled point queries.

:class:`PrimitiveGrid` buckets circles ``(N, 3)`` (``cx, cy, r``) and segments ``(M, 4)``
(``x1, y1, x2, y2``), all in metres in the world frame, into square cells, so that a query
visits only the cells near a point. The numba kernels here (:func:`segment_distance2`,
:func:`grid_cell`, :func:`odd_crossings`, :func:`point_queries`) answer clearance and inside
queries for :class:`~lidar_env.world.world.World`; the Lidar's ray caster reuses the first three and
:func:`cell_block` (the cells under a sensor's sector). The kernels take the grid as a
:class:`PrimitiveGrid` or as a plain tuple of its fields (``tuple(grid)``), which numba is
handed several microseconds faster.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit
from numpy.typing import NDArray

#: Average primitives per cell of :attr:`World.grid`: a few, so a range query visits few empty
#: cells yet culls most far primitives.
_PRIMITIVES_PER_CELL = 4.0
#: Cap on grid cells along one axis (keeps skinny worlds from exploding the cell count).
_MAX_CELLS_PER_AXIS = 2048


class PrimitiveGrid(NamedTuple):
    """A uniform grid over the primitives, for range queries.

    Cell ``(ix, iy)`` covers ``x in x0 + [ix, ix + 1) * cell`` and likewise ``y``; its id is
    ``iy * nx + ix``. ``circle_ids[circle_start[c]:circle_start[c + 1]]`` are the circles whose
    bounding box touches cell ``c``; likewise the segments (indexing :attr:`World.segments`)
    that pass through cell ``c`` (listed conservatively: possibly in a few neighbouring cells
    too). Points outside the grid belong to its border cells.
    """

    x0: float
    y0: float
    cell: float  # [m]
    nx: int
    ny: int
    circle_start: NDArray[np.int64]
    circle_ids: NDArray[np.int64]
    segment_start: NDArray[np.int64]
    segment_ids: NDArray[np.int64]


def _cell_index(value: NDArray, origin: float, cell: float, count: int) -> NDArray[np.int64]:
    """Grid index of coordinates [m], clipped to ``[0, count)``."""
    return np.clip(np.floor((value - origin) / cell), 0, count - 1).astype(np.int64)


def build_grid(circles: NDArray[np.float64], segments: NDArray[np.float64]) -> PrimitiveGrid:
    """Bucket the circles' bounding boxes and the cells each segment passes through."""
    starts, ends = segments[:, 0:2], segments[:, 2:4]
    lo = np.vstack([circles[:, :2] - circles[:, 2:3], np.minimum(starts, ends)])
    hi = np.vstack([circles[:, :2] + circles[:, 2:3], np.maximum(starts, ends)])
    if len(lo) == 0:
        empty = np.zeros(2, dtype=np.int64)
        return PrimitiveGrid(0.0, 0.0, 1.0, 1, 1, empty, empty[:0], empty, empty[:0])
    x0, y0 = lo.min(axis=0)
    width, height = np.maximum(hi.max(axis=0) - (x0, y0), 1e-9)
    # A thin extent (one straight wall) must not shrink the area, and with it the cell, to zero.
    area = max(width * height, (max(width, height) / 16.0) ** 2)
    cell = max(
        float(np.sqrt(area * _PRIMITIVES_PER_CELL / len(lo))),
        max(width, height) / _MAX_CELLS_PER_AXIS,
    )
    nx, ny = int(np.ceil(width / cell)) + 1, int(np.ceil(height / cell)) + 1

    def box_cells(box_lo: NDArray, box_hi: NDArray) -> tuple[NDArray, NDArray]:
        """(box index, cell id) of every cell each box touches."""
        ix0, ix1 = _cell_index(box_lo[:, 0], x0, cell, nx), _cell_index(box_hi[:, 0], x0, cell, nx)
        iy0, iy1 = _cell_index(box_lo[:, 1], y0, cell, ny), _cell_index(box_hi[:, 1], y0, cell, ny)
        span_x = ix1 - ix0 + 1
        counts = span_x * (iy1 - iy0 + 1)
        box = np.repeat(np.arange(len(box_lo)), counts)
        local = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
        return box, (iy0[box] + local // span_x[box]) * nx + ix0[box] + local % span_x[box]

    def csr(owner: NDArray, cells: NDArray) -> tuple[NDArray, NDArray]:
        order = np.argsort(cells, kind="stable")
        start = np.concatenate([[0], np.cumsum(np.bincount(cells, minlength=nx * ny))])
        return start.astype(np.int64), owner[order].astype(np.int64)

    n = len(circles)
    circle_start, circle_ids = csr(*box_cells(lo[:n], hi[:n]))
    # A long diagonal segment's box covers many cells it never enters: split each segment into
    # pieces no longer than a cell and take the pieces' boxes, padded against rounding.
    lengths = np.hypot(*(ends - starts).T)
    pieces = np.maximum(np.ceil(lengths / cell), 1).astype(np.int64)
    owner = np.repeat(np.arange(len(segments)), pieces)
    k = np.arange(pieces.sum()) - np.repeat(np.cumsum(pieces) - pieces, pieces)
    u0, u1 = (k / pieces[owner])[:, None], ((k + 1) / pieces[owner])[:, None]
    a = starts[owner] + u0 * (ends - starts)[owner]
    b = starts[owner] + u1 * (ends - starts)[owner]
    pad = 1e-9 * cell
    piece, cells = box_cells(np.minimum(a, b) - pad, np.maximum(a, b) + pad)
    key = np.unique(owner[piece] * (nx * ny) + cells)
    segment_start, segment_ids = csr(key // (nx * ny), key % (nx * ny))
    return PrimitiveGrid(
        float(x0), float(y0), cell, nx, ny, circle_start, circle_ids, segment_start, segment_ids
    )


#: Header of :func:`pack_scan_world`'s int array: circle and segment counts, first polygon
#: edge, nx, ny, the next free seen stamp, and the lengths of the grid's four id arrays.
N_CIRCLES, N_SEGMENTS, FIRST_EDGE, NX, NY, STAMP = range(6)
_HEADER = 10


def pack_scan_world(circles: NDArray[np.float64], segments: NDArray[np.float64],
                    first_polygon_edge: int, grid: PrimitiveGrid) -> tuple[NDArray, NDArray]:
    """A world's primitives and grid as two arrays, ``(floats, ints)``: ``x0, y0, cell``, the
    circles and segments raveled; the header (see :data:`STAMP`), the grid's id arrays and
    zeroed seen marks for the Lidar's casts (numba takes two arrays several microseconds
    faster than the dozen they hold). Unpacked by :func:`unpack_scan_world`."""
    parts = [grid.circle_start, grid.circle_ids, grid.segment_start, grid.segment_ids]
    header = [len(circles), len(segments), first_polygon_edge, grid.nx, grid.ny, 1,
              *[len(part) for part in parts]]
    floats = np.concatenate([[grid.x0, grid.y0, grid.cell], np.ravel(circles),
                             np.ravel(segments)]).astype(np.float64)
    ints = np.concatenate([header, *parts, np.zeros(len(circles) + len(segments))])
    return floats, ints.astype(np.int64)


@njit(cache=True, fastmath=False)
def unpack_scan_world(floats: NDArray[np.float64], ints: NDArray[np.int64]) -> tuple:
    """``(circles, segments, first_polygon_edge, grid, seen, stamp)``, views of a packed
    world (``grid`` the :class:`PrimitiveGrid` fields as a plain tuple)."""
    n, m = ints[N_CIRCLES], ints[N_SEGMENTS]
    circles = floats[3:3 + 3 * n].reshape((n, 3))
    segments = floats[3 + 3 * n:3 + 3 * n + 4 * m].reshape((m, 4))
    a = _HEADER
    b = a + ints[6]
    c = b + ints[7]
    d = c + ints[8]
    e = d + ints[9]
    grid = (floats[0], floats[1], floats[2], ints[NX], ints[NY], ints[a:b], ints[b:c],
            ints[c:d], ints[d:e])
    return circles, segments, ints[FIRST_EDGE], grid, (ints[e:e + n], ints[e + n:e + n + m]), \
        ints[STAMP]


@njit(cache=True, fastmath=False)
def point_segment_distance2(px: float, py: float, x1: float, y1: float, x2: float,
                            y2: float) -> float:
    """Squared distance [m^2] from a point to the segment ``(x1, y1)-(x2, y2)`` (no sqrt, at
    most one division)."""
    ex, ey = x2 - x1, y2 - y1
    wx, wy = px - x1, py - y1
    along = wx * ex + wy * ey
    if along <= 0.0:
        return wx * wx + wy * wy
    length2 = ex * ex + ey * ey
    if along >= length2:
        return (wx - ex) * (wx - ex) + (wy - ey) * (wy - ey)
    cross = wx * ey - wy * ex
    return cross * cross / length2


@njit(cache=True, fastmath=False)
def segment_distance2(px: float, py: float, seg: NDArray[np.float64]) -> float:
    """:func:`point_segment_distance2` to a segment row ``x1, y1, x2, y2``."""
    return point_segment_distance2(px, py, seg[0], seg[1], seg[2], seg[3])


@njit(cache=True, fastmath=False)
def grid_cell(value: float, origin: float, cell: float, count: int) -> int:
    """Grid index of a coordinate [m], clipped to ``[0, count)``."""
    return min(max(int(math.floor((value - origin) / cell)), 0), count - 1)


@njit(cache=True, fastmath=False)
def cell_block(px: float, py: float, reach: float, wedge: tuple,
               grid: tuple) -> tuple[int, int, int, int, int, int]:
    """The cells ``[c0, c1] x [r0, r1]`` over the bounding box of the sector of radius
    ``reach`` [m] around ``(px, py)`` spanning ``wedge`` = ``(width [rad], ax, ay, bx, by)``
    from the unit vector ``a`` counter-clockwise to ``b`` (``width`` >= 2 pi: the whole disc),
    padded against rounding; and the point's cell ``(sx, sy)``. ``grid`` is a
    :class:`PrimitiveGrid` or a plain tuple of its fields."""
    x0, y0, size, nx, ny = grid[0], grid[1], grid[2], grid[3], grid[4]
    lo_x, lo_y, hi_x, hi_y = px - reach, py - reach, px + reach, py + reach
    width, ax, ay, bx, by = wedge
    if width < 2.0 * math.pi:
        lo_x, hi_x = min(0.0, ax, bx), max(0.0, ax, bx)
        lo_y, hi_y = min(0.0, ay, by), max(0.0, ay, by)
        for ux, uy in ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)):
            after_a, before_b = ax * uy - ay * ux >= 0.0, ux * by - uy * bx >= 0.0
            if (after_a and before_b) if width <= math.pi else (after_a or before_b):
                lo_x, hi_x = min(lo_x, ux), max(hi_x, ux)
                lo_y, hi_y = min(lo_y, uy), max(hi_y, uy)
        pad = 1e-9 * (reach + size)
        lo_x, hi_x = px + reach * lo_x - pad, px + reach * hi_x + pad
        lo_y, hi_y = py + reach * lo_y - pad, py + reach * hi_y + pad
    return (grid_cell(lo_x, x0, size, nx), grid_cell(hi_x, x0, size, nx),
            grid_cell(lo_y, y0, size, ny), grid_cell(hi_y, y0, size, ny),
            grid_cell(px, x0, size, nx), grid_cell(py, y0, size, ny))


@njit(cache=True, fastmath=False)
def odd_crossings(
    px: float,
    py: float,
    segments: NDArray[np.float64],
    first_polygon_edge: int,
    grid: tuple,
    seen: NDArray[np.int64],
    stamp: int,
) -> bool:
    """Even-odd crossing test (ray towards +x) of the point against all polygon edges.

    Only the grid row holding ``py`` can list edges that cross the ray's line, and only from
    the point's column on (padded: a crossing rounded onto the point still counts); ``seen``
    and ``stamp`` make an edge listed in several cells of the row count once. ``grid`` is a
    :class:`PrimitiveGrid` or a plain tuple of its fields.
    """
    if first_polygon_edge >= segments.shape[0]:
        return False
    x0, y0, size, nx, ny, segment_start, segment_ids = (grid[0], grid[1], grid[2], grid[3],
                                                        grid[4], grid[7], grid[8])
    row = grid_cell(py, y0, size, ny)
    first = row * nx + grid_cell(px - 1e-6 * size, x0, size, nx)
    inside = False
    for c in range(first, (row + 1) * nx):
        for p in range(segment_start[c], segment_start[c + 1]):
            i = segment_ids[p]
            if i < first_polygon_edge or seen[i] == stamp:
                continue
            seen[i] = stamp
            x1, y1, x2, y2 = segments[i, 0], segments[i, 1], segments[i, 2], segments[i, 3]
            if (y1 > py) != (y2 > py) and px < x1 + (py - y1) * (x2 - x1) / (y2 - y1):
                inside = not inside
    return inside


@njit(cache=True, fastmath=False)
def point_queries(
    points: NDArray[np.float64],
    circles: NDArray[np.float64],
    segments: NDArray[np.float64],
    first_polygon_edge: int,
    grid: PrimitiveGrid,
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Signed clearance [m] and inside flag of each point.

    The clearance is the minimum over the signed distance of every circle, the distance of every
    wall and +-(distance to the nearest polygon edge), minus inside the even-odd polygon region.
    Nearest primitives are found by searching grid cells in square rings around the point's
    cell until no unvisited cell can hold anything nearer.
    """
    circle_seen = np.zeros(circles.shape[0], dtype=np.int64)
    segment_seen = np.zeros(segments.shape[0], dtype=np.int64)
    clearance = np.empty(points.shape[0])
    inside = np.zeros(points.shape[0], dtype=np.bool_)
    x0, y0, size, nx, ny = grid[0], grid[1], grid[2], grid[3], grid[4]
    circle_start, circle_ids, segment_start, segment_ids = grid[5], grid[6], grid[7], grid[8]
    for k in range(points.shape[0]):
        px, py = points[k, 0], points[k, 1]
        odd = odd_crossings(px, py, segments, first_polygon_edge, grid, segment_seen, -(k + 1))
        nearest = math.inf  # over circles (signed) and walls
        nearest_edge = math.inf  # over polygon edges
        sx, sy = grid_cell(px, x0, size, nx), grid_cell(py, y0, size, ny)
        ring = 0
        while True:
            for iy in range(max(0, sy - ring), min(ny - 1, sy + ring) + 1):
                if iy == sy - ring or iy == sy + ring:  # the ring's top or bottom row
                    ix, ix_last, ix_step = max(0, sx - ring), min(nx - 1, sx + ring), 1
                else:  # the ring's left and right cells
                    ix, ix_last, ix_step = sx - ring, sx + ring, 2 * ring
                while ix <= ix_last:
                    column = ix
                    ix += ix_step
                    if column < 0 or column >= nx:  # that side of the ring is off the grid
                        continue
                    c = iy * nx + column
                    for p in range(circle_start[c], circle_start[c + 1]):
                        i = circle_ids[p]
                        if circle_seen[i] != k + 1:
                            circle_seen[i] = k + 1
                            d = math.sqrt((px - circles[i, 0]) ** 2 + (py - circles[i, 1]) ** 2)
                            nearest = min(nearest, d - circles[i, 2])
                    for p in range(segment_start[c], segment_start[c + 1]):
                        i = segment_ids[p]
                        if segment_seen[i] != k + 1:
                            segment_seen[i] = k + 1
                            d = math.sqrt(segment_distance2(px, py, segments[i]))
                            if i < first_polygon_edge:
                                nearest = min(nearest, d)
                            else:
                                nearest_edge = min(nearest_edge, d)
            # Distance from the point to the nearest cell not yet visited (inf: none left).
            unvisited = math.inf
            if sx + ring < nx - 1:
                unvisited = min(unvisited, x0 + (sx + ring + 1) * size - px)
            if sx - ring > 0:
                unvisited = min(unvisited, px - (x0 + (sx - ring) * size))
            if sy + ring < ny - 1:
                unvisited = min(unvisited, y0 + (sy + ring + 1) * size - py)
            if sy - ring > 0:
                unvisited = min(unvisited, py - (y0 + (sy - ring) * size))
            # Inside a polygon its nearest edge sets the depth; a circle around the point is
            # listed in the point's own cell.
            found = nearest_edge if odd else min(nearest, nearest_edge)
            if found <= unvisited:
                break
            ring += 1
        clearance[k] = min(nearest, -nearest_edge if odd else nearest_edge)
        inside[k] = odd or nearest < 0.0
    return clearance, inside
