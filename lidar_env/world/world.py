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
import numbers
import os
from collections.abc import Sequence
from functools import cached_property
from pathlib import Path

import numpy as np
import pymunk
from numpy.typing import ArrayLike, NDArray

from lidar_env.core.errors import MapError, quoted
from lidar_env.world.occupancy_image import PixelGrid, read_occupancy, trace_outlines
from lidar_env.world.polygons import (
    as_polygon,
    as_rows,
    convex_pieces,
    even_odd_inside,
    polygon_edges,
)
from lidar_env.world.primitive_grid import PrimitiveGrid, build_grid, point_queries
from lidar_env.world.ros_map import RosMap, read_ros_map

#: [m] margin either side of a flat default bounding box (a world of one straight wall).
FLAT_BOUNDS_MARGIN = 0.5
#: [m] largest coordinate of a world's bounds (either sign): a continent, far beyond any map a
#: planar Lidar drives in, while float64 still holds positions to a nanometre there (larger
#: worlds overflow areas and grid sizes to inf).
MAX_WORLD_EXTENT = 1e7


def _check_resolution(resolution: object) -> float:
    """A pixel size [m]: a positive finite real number (a string such as ``"0.05"`` is named,
    not mangled)."""
    value = None
    if isinstance(resolution, numbers.Real) and not isinstance(resolution, (bool, np.bool_)):
        try:
            value = float(resolution)
        except OverflowError:  # an int beyond float's range
            value = None
    if value is None or not (math.isfinite(value) and value > 0):
        raise MapError(f"resolution: expected a positive pixel size [m], got "
                       f"{type(resolution).__name__} {quoted(resolution)}")
    return value


#: ``collision_type`` of every static obstacle shape added by :meth:`World.build_space`.
OBSTACLE_COLLISION_TYPE: int = 1


class World:
    """Static obstacles [m] seen by the Lidars and collided with by the car.

    Args:
        circles: ``(N, 3)`` rows ``cx, cy, r`` with ``r > 0``.
        segments: ``(M, 4)`` rows ``x1, y1, x2, y2``: zero-thickness walls of non-zero length.
        polygons: sequence of ``(k, 2)`` vertex arrays (closed implicitly, any orientation),
            filled with the even-odd rule (see the module docstring).
        name: label for plots and logs.
        bounds: ``(xmin, ymin, xmax, ymax)`` of the map; default: the bounding box of the geometry.
            Either way within :data:`MAX_WORLD_EXTENT` (1e7 m) of the origin.

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
        self.circles = as_rows(circles, 3, "circles").copy()
        if np.any(self.circles[:, 2] <= 0):
            bad = int(np.argmax(self.circles[:, 2] <= 0))
            raise MapError(
                f"circles[{bad}]: expected a positive radius, got {self.circles[bad, 2]}"
            )
        self.walls = as_rows(segments, 4, "segments").copy()
        lengths = np.hypot(*(self.walls[:, 2:4] - self.walls[:, 0:2]).T)
        if np.any(lengths <= 0):
            bad = int(np.argmax(lengths <= 0))
            raise MapError(
                f"segments[{bad}]: expected two distinct end points, got {self.walls[bad]}"
            )
        if isinstance(polygons, np.ndarray) and polygons.ndim == 2:
            raise MapError(
                f"polygons: expected a sequence of (k, 2) arrays, got one array {polygons.shape}; "
                "wrap a single polygon in a list"
            )
        self.polygons = [as_polygon(p, i) for i, p in enumerate(polygons)]
        edges = [polygon_edges(p) for p in self.polygons]
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
                raise MapError(
                    "bounds: expected (xmin, ymin, xmax, ymax) for a world without obstacles"
                )
            lo, hi = points.min(axis=0), points.max(axis=0)
            # a world of one straight wall (or of collinear ones) spans no area: give the
            # flat axis a margin so the box can be drawn and rasterised
            flat = hi - lo <= 0
            lo, hi = lo - flat * FLAT_BOUNDS_MARGIN, hi + flat * FLAT_BOUNDS_MARGIN
            box = np.array([lo[0], lo[1], hi[0], hi[1]])
            what = "the geometry's bounding box"
        else:
            try:
                box = np.asarray(bounds, dtype=np.float64)
            except (TypeError, ValueError, OverflowError) as error:
                raise MapError(f"bounds: expected four numbers (xmin, ymin, xmax, ymax), got "
                               f"{quoted(bounds)}") from error
            ordered = box.shape == (4,) and box[0] < box[2] and box[1] < box[3]
            if not (ordered and np.all(np.isfinite(box))):
                raise MapError(
                    f"bounds: expected finite (xmin, ymin, xmax, ymax) with xmin < xmax and "
                    f"ymin < ymax, got {quoted(bounds)}"
                )
            what = "bounds"
        if not np.all(np.abs(box) <= MAX_WORLD_EXTENT):
            raise MapError(
                f"{what}: expected a world within +-{MAX_WORLD_EXTENT:.0e} m, got ({box[0]:.3g}, "
                f"{box[1]:.3g}, {box[2]:.3g}, {box[3]:.3g}) m"
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
        return build_grid(self.circles, self.segments)

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
                0 = free, > 0 = obstacle (the paper's world-map convention). At most 2000 x 2000.
            resolution: pixel size [m].
            origin: world ``(x, y)`` [m] of the bottom-left corner of the image. Row 0 is the
                top (max y): pixel ``(r, c)`` covers ``x in origin_x + [c, c+1) * res`` and
                ``y in origin_y + [H-1-r, H-r) * res``.
            name: world name; default the file stem, or ``"image"``.
            tolerance: Douglas-Peucker simplification [pixels] of the traced staircase
                outlines, in ``[0, 0.5]``; 0.5 keeps every outline within half a pixel.

        The outlines run along pixel edges (:func:`~lidar_env.world.occupancy_image.boundary_loops`,
        vectorised, linear in the image size) before simplification; diagonal neighbours stay
        separate polygons touching at a corner, and outlines of free regions enclosed by
        obstacles become holes by the even-odd rule. The world's bounds are the image extent.
        An image over :data:`~lidar_env.world.occupancy_image.MAX_IMAGE_PIXELS` (2000 x 2000) is a
        :class:`~lidar_env.core.errors.MapError`. 1000 x 1000 px of 5 % speckle (45,000 polygons)
        takes about 10 s of CPU here (``benchmarks/bench_from_image.py``).
        """
        if name is None:
            name = Path(image).stem if isinstance(image, (str, os.PathLike)) else "image"
        pixels = read_occupancy(image)
        resolution = _check_resolution(resolution)
        ox, oy = as_rows(origin, 2, "origin")[0]
        if not 0.0 <= tolerance <= 0.5:
            raise MapError(f"tolerance: expected a value in [0, 0.5] pixels, got {tolerance}")
        height, width = pixels.shape
        bounds = (ox, oy, ox + width * resolution, oy + height * resolution)
        if not np.all(np.abs(bounds) <= MAX_WORLD_EXTENT):
            raise MapError(
                f"resolution: {resolution:.3g} m/px at origin ({ox:.3g}, {oy:.3g}) m spans the "
                f"{height} x {width} px image over ({bounds[0]:.3g}, {bounds[1]:.3g}, "
                f"{bounds[2]:.3g}, {bounds[3]:.3g}) m; expected a world within "
                f"+-{MAX_WORLD_EXTENT:.0e} m"
            )
        loops = trace_outlines(pixels, tolerance)
        polygons = [np.asarray(loop) * resolution + (ox, oy) for loop in loops]
        return cls(polygons=polygons, name=name, bounds=bounds)

    @classmethod
    def from_ros_map(
        cls, yaml_path: str | os.PathLike | RosMap, unknown_is_obstacle: bool = True
    ) -> World:
        """The world of a ROS ``map_server`` map: its YAML (``image``, ``resolution``, ``origin``
        [x, y, yaw], ``negate``, ``occupied_thresh``, ``free_thresh``, ``mode``; see
        :mod:`lidar_env.world.ros_map`) or a :class:`~lidar_env.world.ros_map.RosMap` read from one.
        Traced polygons; unknown cells are obstacles unless ``unknown_is_obstacle`` is False; a
        yaw rotates the map about its origin. A :class:`~lidar_env.core.errors.MapError` names the
        file and key of a bad map."""
        ros = yaml_path if isinstance(yaml_path, RosMap) else read_ros_map(yaml_path)
        blocked = (ros.cells == 100) | ((ros.cells == -1) & bool(unknown_is_obstacle))
        ox, oy, yaw = ros.origin
        if yaw == 0.0:
            return cls.from_image(blocked, ros.resolution, (ox, oy), name=ros.name)
        flat = cls.from_image(blocked, ros.resolution, (0.0, 0.0), name=ros.name)
        height, width = blocked.shape
        corners = np.array([[0, 0], [width, 0], [width, height], [0, height]]) * ros.resolution
        c, s = math.cos(yaw), math.sin(yaw)
        c, s = (round(c), round(s)) if min(abs(c), abs(s)) < 1e-12 else (c, s)  # quarter turns

        def place(points: NDArray[np.float64]) -> NDArray[np.float64]:
            return points @ np.array([[c, s], [-s, c]]) + (ox, oy)

        rect = place(corners.astype(np.float64))
        lo, hi = rect.min(axis=0), rect.max(axis=0)
        box = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
        # the parts of the bounding box outside the rotated image are not map: each box corner
        # and the two image corners on the box edges through it make a solid triangle
        outside = []
        for corner in box:
            if np.min(np.abs(rect - corner).sum(axis=1)) < 1e-9 * (hi - lo).sum():
                continue  # the image fills this corner (a quarter-turn yaw)
            on_row = rect[np.argmin(np.abs(rect[:, 1] - corner[1]))]
            on_column = rect[np.argmin(np.abs(rect[:, 0] - corner[0]))]
            u, v = on_row - corner, on_column - corner
            if abs(u[0] * v[1] - u[1] * v[0]) > 1e-9 * (hi - lo).prod():  # not a sliver
                outside.append(np.array([corner, on_row, on_column]))
        polygons = [place(np.asarray(p, dtype=np.float64)) for p in flat.polygons] + outside
        return cls(polygons=polygons, name=ros.name, bounds=(*lo, *hi))

    def to_image(
        self, resolution: float, bounds: Sequence[float] | None = None
    ) -> NDArray[np.uint8]:
        """Rasterise the obstacles: ``(H, W)`` uint8, 255 = obstacle, 0 = free.

        Same pixel convention as :meth:`from_image` with ``origin = (xmin, ymin)`` of
        ``bounds`` (default :attr:`bounds`); ``H, W = ceil(extent / resolution)``. A pixel is
        occupied when its centre is inside a circle or polygon (even-odd) or it holds a circle
        centre, or a wall passes through it (walls are drawn at least one pixel wide).
        """
        resolution = _check_resolution(resolution)
        xmin, ymin, xmax, ymax = self._check_bounds(self.bounds if bounds is None else bounds)
        width = max(1, int(np.ceil((xmax - xmin) / resolution - 1e-9)))
        height = max(1, int(np.ceil((ymax - ymin) / resolution - 1e-9)))
        if width * height > 50_000_000:
            raise MapError(
                f"to_image: expected at most 5e7 pixels, got {height} x {width}; "
                "use a coarser resolution or smaller bounds"
            )
        grid = PixelGrid(xmin, ymin, resolution, height, width)
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
            for piece in convex_pieces(polygon):
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
            inside = even_odd_inside(firsts, polygon_edges(polygon))
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
        pts = np.ascontiguousarray(as_rows(points, 2, "points"))
        return point_queries(pts, self.circles, self.segments, len(self.walls), self.grid)[1]

    def clearance(self, points: ArrayLike) -> NDArray[np.float64]:
        """``(N,)`` signed distance [m] from each point ``(N, 2)`` to the nearest obstacle surface.

        Positive in free space; negative inside a circle or polygon (minus the distance to the
        surface it is under). With no obstacles at all, ``inf``.
        """
        pts = np.ascontiguousarray(as_rows(points, 2, "points"))
        return point_queries(pts, self.circles, self.segments, len(self.walls), self.grid)[0]
