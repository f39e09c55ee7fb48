"""Top-down pictures of a ``DualLidar-v0`` episode, drawn with numpy (PNG files by Pillow).

``rgb_array`` frames need no window and no pygame; the ``human`` window imports pygame only
when first shown, is titled, and closes when the user closes it. A frame covers the world's
bounds, or a ROS map's known area (its unknown cells drawn apart from obstacles,
:mod:`lidar_env.rendering.overlays`), with a scale bar and a legend.

Pixel convention (exactly :meth:`lidar_env.world.world.World.to_image`'s and
``estimators.mapping.occupancy.OccupancyGrid``'s): ``H, W = ceil(extent / resolution)`` pixels
anchored at ``(xmin, ymin)``; pixel ``(row, col)`` covers ``x`` in ``xmin + [col, col + 1) * res``
and ``y`` in ``ymin + [H - 1 - row, H - row) * res``, so row 0 is the top (its upper edge may
reach past ``ymax`` by less than a pixel) and column 0 the left edge. Anchoring at ``ymin`` keeps
the world raster, the points drawn on it and an occupancy-map overlay on the same pixels.

An overlay is anything shaped like :class:`OccupancyMap` (bounds, resolution, probabilities):
the env never imports the estimators that build maps.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from typing import Any, Protocol, runtime_checkable

import numpy as np
from gymnasium.error import DependencyNotInstalled
from numpy.typing import ArrayLike, NDArray
from PIL import Image

from lidar_env.core.errors import ConfigError
from lidar_env.rendering.overlays import UNKNOWN, UnknownCells, legend, paste, scale_bar
from lidar_env.world.world import World

Bounds = tuple[float, float, float, float]

#: Longest image side [pixels] by default: sharp enough to see 0.05 m on a 40 m world.
DEFAULT_MAX_SIZE = 800
#: Margin [-] around a ROS map's known area in a cropped frame, as a fraction of its extent.
CROP_MARGIN = 0.03

FREE = np.array([250, 250, 250], dtype=np.uint8)
OBSTACLE = np.array([40, 40, 40], dtype=np.uint8)
TRACE_COLOUR = np.array([120, 160, 255], dtype=np.uint8)
CAR_COLOUR = np.array([220, 30, 30], dtype=np.uint8)
MOVER_COLOUR = np.array([200, 0, 200], dtype=np.uint8)
#: Opacity of an occupancy-map overlay over the world raster (the world stays visible through it).
MAP_ALPHA = 0.6
LIDAR_COLOURS = (np.array([255, 140, 0], dtype=np.uint8), np.array([0, 170, 80], dtype=np.uint8))
#: Colours cycled through for the trajectories handed in (blue, purple, brown, teal, olive).
TRAJECTORY_COLOURS = tuple(
    np.array(c, dtype=np.uint8)
    for c in ((30, 60, 200), (150, 40, 170), (140, 90, 40), (0, 140, 140), (120, 120, 0))
)


@runtime_checkable
class OccupancyMap(Protocol):
    """What an overlay needs of an occupancy map (``estimators.mapping.occupancy.OccupancyGrid``
    is one): ``bounds`` (xmin, ymin, xmax, ymax) [m], ``resolution`` [m/cell] and
    ``probabilities()``, the ``(rows, cols)`` occupancy probability of each cell (0.5: never
    observed), laid out as :meth:`lidar_env.world.world.World.to_image` (row 0 the top)."""

    bounds: Bounds
    resolution: float

    def probabilities(self) -> NDArray[np.float64]: ...


def raster_shape(bounds: Bounds, resolution: float) -> tuple[int, int]:
    """``(rows, cols)`` of a raster of ``bounds`` at ``resolution`` [m/pixel]; a relative
    tolerance keeps 10 m / 0.05 m at 200 pixels despite rounding."""
    xmin, ymin, xmax, ymax = bounds
    cols = math.ceil((xmax - xmin) / resolution - 1e-9)
    rows = math.ceil((ymax - ymin) / resolution - 1e-9)
    return rows, cols


def occupancy_to_rgb(
    probabilities: ArrayLike,
    map_bounds: Bounds,
    map_resolution: float,
    bounds: Bounds,
    resolution: float,
) -> NDArray[np.uint8]:
    """An ``(H, W, 3)`` uint8 picture of an occupancy map for overlays, row 0 = largest ``y``.

    ``probabilities`` ``(rows, cols)``: the map's cells over ``map_bounds`` at
    ``map_resolution`` [m/cell], laid out as :class:`OccupancyMap`. Grey level
    ``255 * (1 - p)``: occupied cells dark, free cells white, unobserved cells mid-grey (128).
    The picture spans ``bounds`` at ``resolution`` [m/pixel], sampled at pixel centres
    (nearest cell); area outside the map is unobserved."""
    cells_p = np.asarray(probabilities, dtype=np.float64)
    height, width = raster_shape(bounds, resolution)
    xmin, ymin, _, _ = bounds
    x = xmin + (np.arange(width) + 0.5) * resolution
    y = ymin + (height - np.arange(height) - 0.5) * resolution
    centres = np.stack(np.meshgrid(x, y), axis=-1).reshape(-1, 2)
    rows, cols = cells_p.shape
    map_xmin, map_ymin, _, _ = map_bounds
    cells = np.floor(
        np.column_stack(
            [(centres[:, 0] - map_xmin) / map_resolution,
             rows - (centres[:, 1] - map_ymin) / map_resolution]
        )
    ).astype(np.int64)
    inside = (cells[:, 0] >= 0) & (cells[:, 0] < cols) & (cells[:, 1] >= 0) & (cells[:, 1] < rows)
    probability = np.full(len(centres), 0.5)
    probability[inside] = cells_p[cells[inside, 1], cells[inside, 0]]
    grey = np.round(255.0 * (1.0 - probability)).clip(0, 255).astype(np.uint8)
    return np.repeat(grey.reshape(height, width)[..., None], 3, axis=-1)


class Renderer:
    """Draws a world, a trace, the car, both Lidars' hits and trajectories into RGB frames.

    Args:
        world: the world; its obstacle raster is computed once.
        max_size: longest image side [pixels]; sets the scale ``resolution`` [m/pixel].
        unknown: a ROS map's unknown cells: frames are cropped to its known area and unknown
            cells drawn in :data:`~lidar_env.rendering.overlays.UNKNOWN`, not as obstacles.
        title: the ``human`` window's title.
        overlays: draw the scale bar (bottom left) and the legend (top right).
    """

    def __init__(self, world: World, max_size: int = DEFAULT_MAX_SIZE,
                 unknown: UnknownCells | None = None, title: str = "DualLidar-v0",
                 overlays: bool = True) -> None:
        if isinstance(max_size, bool) or not isinstance(max_size, (int, np.integer)) \
                or not 16 <= max_size <= 8192:
            raise ConfigError(f"render_size: expected an integer in [16, 8192] pixels, got "
                              f"{max_size!r:.40}")
        self.world = world
        self.bounds = self._view(world.bounds, unknown)
        xmin, ymin, xmax, ymax = self.bounds
        self.resolution = max(xmax - xmin, ymax - ymin) / max_size
        occupied = world.to_image(self.resolution, self.bounds) > 0
        self.background = np.where(occupied[..., None], OBSTACLE, FREE)
        if unknown is not None:
            hidden = unknown.mask(self.bounds, self.resolution, occupied.shape)
            self.background[hidden] = UNKNOWN
        self.title = title
        self.overlays = overlays
        self.dot = max(3, round(max_size / 266))
        self._legends: dict[tuple[int, bool], NDArray[np.uint8]] = {}
        self._scale = scale_bar(self.resolution, self.shape[1]) if overlays else None
        self.window: Any = None
        self.closed = False
        self._clock: Any = None

    @staticmethod
    def _view(bounds: Bounds, unknown: UnknownCells | None) -> Bounds:
        """The world's ``bounds``, or the known area of ``unknown`` with a margin, within them."""
        known = None if unknown is None else unknown.known_bounds()
        if known is None:
            return tuple(float(v) for v in bounds)  # type: ignore[return-value]
        margin = CROP_MARGIN * max(known[2] - known[0], known[3] - known[1])
        return (max(bounds[0], known[0] - margin), max(bounds[1], known[1] - margin),
                min(bounds[2], known[2] + margin), min(bounds[3], known[3] + margin))

    def _legend(self, n_lidars: int, movers: bool) -> NDArray[np.uint8]:
        """The legend patch for ``n_lidars`` Lidars, with or without movers (built once)."""
        key = (n_lidars, movers)
        if key not in self._legends:
            entries = [("car", CAR_COLOUR), ("trace", TRACE_COLOUR)]
            entries += [(f"lidar_{k + 1} hits", LIDAR_COLOURS[k % len(LIDAR_COLOURS)])
                        for k in range(n_lidars)]
            if movers:
                entries.append(("movers", MOVER_COLOUR))
            if (UNKNOWN == self.background).all(axis=-1).any():
                entries.append(("unknown", UNKNOWN))
            entries.append(("obstacle", OBSTACLE))
            self._legends[key] = legend(entries, self.shape[1])
        return self._legends[key]

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) of every frame [pixels]."""
        return self.background.shape[:2]

    def to_pixels(self, points: ArrayLike) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """(rows, cols) of world points (N, 2) [m]; may fall outside the image."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        xmin, ymin, _, _ = self.bounds
        cols = np.floor((p[:, 0] - xmin) / self.resolution).astype(np.int64)
        rows = np.floor(self.shape[0] - (p[:, 1] - ymin) / self.resolution).astype(np.int64)
        return rows, cols

    def pixel_centres(self, rows: ArrayLike, cols: ArrayLike) -> NDArray[np.float64]:
        """World ``(x, y)`` [m] of the centres of pixels ``rows``, ``cols`` (same shapes),
        stacked on a last axis: the inverse of :meth:`to_pixels`."""
        xmin, ymin, _, _ = self.bounds
        x = xmin + (np.asarray(cols, dtype=np.float64) + 0.5) * self.resolution
        y = ymin + (self.shape[0] - np.asarray(rows, dtype=np.float64) - 0.5) * self.resolution
        return np.stack(np.broadcast_arrays(x, y), axis=-1)

    def overlay_map(self, frame: NDArray[np.uint8], grid: OccupancyMap) -> None:
        """Blend the occupancy map ``grid`` (its own bounds and cell size) over ``frame`` with
        opacity :data:`MAP_ALPHA`: occupied cells dark, free cells light; cells the map never
        observed (probability 0.5, grey 128) leave the frame as it is."""
        # same bounds and pixel size as World.to_image: the picture has the frame's shape
        picture = occupancy_to_rgb(
            grid.probabilities(), grid.bounds, grid.resolution, self.bounds, self.resolution
        )
        observed = picture[..., 0] != 128
        blended = (1.0 - MAP_ALPHA) * frame[observed] + MAP_ALPHA * picture[observed]
        frame[observed] = np.round(blended).astype(np.uint8)

    def _paint(
        self, frame: NDArray[np.uint8], points: ArrayLike, colour: NDArray, size: int
    ) -> None:
        """Paint ``size`` x ``size`` pixel dots at world ``points`` (clipped to the frame)."""
        rows, cols = self.to_pixels(points)
        height, width = self.shape
        for dr in range(size):
            for dc in range(size):
                r, c = rows + dr - size // 2, cols + dc - size // 2
                keep = (r >= 0) & (r < height) & (c >= 0) & (c < width)
                frame[r[keep], c[keep]] = colour

    def _polyline(self, frame: NDArray[np.uint8], points: ArrayLike, colour: NDArray,
                  size: int) -> None:
        """Paint the polyline through ``points`` (N, 2) [m], sampled every half pixel."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        if len(p) < 2:
            self._paint(frame, p, colour, size)
            return
        steps = np.hypot(*np.diff(p, axis=0).T)
        arc = np.concatenate([[0.0], np.cumsum(steps)])
        samples = np.linspace(0.0, arc[-1], max(2, int(arc[-1] / (0.5 * self.resolution)) + 1))
        dense = np.stack([np.interp(samples, arc, p[:, 0]), np.interp(samples, arc, p[:, 1])], 1)
        self._paint(frame, dense, colour, size)

    def _car(self, frame: NDArray[np.uint8], pose: NDArray[np.float64],
             size: tuple[float, float]) -> None:
        """Fill the car's box and mark its nose."""
        x, y, heading = pose
        half_length, half_width = 0.5 * size[0], 0.5 * size[1]
        reach = math.hypot(half_length, half_width)
        (r0, r1), (c0, c1) = self.to_pixels([[x - reach, y + reach], [x + reach, y - reach]])
        height, width = self.shape
        rows = np.arange(max(r0, 0), min(r1 + 1, height))
        cols = np.arange(max(c0, 0), min(c1 + 1, width))
        if len(rows) == 0 or len(cols) == 0:
            return
        centres = self.pixel_centres(rows[:, None], cols[None, :])
        px, py = centres[..., 0] - x, centres[..., 1] - y
        c, s = math.cos(heading), math.sin(heading)
        along, across = c * px + s * py, -s * px + c * py
        inside = (np.abs(along) <= half_length) & (np.abs(across) <= half_width)
        hit_rows, hit_cols = np.nonzero(inside)
        frame[rows[hit_rows], cols[hit_cols]] = CAR_COLOUR
        nose = [[x + c * half_length, y + s * half_length]]
        self._paint(frame, nose, np.array([255, 255, 255], dtype=np.uint8), 3)

    def _movers(self, frame: NDArray[np.uint8], movers: ArrayLike) -> None:
        """Fill each mover's disc (rows x, y, [vx, vy,] radius [m]; at least one pixel)."""
        rows_xyr = np.asarray(movers, dtype=np.float64).reshape(len(movers), -1)
        height, width = self.shape
        for x, y, r in rows_xyr[:, [0, 1, -1]]:
            (r0, r1), (c0, c1) = self.to_pixels([[x - r, y + r], [x + r, y - r]])
            rows = np.arange(max(r0, 0), min(r1 + 1, height))
            cols = np.arange(max(c0, 0), min(c1 + 1, width))
            if len(rows) == 0 or len(cols) == 0:
                continue
            centres = self.pixel_centres(rows[:, None], cols[None, :])
            inside = np.hypot(centres[..., 0] - x, centres[..., 1] - y) <= r
            hit_rows, hit_cols = np.nonzero(inside)
            frame[rows[hit_rows], cols[hit_cols]] = MOVER_COLOUR
            self._paint(frame, [[x, y]], MOVER_COLOUR, 2)

    def draw(
        self,
        car_pose: ArrayLike,
        car_size: tuple[float, float],
        sensor_poses: ArrayLike,
        scans: ArrayLike,
        beam_angles: ArrayLike,
        max_range: float | Sequence[float] | None = None,
        world_aligned: bool = False,
        trace: ArrayLike | None = None,
        trajectories: Mapping[str, ArrayLike] | None = None,
        occupancy: OccupancyMap | None = None,
        movers: ArrayLike | None = None,
    ) -> NDArray[np.uint8]:
        """One ``(H, W, 3)`` uint8 frame.

        Args:
            car_pose: (x [m], y [m], heading [rad]).
            car_size: (length, width) [m].
            sensor_poses: ``(K, 3)`` world poses of the Lidars.
            scans: ``(K, n)`` ranges [m]; readings ``>= max_range`` (default: the largest
                reading) are not drawn.
            beam_angles: ``(n,)`` [rad] from each sensor's forward axis (from world +x if
                ``world_aligned``); or, for Lidars of their own beams, a list of K arrays, with
                ``scans`` a list of K scans and ``max_range`` a number or a list of K.
            trace: ``(M, 2)`` waypoints [m] to draw under everything else.
            trajectories: ``{name: (N, 2 or 3) poses [m]}``, each in its own colour.
            occupancy: an occupancy map to blend over the world, under everything else
                (:meth:`overlay_map`).
            movers: ``(M, 3)`` or ``(M, 5)`` moving circles (x, y, [vx, vy,] radius [m]),
                drawn as discs over the scans.
        """
        frame = self.background.copy()
        if occupancy is not None:
            self.overlay_map(frame, occupancy)
        if trace is not None:
            self._polyline(frame, trace, TRACE_COLOUR, 2)
        for i, path in enumerate((trajectories or {}).values()):
            colour = TRAJECTORY_COLOURS[i % len(TRAJECTORY_COLOURS)]
            self._polyline(frame, np.asarray(path, dtype=np.float64)[:, :2], colour, 2)
        poses = np.asarray(sensor_poses, dtype=np.float64).reshape(-1, 3)
        per_sensor = isinstance(beam_angles, (list, tuple))  # K Lidars of their own beams
        ranges = ([np.asarray(scan, dtype=np.float64) for scan in scans] if per_sensor else
                  np.asarray(scans, dtype=np.float64).reshape(len(poses), -1))
        limits = (list(max_range) if isinstance(max_range, (list, tuple)) else
                  [float(np.max(np.concatenate([np.ravel(r) for r in ranges])))
                   if max_range is None else max_range] * len(poses))
        for k, pose in enumerate(poses):
            angles = np.asarray(beam_angles[k] if per_sensor else beam_angles, dtype=np.float64)
            heading = 0.0 if world_aligned else pose[2]
            hit = ranges[k] < limits[k]
            direction = angles[hit] + heading
            points = pose[:2] + ranges[k][hit, None] * np.stack(
                [np.cos(direction), np.sin(direction)], axis=1
            )
            self._paint(frame, points, LIDAR_COLOURS[k % len(LIDAR_COLOURS)], self.dot)
        if movers is not None and len(movers) > 0:
            self._movers(frame, movers)
        self._car(frame, np.asarray(car_pose, dtype=np.float64), car_size)
        for k, pose in enumerate(poses):
            self._paint(frame, pose[None, :2], LIDAR_COLOURS[k % len(LIDAR_COLOURS)],
                        self.dot + 1)
        if self.overlays:
            assert self._scale is not None
            paste(frame, self._scale, "bottom left")
            paste(frame, self._legend(len(poses), movers is not None and len(movers) > 0),
                  "top right")
        return frame

    def close(self) -> None:
        """Close the window, if one was opened."""
        if self.window is not None:
            import pygame

            pygame.display.quit()
            self.window = None


def show_in_window(renderer: Renderer, frame: NDArray[np.uint8], fps: float) -> None:
    """Show ``frame`` in a pygame window titled ``renderer.title`` (opened on first use), at most
    ``fps`` frames per s; once the user closes the window, nothing more is shown."""
    try:
        import pygame
    except ImportError as error:
        raise DependencyNotInstalled(
            'pygame is not installed: run `pip install "duallidar[human]"` for render_mode="human"'
        ) from error
    height, width = frame.shape[:2]
    if renderer.closed:  # the user closed the window: the episode runs on without it
        return
    if renderer.window is None:
        pygame.display.init()  # the display only: no audio device needed
        renderer.window = pygame.display.set_mode((width, height))
        pygame.display.set_caption(renderer.title)
        renderer._clock = pygame.time.Clock()
    if any(event.type == pygame.QUIT for event in pygame.event.get()):
        renderer.close()
        renderer.closed = True
        return
    surface = pygame.surfarray.make_surface(np.transpose(frame, (1, 0, 2)))
    renderer.window.blit(surface, (0, 0))
    pygame.display.flip()
    renderer._clock.tick(fps)


def tile_frames(frames: Sequence[NDArray[np.uint8]], columns: int = 3) -> NDArray[np.uint8]:
    """RGB ``frames`` laid out row by row in a grid of ``columns``, on white."""
    if not frames:
        raise ConfigError("frames: expected at least one (H, W, 3) frame, got none")
    height = max(f.shape[0] for f in frames)
    width = max(f.shape[1] for f in frames)
    rows = math.ceil(len(frames) / columns)
    sheet = np.full((rows * height, min(columns, len(frames)) * width, 3), 255, dtype=np.uint8)
    for i, frame in enumerate(frames):
        r, c = divmod(i, columns)
        top, left = r * height, c * width
        sheet[top : top + frame.shape[0], left : left + frame.shape[1]] = frame
    return sheet


def write_png(path: str | os.PathLike, image: ArrayLike) -> None:
    """Save an ``(H, W, 3)`` uint8 RGB image as a PNG file."""
    rgb = np.asarray(image)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise ConfigError(f"image: expected (H, W, 3) uint8, got {rgb.shape} {rgb.dtype}")
    Image.fromarray(np.ascontiguousarray(rgb)).save(path, format="PNG")
