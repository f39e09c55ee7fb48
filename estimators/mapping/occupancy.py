"""Log-odds occupancy grid built from planar Lidar scans at (estimated) sensor poses.

The grid uses the image convention of :meth:`lidar_env.world.world.World.to_image`: ``H, W =
ceil(extent / res)`` anchored at ``(xmin, ymin)``, cell ``(row, col)`` covers ``x`` in
``xmin + [col, col + 1) * res`` and ``y`` in ``ymin + [H - 1 - row, H - row) * res`` (up to
which side owns a boundary), so row 0 is the top (largest ``y``) and a map can be compared cell
by cell with ``world.to_image(res)`` of the same bounds.

Every beam is traced exactly through the cells it crosses (Amanatides & Woo, "A fast voxel
traversal algorithm", Eurographics 1987): the cells it crosses up to ``free_margin`` before the
return whose centre it passes within ``clear_radius`` (half a cell: through the cell's inscribed
circle) get a "miss", the cell of the return a "hit", and the cells in between are left alone
(the obstacle band ``alpha / 2`` of the inverse range sensor model of Thrun, Burgard & Fox,
"Probabilistic Robotics", table 9.2: a surface met obliquely, or crossing a cell boundary, also
reaches into the cell before the return, which would otherwise be cleared by every grazing
beam). A beam that only clips a cell's corner says little about the cell, which may hold a
surface the beam passed by: the rim cells of a round obstacle are clipped from every side by
the beams that pass it tangentially. With every crossed cell cleared (``clear_radius=1``), the
map at true poses found 0.964 of the visible true cells of ``open_cylinders`` at 5 cm and 0.909
at 10 cm; with half-cell clearing 0.992 and 0.957 (the scripted drive of
``benchmarks/bench_mapping.py``; ``hallway`` 1.000 either way, ``closed_to_open`` 0.990 -> 0.994
at 5 cm). A beam that reads ``max_range`` or more marks free space up to
``max_range`` and nothing occupied. One call of :meth:`OccupancyGrid.integrate` is one
observation: each cell changes at most once per call, and a hit in a cell outranks a miss from
another beam of the same call, so dense near-field cells are not driven to "free" by hundreds
of beams at once and a thin wall grazed by one beam and hit by another stays occupied.

The log-odds increments and clamps default to OctoMap's (Hornung et al., "OctoMap", Autonomous
Robots 2013): p(hit) 0.7, p(miss) 0.4, probabilities clamped to [0.12, 0.97], so a cell needs
about two hits to be occupied and can still be cleared when the scene changes.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimators.base import SensorSetup
from lidar_env import rendering
from lidar_env.core import ConfigError, EstimatorInputError
from lidar_env.core.se2 import compose

#: ``(xmin, ymin, xmax, ymax)`` [m] of an axis-aligned world rectangle.
Bounds = tuple[float, float, float, float]


def logit(p: float) -> float:
    """Log-odds ``ln(p / (1 - p))`` of a probability in (0, 1)."""
    return math.log(p / (1.0 - p))


@numba.njit(cache=True)
def _clip_to_box(
    x0: float, y0: float, dx: float, dy: float, width: float, height: float
) -> tuple[float, float]:
    """Liang-Barsky: the parameter interval ``[t0, t1]`` of ``p0 + t * d``, ``t`` in [0, 1],
    inside ``[0, width] x [0, height]``; ``t0 > t1`` when the segment misses the box."""
    t0, t1 = 0.0, 1.0
    for p, q in ((-dx, x0), (dx, width - x0), (-dy, y0), (dy, height - y0)):
        if p == 0.0:
            if q < 0.0:
                return 1.0, 0.0
        else:
            t = q / p
            if p < 0.0:
                t0 = max(t0, t)
            else:
                t1 = min(t1, t)
    return t0, t1


@numba.njit(cache=True)
def _cell_index(coordinate: float, n_cells: int) -> int:
    return min(max(int(math.floor(coordinate)), 0), n_cells - 1)


@numba.njit(cache=True)
def _trace_scans(
    log_odds: NDArray[np.float64],
    marks: NDArray[np.int32],
    call: int,
    origins: NDArray[np.float64],
    headings: NDArray[np.float64],
    beam_angles: NDArray[np.float64],
    ranges: NDArray[np.float64],
    moving: NDArray[np.bool_],
    max_range: float,
    free_margin: float,
    clear_radius: float,
    miss: float,
    hit: float,
    low: float,
    high: float,
) -> None:
    """Update ``log_odds`` in place with the scans ``ranges`` (K, n) [cells] taken from
    ``origins`` (K, 2) (column, row) [cells] at world ``headings`` (K,) [rad]: a miss in each
    cell a beam crosses up to ``free_margin`` [cells] before its return (or up to ``max_range``
    [cells]), a hit in the cell of each return not on something ``moving`` (K, n). ``marks``
    remembers per cell what this ``call`` (>= 1) did: ``2 call`` = updated, ``2 call + 1`` =
    holds a return, not yet updated. A miss goes only to the cells whose centre lies within
    ``clear_radius`` [cells] of the beam."""
    n_rows, n_cols = log_odds.shape
    n_scans, n_beams = ranges.shape
    done, pending = 2 * call, 2 * call + 1
    flat_odds = log_odds.reshape(n_rows * n_cols)  # views: the walk steps a flat index
    flat_marks = marks.reshape(n_rows * n_cols)
    # grid axes: column grows with x, row grows with -y
    dir_col = np.cos(headings.reshape(-1, 1) + beam_angles.reshape(1, -1))
    dir_row = -np.sin(headings.reshape(-1, 1) + beam_angles.reshape(1, -1))
    for k in range(n_scans):  # mark this call's hit cells first: hits outrank misses
        for j in range(n_beams):
            if ranges[k, j] < max_range and not moving[k, j]:
                gx = origins[k, 0] + ranges[k, j] * dir_col[k, j]
                gy = origins[k, 1] + ranges[k, j] * dir_row[k, j]
                if 0.0 <= gx < n_cols and 0.0 <= gy < n_rows:
                    marks[int(gy), int(gx)] = pending
    for k in range(n_scans):
        x0, y0 = origins[k, 0], origins[k, 1]
        for j in range(n_beams):
            if ranges[k, j] < max_range:
                length = max(ranges[k, j] - free_margin, 0.0)
            else:
                length = max_range
            dx, dy = length * dir_col[k, j], length * dir_row[k, j]
            t0, t1 = _clip_to_box(x0, y0, dx, dy, float(n_cols), float(n_rows))
            if t0 > t1:
                continue
            col = _cell_index(x0 + t0 * dx, n_cols)
            row = _cell_index(y0 + t0 * dy, n_rows)
            end_col = _cell_index(x0 + t1 * dx, n_cols)
            end_row = _cell_index(y0 + t1 * dy, n_rows)
            step_col = 1 if dx > 0 else -1
            step_row = 1 if dy > 0 else -1
            # t at which the ray crosses the next column / row boundary, and t between crossings
            if dx != 0.0:
                next_col = (col + (1 if dx > 0 else 0) - x0) / dx
                delta_col = abs(1.0 / dx)
            else:
                next_col, delta_col = np.inf, np.inf
            if dy != 0.0:
                next_row = (row + (1 if dy > 0 else 0) - y0) / dy
                delta_row = abs(1.0 / dy)
            else:
                next_row, delta_row = np.inf, np.inf
            # a 4-connected walk from the start cell to the end cell takes exactly these steps;
            # it stays inside the grid, as both cells are
            n_col_steps, n_row_steps = abs(end_col - col), abs(end_row - row)
            index = row * n_cols + col
            row_stride = step_row * n_cols
            ux, uy = dir_col[k, j], dir_row[k, j]
            for _ in range(n_col_steps + n_row_steps + 1):
                if flat_marks[index] < done and abs(
                        ux * (row + 0.5 - y0) - uy * (col + 0.5 - x0)) <= clear_radius:
                    flat_marks[index] = done
                    flat_odds[index] = max(flat_odds[index] + miss, low)
                if (next_col < next_row and n_col_steps > 0) or n_row_steps == 0:
                    index += step_col
                    col += step_col
                    next_col += delta_col
                    n_col_steps -= 1
                else:
                    index += row_stride
                    row += step_row
                    next_row += delta_row
                    n_row_steps -= 1
    for k in range(n_scans):
        for j in range(n_beams):
            if ranges[k, j] < max_range and not moving[k, j]:
                gx = origins[k, 0] + ranges[k, j] * dir_col[k, j]
                gy = origins[k, 1] + ranges[k, j] * dir_row[k, j]
                if 0.0 <= gx < n_cols and 0.0 <= gy < n_rows:
                    row, col = int(gy), int(gx)
                    if marks[row, col] == pending:  # update each hit cell once per call
                        marks[row, col] = done
                        log_odds[row, col] = min(log_odds[row, col] + hit, high)


@dataclass
class OccupancyGrid:
    """A log-odds occupancy grid over ``bounds`` at ``resolution`` [m/cell], image layout.

    It has what :class:`lidar_env.rendering.renderer.OccupancyMap` asks for (``bounds``,
    ``resolution``, ``probabilities()``), so ``env.unwrapped.set_render_map(grid)`` draws it.

    Attributes:
        bounds: ``(xmin, ymin, xmax, ymax)`` [m] of the mapped world rectangle; the grid has
            ``ceil(width / resolution)`` columns and ``ceil(height / resolution)`` rows anchored
            at ``(xmin, ymin)`` (row 0 = top; the top row may reach past ``ymax``).
        resolution: [m] side of a square cell.
        p_hit, p_miss: inverse sensor model, probability of occupancy of the cell holding a
            return and of a cell a beam passed through.
        p_min, p_max: clamps of the cell probability (keep the map able to change).
        free_margin: [m] length before each return that is not marked free (module doc);
            default one cell, the smallest band that holds a surface crossing the boundary of
            the return's cell.
        clear_radius: [cells] a beam marks free only the cells whose centre it passes within
            this distance of (module doc); 0.5 = through the inscribed circle, >= 0.71 = every
            cell it crosses.
        log_odds: ``(rows, cols)`` float64 cell log-odds, 0 = unknown.
    """

    bounds: Bounds
    resolution: float = 0.05
    p_hit: float = 0.7
    p_miss: float = 0.4
    p_min: float = 0.12
    p_max: float = 0.97
    free_margin: float | None = None
    clear_radius: float = 0.5
    log_odds: NDArray[np.float64] = field(init=False, repr=False)
    _marks: NDArray[np.int32] = field(init=False, repr=False)
    _n_updates: int = field(default=0, init=False, repr=False)

    def __post_init__(self) -> None:
        bounds = np.asarray(self.bounds, dtype=np.float64)
        if bounds.shape != (4,) or not np.all(np.isfinite(bounds)):
            raise ConfigError(f"bounds: expected 4 finite numbers (xmin, ymin, xmax, ymax), "
                             f"got {self.bounds!r}")
        if not (bounds[2] > bounds[0] and bounds[3] > bounds[1]):
            raise ConfigError(f"bounds: expected xmax > xmin and ymax > ymin, got {self.bounds!r}")
        if not (math.isfinite(self.resolution) and self.resolution > 0):
            raise ConfigError(f"resolution: expected a positive number [m/cell], "
                             f"got {self.resolution!r}")
        for name in ("p_hit", "p_miss", "p_min", "p_max"):
            value = getattr(self, name)
            if not 0.0 < value < 1.0:
                raise ConfigError(f"{name}: expected a probability in (0, 1), got {value!r}")
        if not (self.p_min < 0.5 < self.p_max and self.p_miss < 0.5 < self.p_hit):
            raise ConfigError(
                "expected p_min < 0.5 < p_max and p_miss < 0.5 < p_hit, got "
                f"p_min={self.p_min}, p_max={self.p_max}, p_miss={self.p_miss}, p_hit={self.p_hit}"
            )
        self.bounds = tuple(float(b) for b in bounds)  # type: ignore[assignment]
        self.resolution = float(self.resolution)
        if self.free_margin is None:
            self.free_margin = self.resolution
        if not (math.isfinite(self.free_margin) and self.free_margin >= 0):
            raise ConfigError(f"free_margin: expected a distance >= 0 [m], "
                              f"got {self.free_margin!r}")
        if not (math.isfinite(self.clear_radius) and self.clear_radius >= 0):
            raise ConfigError(f"clear_radius: expected a distance >= 0 [cells], "
                             f"got {self.clear_radius!r}")
        shape = self.shape
        if shape[0] * shape[1] > 200_000_000:
            raise ConfigError(f"grid of {shape} cells is too large: coarsen the resolution "
                             f"({self.resolution} m) or shrink the bounds {self.bounds}")
        self.log_odds = np.zeros(shape, dtype=np.float64)
        self._marks = np.zeros(shape, dtype=np.int32)
        self._n_updates = 0

    @property
    def shape(self) -> tuple[int, int]:
        """``(rows, cols)`` of the grid."""
        return rendering.raster_shape(self.bounds, self.resolution)

    def to_grid_coordinates(self, points: ArrayLike) -> NDArray[np.float64]:
        """World points ``(N, 2)`` [m] -> continuous ``(col, row)`` [cells]; ``floor`` gives the
        cell index."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        xmin, ymin, _, _ = self.bounds
        return np.column_stack(
            [(points[:, 0] - xmin) / self.resolution,
             self.shape[0] - (points[:, 1] - ymin) / self.resolution]
        )

    def cell_centres(self) -> NDArray[np.float64]:
        """``(rows, cols, 2)`` world ``(x, y)`` [m] of every cell centre."""
        rows, cols = self.shape
        xmin, ymin, _, _ = self.bounds
        x = xmin + (np.arange(cols) + 0.5) * self.resolution
        y = ymin + (rows - np.arange(rows) - 0.5) * self.resolution
        return np.stack(np.meshgrid(x, y), axis=-1)

    def integrate(
        self,
        ranges: ArrayLike,
        beam_angles: ArrayLike,
        sensor_pose: ArrayLike,
        max_range: float,
        moving: ArrayLike | None = None,
    ) -> None:
        """Add one observation: scan ``ranges`` (n,) [m] taken at ``sensor_pose`` (3,) (world
        x [m], y [m], heading [rad]); beam ``i`` points ``beam_angles[i]`` [rad] CCW from the
        sensor's forward axis. Several sensors observing at once: ``ranges`` (K, n) and
        ``sensor_pose`` (K, 3). Readings ``>= max_range`` are free space up to ``max_range``.
        ``moving`` (shaped like ``ranges``) marks returns on moving things
        (:mod:`estimators.mapping.moving_returns`): their beams clear the space before them, and
        their cells are not marked occupied."""
        ranges = np.atleast_2d(np.asarray(ranges, dtype=np.float64))
        on_movers = np.zeros(ranges.shape, np.bool_) if moving is None else np.atleast_2d(
            np.asarray(moving, dtype=np.bool_))
        if on_movers.shape != ranges.shape:
            raise EstimatorInputError(
                f"moving: expected the shape of ranges {ranges.shape}, got {np.shape(moving)}")
        angles = np.asarray(beam_angles, dtype=np.float64)
        poses = np.atleast_2d(np.asarray(sensor_pose, dtype=np.float64))
        if angles.ndim != 1 or ranges.ndim != 2 or ranges.shape[1] != len(angles):
            raise EstimatorInputError(f"ranges: expected shape (n,) or (K, n), n = {angles.shape} "
                                      f"beam angles, got {np.shape(ranges)}")
        if poses.shape != (len(ranges), 3):
            raise EstimatorInputError(
                f"sensor_pose: expected shape (3,) or ({len(ranges)}, 3), one pose "
                f"per scan, got {np.shape(sensor_pose)}")
        if not (np.all(np.isfinite(ranges)) and np.all(ranges >= 0)):
            raise EstimatorInputError("ranges: expected finite ranges >= 0 [m]")
        if not (np.all(np.isfinite(poses)) and np.all(np.isfinite(angles))):
            raise EstimatorInputError("sensor_pose and beam_angles: expected finite numbers")
        if not (math.isfinite(max_range) and max_range > 0):
            raise EstimatorInputError(f"max_range: expected a number > 0 [m], got {max_range!r}")
        if self._n_updates >= 2**30 - 1:  # marks are int32 (2 per call): start them afresh
            self._marks[:] = 0
            self._n_updates = 0
        self._n_updates += 1
        _trace_scans(
            self.log_odds, self._marks, self._n_updates, self.to_grid_coordinates(poses[:, :2]),
            np.ascontiguousarray(poses[:, 2]), angles, ranges / self.resolution, on_movers,
            max_range / self.resolution, self.free_margin / self.resolution, self.clear_radius,
            logit(self.p_miss), logit(self.p_hit), logit(self.p_min), logit(self.p_max),
        )

    def integrate_observation(
        self, observation: Mapping[str, ArrayLike], car_pose: ArrayLike, setup: SensorSetup,
        moving: Mapping[str, ArrayLike] | None = None,
    ) -> None:
        """Add one env observation (scans keyed by ``setup.keys``) taken at the (estimated) car
        pose ``car_pose`` (3,) [m, m, rad]: each Lidar at car pose ⊕ its mount; ``moving``, per
        key, the returns on moving things (:meth:`integrate`). This is the online use: call it
        every step with the estimator's latest pose."""
        scans = setup.check_observation(observation)
        poses = sensor_poses(car_pose, setup)[0]
        masks = [None if moving is None else moving[key] for key in setup.keys]
        if setup.uniform:
            self.integrate(np.stack([scans[key] for key in setup.keys]), setup.beam_angles,
                           poses, setup.max_range,
                           None if moving is None else np.stack(masks))
            return
        for key, sensor, pose, mask in zip(setup.keys, setup.sensors, poses, masks, strict=True):
            # Lidars of their own beams: one update each (a cell may change once per Lidar)
            self.integrate(scans[key][None, :], sensor.beam_angles, pose[None, :],
                           sensor.max_range, mask)

    def probabilities(self) -> NDArray[np.float64]:
        """``(rows, cols)`` occupancy probability of each cell; 0.5 = never observed."""
        return 1.0 / (1.0 + np.exp(-self.log_odds))

    def occupied(self, threshold: float = 0.5) -> NDArray[np.bool_]:
        """``(rows, cols)`` cells whose occupancy probability exceeds ``threshold``."""
        if not 0.0 < threshold < 1.0:
            raise ConfigError(f"threshold: expected a probability in (0, 1), got {threshold!r}")
        return self.log_odds > logit(threshold)

    def free(self, threshold: float = 0.5) -> NDArray[np.bool_]:
        """``(rows, cols)`` cells whose occupancy probability is below ``threshold``."""
        if not 0.0 < threshold < 1.0:
            raise ConfigError(f"threshold: expected a probability in (0, 1), got {threshold!r}")
        return self.log_odds < logit(threshold)


def sensor_poses(
    car_poses: ArrayLike, setup: SensorSetup
) -> NDArray[np.float64]:
    """``(N, K, 3)`` world poses of the K Lidars at car poses ``(N, 3)``: car pose ⊕ mount.

    With ``setup.world_aligned`` the scans are already in world orientation, so each sensor's
    heading is 0 (its position still follows the car's heading)."""
    car_poses = np.asarray(car_poses, dtype=np.float64).reshape(-1, 3)
    poses = compose(car_poses[:, None, :], setup.mounts[None, :, :])
    if setup.world_aligned:
        poses[..., 2] = 0.0
    return poses


def bounds_around(
    positions: ArrayLike, margin: float
) -> Bounds:
    """The rectangle around ``positions`` (N, 2) [m] grown by ``margin`` [m] on every side."""
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 2)
    low = positions.min(axis=0) - margin
    high = positions.max(axis=0) + margin
    return float(low[0]), float(low[1]), float(high[0]), float(high[1])
