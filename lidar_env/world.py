"""Static 2-D worlds: circles, zero-thickness walls and filled polygons, in metres.

A :class:`World` keeps only numpy arrays, so it pickles cheaply and can be shared with worker
processes; :meth:`World.build_space` makes a fresh ``pymunk.Space`` from it on demand.

Polygons are filled with the **even-odd rule**: a point is inside the obstacle region when it
lies inside an odd number of polygons. A polygon nested in another is therefore a hole, which is
how :meth:`World.from_image` represents the free interior of a walled room. Give disjoint
polygons when you mean a union.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from functools import cached_property
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pymunk
from numba import njit
from numpy.typing import ArrayLike, NDArray

#: ``collision_type`` of every static obstacle shape added by :meth:`World.build_space`.
OBSTACLE_COLLISION_TYPE: int = 1

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


def _build_grid(circles: NDArray[np.float64], segments: NDArray[np.float64]) -> PrimitiveGrid:
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


def _as_rows(values: ArrayLike, width: int, what: str) -> NDArray[np.float64]:
    """``values`` as a finite float64 ``(N, width)`` array (empty input gives ``(0, width)``)."""
    array = np.asarray(values, dtype=np.float64)
    if array.size == 0:
        return np.zeros((0, width))
    if array.ndim == 1 and array.shape[0] == width:
        array = array[None, :]
    if array.ndim != 2 or array.shape[1] != width:
        raise ValueError(f"{what}: expected shape (N, {width}), got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{what}: expected finite values, got NaN or inf")
    return array


def _as_polygon(vertices: ArrayLike, index: int) -> NDArray[np.float64]:
    """One polygon as ``(k, 2)`` float64 with k >= 3 distinct vertices, closing vertex dropped."""
    polygon = np.asarray(vertices, dtype=np.float64)
    if polygon.ndim != 2 or polygon.shape[1] != 2:
        raise ValueError(f"polygons[{index}]: expected shape (k, 2), got {polygon.shape}")
    if not np.all(np.isfinite(polygon)):
        raise ValueError(f"polygons[{index}]: expected finite vertices, got NaN or inf")
    # Drop repeated consecutive vertices (including a closing copy of the first): they would
    # make zero-length edges.
    polygon = polygon[np.any(polygon != np.roll(polygon, 1, axis=0), axis=1)].copy()
    if len(polygon) < 3:
        raise ValueError(f"polygons[{index}]: expected >= 3 distinct vertices, got {len(polygon)}")
    if abs(_signed_area(polygon)) <= 0.0:
        raise ValueError(f"polygons[{index}]: expected a non-zero area, got collinear vertices")
    return polygon


def _signed_area(polygon: NDArray[np.float64]) -> float:
    """Shoelace area [m^2] of a ``(k, 2)`` polygon, positive when counter-clockwise."""
    x, y = polygon[:, 0], polygon[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def _polygon_edges(polygon: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(k, 4)`` edges ``x1, y1, x2, y2`` of a closed polygon."""
    return np.hstack([polygon, np.roll(polygon, -1, axis=0)])


def segment_distances(points: NDArray[np.float64], segments: NDArray[np.float64]) -> NDArray:
    """``(N, M)`` Euclidean distance [m] from each point ``(N, 2)`` to each segment ``(M, 4)``."""
    start = segments[None, :, 0:2]
    edge = segments[None, :, 2:4] - start
    offset = points[:, None, :] - start
    length2 = np.maximum(np.sum(edge * edge, axis=-1), np.finfo(float).tiny)
    u = np.clip(np.sum(offset * edge, axis=-1) / length2, 0.0, 1.0)
    return np.linalg.norm(offset - u[..., None] * edge, axis=-1)


def even_odd_inside(points: NDArray[np.float64], edges: NDArray[np.float64]) -> NDArray[np.bool_]:
    """``(N,)`` True where a point has an odd number of ``edges`` (``(M, 4)``) to its right.

    The crossing-number test of a horizontal ray towards +x: with the edges of closed polygons it
    is the even-odd fill rule.
    """
    px, py = points[:, None, 0], points[:, None, 1]
    x1, y1, x2, y2 = (edges[None, :, i] for i in range(4))
    spans = (y1 > py) != (y2 > py)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_cross = x1 + (py - y1) * (x2 - x1) / (y2 - y1)
    crossings = spans & (px < x_cross)
    return (np.count_nonzero(crossings, axis=1) % 2) == 1


class World:
    """Static obstacles [m] seen by the Lidars and collided with by the car.

    Args:
        circles: ``(N, 3)`` rows ``cx, cy, r`` with ``r > 0``.
        segments: ``(M, 4)`` rows ``x1, y1, x2, y2``: zero-thickness walls of non-zero length.
        polygons: sequence of ``(k, 2)`` vertex arrays (closed implicitly, any orientation),
            filled with the even-odd rule (see the module docstring).
        name: label for plots and logs.
        bounds: ``(xmin, ymin, xmax, ymax)`` of the map; default: the bounding box of the geometry.

    Attributes:
        circles: ``(N, 3)`` float64.
        walls: ``(M, 4)`` float64, the segments given.
        segments: ``(M + E, 4)`` float64: the walls followed by all ``E`` polygon edges, i.e.
            every line the Lidar can see.
        polygons: list of ``(k, 2)`` float64 vertex arrays.
        bounds: ``(xmin, ymin, xmax, ymax)`` tuple of floats.
        grid: :class:`PrimitiveGrid` bucketing the primitives for range and nearest queries
            (built on first use; not pickled).

    All arrays are read-only copies, so the cached grid always matches the geometry.
    """

    def __init__(
        self,
        circles: ArrayLike = (),
        segments: ArrayLike = (),
        polygons: Sequence[ArrayLike] = (),
        name: str = "custom",
        bounds: Sequence[float] | None = None,
    ) -> None:
        self.name = str(name)
        self.circles = _as_rows(circles, 3, "circles").copy()
        if np.any(self.circles[:, 2] <= 0):
            bad = int(np.argmax(self.circles[:, 2] <= 0))
            raise ValueError(
                f"circles[{bad}]: expected a positive radius, got {self.circles[bad, 2]}"
            )
        self.walls = _as_rows(segments, 4, "segments").copy()
        lengths = np.hypot(*(self.walls[:, 2:4] - self.walls[:, 0:2]).T)
        if np.any(lengths <= 0):
            bad = int(np.argmax(lengths <= 0))
            raise ValueError(
                f"segments[{bad}]: expected two distinct end points, got {self.walls[bad]}"
            )
        if isinstance(polygons, np.ndarray) and polygons.ndim == 2:
            raise ValueError(
                f"polygons: expected a sequence of (k, 2) arrays, got one array {polygons.shape}; "
                "wrap a single polygon in a list"
            )
        self.polygons = [_as_polygon(p, i) for i, p in enumerate(polygons)]
        edges = [_polygon_edges(p) for p in self.polygons]
        self.polygon_edges = np.vstack(edges) if edges else np.zeros((0, 4))
        self.segments = np.ascontiguousarray(np.vstack([self.walls, self.polygon_edges]))
        self.bounds = self._check_bounds(bounds)
        self._freeze()

    def _freeze(self) -> None:
        """Make the arrays read-only: the lazily built grid (and anyone holding them) stays
        valid."""
        for array in (self.circles, self.walls, self.polygon_edges, self.segments, *self.polygons):
            array.flags.writeable = False

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state.pop("grid", None)  # cheap to rebuild; keeps pickles small
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._freeze()

    def _check_bounds(self, bounds: Sequence[float] | None) -> tuple[float, float, float, float]:
        if bounds is None:
            corners = [self.circles[:, :2] - self.circles[:, 2:3]]
            corners.append(self.circles[:, :2] + self.circles[:, 2:3])
            corners.append(self.segments[:, 0:2])
            corners.append(self.segments[:, 2:4])
            points = np.vstack(corners)
            if len(points) == 0:
                raise ValueError(
                    "bounds: expected (xmin, ymin, xmax, ymax) for a world without obstacles"
                )
            lo, hi = points.min(axis=0), points.max(axis=0)
            return (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
        box = np.asarray(bounds, dtype=np.float64)
        ordered = box.shape == (4,) and box[0] < box[2] and box[1] < box[3]
        if not (ordered and np.all(np.isfinite(box))):
            raise ValueError(
                f"bounds: expected finite (xmin, ymin, xmax, ymax) with xmin < xmax and "
                f"ymin < ymax, got {bounds}"
            )
        return (float(box[0]), float(box[1]), float(box[2]), float(box[3]))

    def __repr__(self) -> str:
        return (
            f"World(name={self.name!r}, circles={len(self.circles)}, walls={len(self.walls)}, "
            f"polygons={len(self.polygons)}, bounds={self.bounds})"
        )

    @cached_property
    def grid(self) -> PrimitiveGrid:
        """The primitives bucketed in a uniform grid (built on first use, then kept)."""
        return _build_grid(self.circles, self.segments)

    @property
    def n_primitives(self) -> int:
        """Circles plus segments (walls and polygon edges): what the Lidar kernel tests."""
        return len(self.circles) + len(self.segments)

    # ------------------------------------------------------------------ images
    @classmethod
    def from_image(
        cls,
        image: ArrayLike | str | os.PathLike,
        resolution: float,
        origin: Sequence[float] = (0.0, 0.0),
        name: str | None = None,
        tolerance: float = 0.5,
    ) -> World:
        """A world of polygons traced around the occupied pixels of an occupancy image.

        Args:
            image: 2-D array, or path to an image file read as greyscale (PNG, PGM, ...);
                0 = free, > 0 = obstacle (the paper's world-map convention). Up to ~2000 x 2000.
            resolution: pixel size [m].
            origin: world ``(x, y)`` [m] of the bottom-left corner of the image. Row 0 is the
                top (max y): pixel ``(r, c)`` covers ``x in origin_x + [c, c+1) * res`` and
                ``y in origin_y + [H-1-r, H-r) * res``.
            name: world name; default the file stem, or ``"image"``.
            tolerance: Douglas-Peucker simplification [pixels] of the traced staircase
                outlines, in ``[0, 0.5]``; 0.5 keeps every outline within half a pixel.

        The outlines come from ``pymunk.autogeometry.march_hard`` on pixel centres, so they run
        along pixel edges before simplification; outlines of free regions enclosed by obstacles
        become holes by the even-odd rule. The world's bounds are the image extent. Tracing
        calls back into Python once per pixel: about 5 s for 2000 x 2000 pixels.
        """
        if name is None:
            name = Path(image).stem if isinstance(image, (str, os.PathLike)) else "image"
        pixels = _read_occupancy(image)
        if not (np.isfinite(resolution) and resolution > 0):
            raise ValueError(f"resolution: expected a positive pixel size [m], got {resolution}")
        ox, oy = _as_rows(origin, 2, "origin")[0]
        if not 0.0 <= tolerance <= 0.5:
            raise ValueError(f"tolerance: expected a value in [0, 0.5] pixels, got {tolerance}")
        height, width = pixels.shape
        loops = _trace_outlines(pixels, tolerance)
        polygons = [np.asarray(loop) * resolution + (ox, oy) for loop in loops]
        bounds = (ox, oy, ox + width * resolution, oy + height * resolution)
        return cls(polygons=polygons, name=name, bounds=bounds)

    def to_image(
        self, resolution: float, bounds: Sequence[float] | None = None
    ) -> NDArray[np.uint8]:
        """Rasterise the obstacles: ``(H, W)`` uint8, 255 = obstacle, 0 = free.

        Same pixel convention as :meth:`from_image` with ``origin = (xmin, ymin)`` of
        ``bounds`` (default :attr:`bounds`); ``H, W = ceil(extent / resolution)``. A pixel is
        occupied when its centre is inside a circle or polygon (even-odd) or it holds a circle
        centre, or a wall passes through it (walls are drawn at least one pixel wide).
        """
        if not (np.isfinite(resolution) and resolution > 0):
            raise ValueError(f"resolution: expected a positive pixel size [m], got {resolution}")
        xmin, ymin, xmax, ymax = self._check_bounds(self.bounds if bounds is None else bounds)
        width = max(1, int(np.ceil((xmax - xmin) / resolution - 1e-9)))
        height = max(1, int(np.ceil((ymax - ymin) / resolution - 1e-9)))
        if width * height > 50_000_000:
            raise ValueError(
                f"to_image: expected at most 5e7 pixels, got {height} x {width}; "
                "use a coarser resolution or smaller bounds"
            )
        grid = _PixelGrid(xmin, ymin, resolution, height, width)
        occupied = grid.even_odd_fill(self.polygon_edges)
        for cx, cy, r in self.circles:
            grid.mark_disc(occupied, cx, cy, r)
        for wall in self.walls:
            grid.mark_segment(occupied, wall)
        return np.where(occupied, np.uint8(255), np.uint8(0))

    # ------------------------------------------------------------------ pymunk
    def build_space(self) -> pymunk.Space:
        """A fresh ``pymunk.Space`` holding every obstacle as a static shape.

        Circles become ``pymunk.Circle``, walls and polygon edges ``pymunk.Segment`` of radius 0
        (so ray queries see exactly the lines the Lidar kernel sees), and each polygon that is
        not part of a nesting (no hole, not inside another polygon) is also added as convex
        ``pymunk.Poly`` pieces so that it is solid. All shapes get
        ``collision_type = OBSTACLE_COLLISION_TYPE``.
        """
        space = pymunk.Space()
        body = space.static_body
        shapes: list[pymunk.Shape] = []
        for cx, cy, r in self.circles:
            shapes.append(pymunk.Circle(body, float(r), offset=(float(cx), float(cy))))
        for x1, y1, x2, y2 in self.segments:
            shapes.append(pymunk.Segment(body, (float(x1), float(y1)), (float(x2), float(y2)), 0.0))
        for polygon in self._solid_polygons():
            for piece in _convex_pieces(polygon):
                shapes.append(pymunk.Poly(body, [tuple(v) for v in piece], radius=0.0))
        for shape in shapes:
            shape.collision_type = OBSTACLE_COLLISION_TYPE
        space.add(*shapes)
        return space

    def _solid_polygons(self) -> list[NDArray[np.float64]]:
        """Polygons that neither contain nor lie inside another polygon (safe to fill alone)."""
        if len(self.polygons) < 2:
            return list(self.polygons)
        firsts = np.array([p[0] for p in self.polygons])
        nested = np.zeros(len(self.polygons), dtype=bool)
        for i, polygon in enumerate(self.polygons):
            inside = even_odd_inside(firsts, _polygon_edges(polygon))
            inside[i] = False
            if np.any(inside):
                nested[i] = True
                nested[inside] = True
        return [p for p, n in zip(self.polygons, nested, strict=True) if not n]

    # ------------------------------------------------------------------ queries
    def contains(self, points: ArrayLike) -> NDArray[np.bool_]:
        """``(N,)`` True where a point ``(N, 2)`` [m] is strictly inside a circle or polygon.

        Walls have zero thickness and contain nothing.
        """
        pts = np.ascontiguousarray(_as_rows(points, 2, "points"))
        return _point_queries(pts, self.circles, self.segments, len(self.walls), self.grid)[1]

    def clearance(self, points: ArrayLike) -> NDArray[np.float64]:
        """``(N,)`` signed distance [m] from each point ``(N, 2)`` to the nearest obstacle surface.

        Positive in free space; negative inside a circle or polygon (minus the distance to the
        surface it is under). With no obstacles at all, ``inf``.
        """
        pts = np.ascontiguousarray(_as_rows(points, 2, "points"))
        return _point_queries(pts, self.circles, self.segments, len(self.walls), self.grid)[0]


@njit(cache=True, fastmath=False)
def segment_distance2(px: float, py: float, seg: NDArray[np.float64]) -> float:
    """Squared distance [m^2] from a point to a segment ``x1, y1, x2, y2`` (no sqrt, at most
    one division)."""
    ex, ey = seg[2] - seg[0], seg[3] - seg[1]
    wx, wy = px - seg[0], py - seg[1]
    along = wx * ex + wy * ey
    if along <= 0.0:
        return wx * wx + wy * wy
    length2 = ex * ex + ey * ey
    if along >= length2:
        return (wx - ex) * (wx - ex) + (wy - ey) * (wy - ey)
    cross = wx * ey - wy * ex
    return cross * cross / length2


@njit(cache=True, fastmath=False)
def grid_cell(value: float, origin: float, cell: float, count: int) -> int:
    """Grid index of a coordinate [m], clipped to ``[0, count)``."""
    return min(max(int(math.floor((value - origin) / cell)), 0), count - 1)


@njit(cache=True, fastmath=False)
def odd_crossings(
    px: float,
    py: float,
    segments: NDArray[np.float64],
    first_polygon_edge: int,
    grid: PrimitiveGrid,
    seen: NDArray[np.int64],
    stamp: int,
) -> bool:
    """Even-odd crossing test (ray towards +x) of the point against all polygon edges.

    Only the grid row holding ``py`` can list edges that cross the ray's line; ``seen`` and
    ``stamp`` make an edge listed in several cells of the row count once.
    """
    if first_polygon_edge >= segments.shape[0]:
        return False
    row = grid_cell(py, grid.y0, grid.cell, grid.ny)
    inside = False
    for c in range(row * grid.nx, (row + 1) * grid.nx):
        for p in range(grid.segment_start[c], grid.segment_start[c + 1]):
            i = grid.segment_ids[p]
            if i < first_polygon_edge or seen[i] == stamp:
                continue
            seen[i] = stamp
            x1, y1, x2, y2 = segments[i, 0], segments[i, 1], segments[i, 2], segments[i, 3]
            if (y1 > py) != (y2 > py) and px < x1 + (py - y1) * (x2 - x1) / (y2 - y1):
                inside = not inside
    return inside


@njit(cache=True, fastmath=False)
def _point_queries(
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
    x0, y0, size, nx, ny = grid.x0, grid.y0, grid.cell, grid.nx, grid.ny
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
                    for p in range(grid.circle_start[c], grid.circle_start[c + 1]):
                        i = grid.circle_ids[p]
                        if circle_seen[i] != k + 1:
                            circle_seen[i] = k + 1
                            d = math.sqrt((px - circles[i, 0]) ** 2 + (py - circles[i, 1]) ** 2)
                            nearest = min(nearest, d - circles[i, 2])
                    for p in range(grid.segment_start[c], grid.segment_start[c + 1]):
                        i = grid.segment_ids[p]
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


def _convex_pieces(polygon: NDArray[np.float64]) -> list[NDArray[np.float64]]:
    """Convex pieces exactly covering a simple polygon: itself if convex, else pymunk's convex
    decomposition, or (if that fails or loses area) an ear-clip triangulation."""
    if _is_convex(polygon):
        return [polygon]
    from pymunk import autogeometry

    ccw = polygon if _signed_area(polygon) > 0 else polygon[::-1]
    extent = float(np.ptp(polygon, axis=0).max())
    try:
        pieces = autogeometry.convex_decomposition([*map(tuple, ccw), tuple(ccw[0])], 0.0)
    except AssertionError:  # pymunk's way of rejecting a polygon it cannot decompose
        return _ear_clip(polygon)
    arrays = [
        cleaned
        for piece in pieces
        if len(cleaned := _drop_collinear(np.array([(v.x, v.y) for v in piece]), extent)) >= 3
    ]
    area = sum(abs(_signed_area(piece)) for piece in arrays)
    if not np.isclose(area, abs(_signed_area(polygon)), rtol=1e-9, atol=0.0):
        return _ear_clip(polygon)
    return arrays


def _drop_collinear(polygon: NDArray[np.float64], extent: float) -> NDArray[np.float64]:
    """The polygon without repeated vertices and vertices on the line through their
    neighbours (to 1e-12 of ``extent`` [m] squared, the size of the polygon it was cut from);
    fewer than 3 rows left means it had no area (pymunk's decomposition can return such
    slivers, e.g. 7.3.1 on a star)."""
    points = polygon
    while len(points) >= 3:
        before, after = np.roll(points, 1, axis=0), np.roll(points, -1, axis=0)
        cross = (points[:, 0] - before[:, 0]) * (after[:, 1] - before[:, 1]) - (
            points[:, 1] - before[:, 1]
        ) * (after[:, 0] - before[:, 0])
        keep = np.abs(cross) > 1e-12 * extent**2
        if keep.all():
            return points
        if not keep.any():
            return points[:0]
        # Drop one vertex at a time: removing both ends of a short edge at once could cut area.
        points = np.delete(points, int(np.argmin(np.abs(cross))), axis=0)
    return points[:0]


def _is_convex(polygon: NDArray[np.float64]) -> bool:
    edge = np.roll(polygon, -1, axis=0) - polygon
    turn = edge[:, 0] * np.roll(edge[:, 1], -1) - edge[:, 1] * np.roll(edge[:, 0], -1)
    return bool(np.all(turn >= 0) or np.all(turn <= 0))


def _ear_clip(polygon: NDArray[np.float64]) -> list[NDArray[np.float64]]:
    """Triangles of a simple polygon by ear clipping (O(k^2)); collinear slivers are dropped."""
    vertices = polygon if _signed_area(polygon) > 0 else polygon[::-1]
    remaining = list(range(len(vertices)))
    triangles: list[NDArray[np.float64]] = []
    guard = 0
    while len(remaining) > 3 and guard < len(remaining):
        k = len(remaining)
        for position in range(k):
            i, j, m = remaining[position - 1], remaining[position], remaining[(position + 1) % k]
            a, b, c = vertices[i], vertices[j], vertices[m]
            cross = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
            if cross < 0:
                continue
            others = vertices[[v for v in remaining if v not in (i, j, m)]]
            if cross > 0 and np.any(_in_triangle(others, a, b, c)):
                continue
            if cross > 0:
                triangles.append(np.array([a, b, c]))
            del remaining[position]
            guard = 0
            break
        else:
            guard = len(remaining)  # no ear found: not a simple polygon; keep what we have
    if len(remaining) == 3:
        tri = vertices[remaining]
        if abs(_signed_area(tri)) > 0:
            triangles.append(tri)
    return triangles


def _in_triangle(points: NDArray, a: NDArray, b: NDArray, c: NDArray) -> NDArray[np.bool_]:
    """``(N,)`` True where points lie inside or on the CCW triangle ``a, b, c``."""
    def side(p: NDArray, q: NDArray) -> NDArray:
        return (q[0] - p[0]) * (points[:, 1] - p[1]) - (q[1] - p[1]) * (points[:, 0] - p[0])

    return (side(a, b) >= 0) & (side(b, c) >= 0) & (side(c, a) >= 0)


def _read_occupancy(image: ArrayLike | str | os.PathLike) -> NDArray[np.bool_]:
    """``(H, W)`` bool occupancy (True = obstacle) of an image array or file, validated."""
    if isinstance(image, (str, os.PathLike)):
        try:
            from PIL import Image, UnidentifiedImageError
        except ImportError as error:  # pragma: no cover - pillow ships with matplotlib
            raise ImportError("World.from_image(path) needs pillow: pip install pillow") from error
        try:
            with Image.open(image) as handle:
                array = np.asarray(handle.convert("L"))
        except (UnidentifiedImageError, OSError, SyntaxError) as error:
            if isinstance(error, FileNotFoundError):
                raise
            raise ValueError(
                f"image: expected a readable image file, got {image!s}: {error}"
            ) from error
    else:
        array = np.asarray(image)
    if array.ndim != 2:
        raise ValueError(f"image: expected a 2-D occupancy array, got shape {array.shape}")
    if array.size == 0:
        raise ValueError(f"image: expected a non-empty image, got shape {array.shape}")
    if array.dtype == bool:
        occupied = array.copy()
    else:
        if not np.issubdtype(array.dtype, np.number):
            raise ValueError(f"image: expected numeric pixel values, got dtype {array.dtype}")
        values = array.astype(np.float64)
        if not np.all(np.isfinite(values)) or np.any(values < 0):
            raise ValueError("image: expected finite pixel values >= 0 (0 = free, > 0 = obstacle)")
        occupied = values > 0
    if occupied.all():
        raise ValueError(f"image: expected some free (0) pixels, got all {array.size} occupied")
    return occupied


def _trace_outlines(occupied: NDArray[np.bool_], tolerance: float) -> list[NDArray[np.float64]]:
    """Closed outlines ``(k, 2)`` [pixels, origin at the bottom-left corner] of the occupied
    pixels, traced by pymunk's marching squares and simplified by Douglas-Peucker."""
    from pymunk import autogeometry

    height, width = occupied.shape
    # One free pixel of padding closes outlines that touch the image border.
    padded = np.pad(occupied, 1).astype(float).tolist()

    def sample(point: tuple[float, float]) -> float:
        # Samples sit on pixel centres (c + 0.5, H - 1 - r + 0.5) in padded index space.
        return padded[int(height + 1.0 - point[1])][int(point[0] + 1.0)]

    box = pymunk.BB(-0.5, -0.5, width + 0.5, height + 0.5)
    polylines = autogeometry.march_hard(box, width + 2, height + 2, 0.5, sample)
    loops = []
    for line in polylines:
        simplified = autogeometry.simplify_curves(line, tolerance) if tolerance > 0 else line
        loop = np.array([(v.x, v.y) for v in simplified])
        if len(loop) > 1 and np.array_equal(loop[0], loop[-1]):
            loop = loop[:-1]
        if len(loop) >= 3 and abs(_signed_area(loop)) > 0:
            loops.append(loop)
    return loops


class _PixelGrid:
    """Pixel-centre geometry of a raster whose row 0 is the top (max y)."""

    def __init__(self, xmin: float, ymin: float, resolution: float, height: int, width: int):
        self.xmin, self.ymin, self.res = xmin, ymin, resolution
        self.height, self.width = height, width

    def rows_of(self, y: NDArray) -> NDArray:
        """Row index whose pixel holds world ``y`` (may be out of range)."""
        return self.height - 1 - np.floor((y - self.ymin) / self.res).astype(np.int64)

    def cols_of(self, x: NDArray) -> NDArray:
        return np.floor((x - self.xmin) / self.res).astype(np.int64)

    def centre_y(self, rows: NDArray) -> NDArray:
        return self.ymin + (self.height - 1 - rows + 0.5) * self.res

    def even_odd_fill(self, edges: NDArray[np.float64]) -> NDArray[np.bool_]:
        """``(H, W)`` even-odd fill of closed polygon ``edges`` at pixel centres (scanlines)."""
        crossings = np.zeros((self.height, self.width + 1), dtype=np.int64)
        if len(edges):
            x1, y1, x2, y2 = edges.T
            # Rows whose centre y lies in [min(y1,y2), max(y1,y2)): rows_of maps y down to rows.
            top = np.clip(self.rows_of(np.maximum(y1, y2)), 0, self.height - 1)
            bottom = np.clip(self.rows_of(np.minimum(y1, y2)), 0, self.height - 1)
            counts = np.maximum(bottom - top + 1, 0)
            edge_of = np.repeat(np.arange(len(edges)), counts)
            rows = np.repeat(top, counts) + (np.arange(counts.sum()) - np.repeat(
                np.cumsum(counts) - counts, counts))
            yc = self.centre_y(rows)
            ya, yb = y1[edge_of], y2[edge_of]
            spans = (ya > yc) != (yb > yc)
            edge_of, rows, yc = edge_of[spans], rows[spans], yc[spans]
            xa, xb, ya, yb = x1[edge_of], x2[edge_of], y1[edge_of], y2[edge_of]
            x_cross = xa + (yc - ya) * (xb - xa) / (yb - ya)
            # Columns c with centre x < x_cross are those c < k.
            k = np.clip(np.ceil((x_cross - self.xmin) / self.res - 0.5), 0, self.width)
            np.add.at(crossings, (rows, k.astype(np.int64)), 1)
        # Crossings right of centre c: total minus those with k <= c.
        right = crossings.sum(axis=1, keepdims=True) - np.cumsum(crossings, axis=1)[:, :-1]
        return (right % 2) == 1

    def _block(self, x_lo: float, y_lo: float, x_hi: float, y_hi: float) -> tuple:
        """Clipped row and column index ranges covering a world box, or None if outside."""
        r0 = max(int(self.rows_of(np.array(y_hi))), 0)
        r1 = min(int(self.rows_of(np.array(y_lo))), self.height - 1)
        c0 = max(int(self.cols_of(np.array(x_lo))), 0)
        c1 = min(int(self.cols_of(np.array(x_hi))), self.width - 1)
        return (r0, r1, c0, c1) if r0 <= r1 and c0 <= c1 else None

    def mark_disc(self, occupied: NDArray[np.bool_], cx: float, cy: float, r: float) -> None:
        """Occupy pixels whose centre is inside the circle, and the pixel of its centre."""
        block = self._block(cx - r, cy - r, cx + r, cy + r)
        if block is None:
            return
        r0, r1, c0, c1 = block
        rows = np.arange(r0, r1 + 1)[:, None]
        cols = np.arange(c0, c1 + 1)[None, :]
        x = self.xmin + (cols + 0.5) * self.res
        y = self.centre_y(rows)
        occupied[r0 : r1 + 1, c0 : c1 + 1] |= np.hypot(x - cx, y - cy) < r
        row, col = int(self.rows_of(np.array(cy))), int(self.cols_of(np.array(cx)))
        if 0 <= row < self.height and 0 <= col < self.width:
            occupied[row, col] = True

    def mark_segment(self, occupied: NDArray[np.bool_], segment: NDArray[np.float64]) -> None:
        """Occupy every pixel the segment passes through (sampled at quarter-pixel steps)."""
        length = float(np.hypot(segment[2] - segment[0], segment[3] - segment[1]))
        u = np.linspace(0.0, 1.0, int(np.ceil(4.0 * length / self.res)) + 2)
        x = segment[0] + u * (segment[2] - segment[0])
        y = segment[1] + u * (segment[3] - segment[1])
        rows, cols = self.rows_of(y), self.cols_of(x)
        keep = (rows >= 0) & (rows < self.height) & (cols >= 0) & (cols < self.width)
        occupied[rows[keep], cols[keep]] = True
