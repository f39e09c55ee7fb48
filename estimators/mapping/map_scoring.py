"""Scores of a built map against the true world, and pictures of maps side by side.

Occupied cells (:func:`score_occupancy`), at a tolerance of ``t`` cells (Chebyshev distance,
i.e. a ``(2t+1) x (2t+1)`` square dilation with :func:`scipy.ndimage.binary_dilation`):

* precision = share of the map's occupied cells within ``t`` cells of a true occupied cell;
* recall = share of the evaluated true occupied cells within ``t`` cells of a map cell;
* IoU = ``1 / (1/precision + 1/recall - 1)``, which is exactly ``|A ∩ B| / |A ∪ B|`` when
  ``t = 0`` and extends it to a tolerance without counting a cell pair twice.

The true occupied cells (:func:`true_occupancy`) are the cells that hold some obstacle: those of
``world.to_image`` (centre inside a circle or polygon, or crossed by a wall) plus the rim cells
that a circle or a polygon's edge reaches into, so every return of a noiseless beam lies in a
true cell. The evaluated ones are the *visible* ones (:func:`visible_cells`): the true cells that
a beam of the run hit, i.e. that hold the noiseless return of one of the Lidars' beams cast
exactly against the world geometry (:func:`lidar_env.sensors.lidar.cast_rays`) from the true sensor
poses. A cell that no beam reached cannot be mapped by any mapper, whatever its quality:
rays cast in every direction from the same positions would count parts of the cylinders'
faces that fall between the 1-degree beams, and cap any mapper's recall below 1.

Cylinders (:func:`score_cylinders`): detected circles are matched one-to-one to the true
``world.circles`` (Hungarian assignment on centre distance, pairs farther than
``match_distance`` discarded); recall counts only *observable* true cylinders
(:func:`observable_cylinders`: at least ``min_points`` returns on it in one true scan), and the
position error is the centre distance of the matched pairs.

Without ground truth (real logs), :func:`return_agreement` scores how consistent a map is with
the poses it was built from: the share of returns that land on its occupied cells. It cannot
see a rigid offset of the whole run, only poses that disagree with each other.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage
from scipy.optimize import linear_sum_assignment

from estimators.base import SensorSetup
from estimators.mapping.occupancy import OccupancyGrid, sensor_poses
from lidar_env.core import ConfigError, EstimatorInputError


@dataclass(frozen=True)
class MapScores:
    """Occupied-cell scores at ``tolerance_cells``; counts are cells."""

    precision: float
    recall: float
    iou: float
    tolerance_cells: int
    n_map: int  # occupied cells in the map
    n_truth: int  # evaluated true occupied cells


@dataclass(frozen=True)
class CylinderScores:
    """Detected cylinders against the observable true ones; errors in metres."""

    recall: float
    precision: float
    mean_error: float  # [m] mean centre distance of matched pairs (nan if none)
    max_error: float  # [m] largest centre distance of matched pairs (nan if none)
    n_true: int  # observable true cylinders
    n_detected: int
    n_matched: int


def truth_mask(image: ArrayLike) -> NDArray[np.bool_]:
    """Occupied cells of a ground-truth image (e.g. ``world.to_image(res)``): any value > 0,
    the paper's convention (0 = nothing, above 0 = obstacle)."""
    image = np.asarray(image)
    if image.ndim != 2:
        raise EstimatorInputError(
            f"truth image: expected a 2-D (rows, cols) array, got {image.shape}")
    return image > 0


def _dilate(mask: NDArray[np.bool_], cells: int) -> NDArray[np.bool_]:
    if cells == 0:
        return mask
    return ndimage.binary_dilation(mask, structure=np.ones((2 * cells + 1, 2 * cells + 1), bool))


def score_occupancy(
    occupied: ArrayLike,
    truth: ArrayLike,
    tolerance_cells: int = 1,
    evaluated: ArrayLike | None = None,
) -> MapScores:
    """Precision, recall and IoU of the ``occupied`` map cells (rows, cols) against the true
    image ``truth`` (same shape, > 0 = obstacle) at ``tolerance_cells`` (module doc).

    ``evaluated`` (rows, cols) bool restricts the true cells that recall must find, e.g. to
    :func:`visible_cells`; by default all true occupied cells count."""
    occupied = np.asarray(occupied, dtype=bool)
    true = truth_mask(truth)
    if occupied.shape != true.shape:
        raise EstimatorInputError(
            f"occupied map {occupied.shape} and truth image {true.shape}: expected "
            "the same shape (build the map over world.bounds at the image resolution)")
    if isinstance(tolerance_cells, bool) or not isinstance(tolerance_cells, (int, np.integer)) \
            or tolerance_cells < 0:
        raise ConfigError(f"tolerance_cells: expected an integer >= 0, got {tolerance_cells!r}")
    if evaluated is not None:
        evaluated = np.asarray(evaluated, dtype=bool)
        if evaluated.shape != true.shape:
            raise EstimatorInputError(
                f"evaluated: expected shape {true.shape}, got {evaluated.shape}")
        true_evaluated = true & evaluated
    else:
        true_evaluated = true
    n_map, n_truth = int(occupied.sum()), int(true_evaluated.sum())
    matched_map = int((occupied & _dilate(true, tolerance_cells)).sum())
    matched_truth = int((true_evaluated & _dilate(occupied, tolerance_cells)).sum())
    precision = matched_map / n_map if n_map else math.nan
    recall = matched_truth / n_truth if n_truth else math.nan
    if precision > 0 and recall > 0:
        iou = 1.0 / (1.0 / precision + 1.0 / recall - 1.0)
    else:
        iou = 0.0 if (precision == 0 or recall == 0) else math.nan
    return MapScores(precision, recall, iou, int(tolerance_cells), n_map, n_truth)


def _cell_window(
    grid: OccupancyGrid, low: NDArray[np.float64], high: NDArray[np.float64]
) -> tuple[slice, slice, NDArray[np.float64], NDArray[np.float64]] | None:
    """The cells of ``grid`` whose squares meet the box ``low``-``high`` (x, y) [m]: their row and
    column slices and the ``(x0, x1)`` and ``(y0, y1)`` [m] edges of those columns and rows
    (broadcastable to the window); ``None`` if the box misses the grid."""
    rows, cols = grid.shape
    xmin, ymin, _, _ = grid.bounds
    res = grid.resolution
    col0 = max(int(math.floor((low[0] - xmin) / res)) - 1, 0)
    col1 = min(int(math.floor((high[0] - xmin) / res)) + 2, cols)
    # row r covers y in ymin + [rows - 1 - r, rows - r) * res
    row0 = max(rows - 1 - int(math.floor((high[1] - ymin) / res)) - 1, 0)
    row1 = min(rows - int(math.floor((low[1] - ymin) / res)) + 1, rows)
    if col0 >= col1 or row0 >= row1:
        return None
    x = xmin + np.arange(col0, col1 + 1) * res
    y = ymin + (rows - np.arange(row0, row1 + 1)) * res  # top edge of each row, then the last
    xs = np.stack([x[:-1], x[1:]])[:, None, :]  # (2, 1, window cols)
    ys = np.stack([y[1:], y[:-1]])[:, :, None]  # (2, window rows, 1): bottom, top
    return slice(row0, row1), slice(col0, col1), xs, ys


def true_occupancy(world: Any, grid: OccupancyGrid) -> NDArray[np.bool_]:
    """``(rows, cols)`` the cells of ``grid`` (over ``world.bounds``) that hold some obstacle:
    those of ``world.to_image`` (centre inside a circle or a polygon, or crossed by a wall) and
    every cell a circle or a polygon's edge reaches into.

    This is what an occupancy grid's cell means (the cell contains an obstacle), and it holds
    every return of a noiseless beam, which lies on an obstacle's boundary. The image alone
    leaves out the rim cells of a disc or a polygon whose centre lies outside it: the cells
    where the Lidar's returns land on a curved face, which the map then had to be forgiven for
    marking (at one-cell tolerance) while the true cells one further in were never hit."""
    true = truth_mask(world.to_image(grid.resolution))
    if true.shape != grid.shape:
        raise EstimatorInputError(
            f"grid {grid.shape} and world image {true.shape}: expected the same "
            f"shape; build the grid over world.bounds {world.bounds}")
    slack = 1e-9 * grid.resolution  # a return on a cell's edge belongs to both cells
    for cx, cy, r in np.asarray(world.circles, dtype=np.float64).reshape(-1, 3):
        window = _cell_window(grid, np.array([cx - r, cy - r]), np.array([cx + r, cy + r]))
        if window is None:
            continue
        rows, cols, xs, ys = window
        dx = np.maximum(np.maximum(xs[0] - cx, cx - xs[1]), 0.0)  # centre to the nearest cell
        dy = np.maximum(np.maximum(ys[0] - cy, cy - ys[1]), 0.0)  # point, per axis
        true[rows, cols] |= np.hypot(dx, dy) < r + slack
    for x1, y1, x2, y2 in np.asarray(world.segments, dtype=np.float64).reshape(-1, 4):
        window = _cell_window(grid, np.array([min(x1, x2), min(y1, y2)]),
                              np.array([max(x1, x2), max(y1, y2)]))
        if window is None:
            continue
        rows, cols, xs, ys = window
        # separating axes of a segment and a square: x, y (its bounding box) and its normal
        inside_box = ((xs[1] >= min(x1, x2) - slack) & (xs[0] <= max(x1, x2) + slack)
                      & (ys[1] >= min(y1, y2) - slack) & (ys[0] <= max(y1, y2) + slack))
        side = [(x2 - x1) * (y - y1) - (y2 - y1) * (x - x1) for x in xs for y in ys]
        length = math.hypot(x2 - x1, y2 - y1)
        crossed = (np.minimum.reduce(side) <= slack * length) & (
            np.maximum.reduce(side) >= -slack * length)
        true[rows, cols] |= inside_box & crossed
    return true


def beam_hit_cells(
    world: Any,
    sensor_poses: ArrayLike,
    beam_angles: ArrayLike,
    grid: OccupancyGrid,
    max_range: float,
) -> NDArray[np.bool_]:
    """``(rows, cols)`` cells of ``grid`` that hold the noiseless return of a beam
    ``beam_angles`` (n,) [rad] from one of the world ``sensor_poses`` (N, 3) within
    ``max_range`` [m]."""
    from lidar_env.sensors import cast_rays

    poses = np.asarray(sensor_poses, dtype=np.float64).reshape(-1, 3)
    angles = np.asarray(beam_angles, dtype=np.float64)
    ranges = cast_rays(world, poses, angles, max_range)
    directions = poses[:, 2:3] + angles
    hit = (ranges < max_range) & (ranges > 0)  # 0: a sensor inside an obstacle sees nothing
    ends = np.stack([poses[:, 0:1] + ranges * np.cos(directions),
                     poses[:, 1:2] + ranges * np.sin(directions)], axis=-1)[hit]
    cells = np.floor(grid.to_grid_coordinates(ends)).astype(np.int64)
    rows, cols = grid.shape
    inside = (cells[:, 0] >= 0) & (cells[:, 0] < cols) & (cells[:, 1] >= 0) & (cells[:, 1] < rows)
    hit_cells = np.zeros(grid.shape, dtype=bool)
    hit_cells[cells[inside, 1], cells[inside, 0]] = True
    return hit_cells


def visible_cells(
    world: Any,
    sensor_poses: ArrayLike,
    beam_angles: ArrayLike,
    grid: OccupancyGrid,
    max_range: float,
) -> NDArray[np.bool_]:
    """``(rows, cols)`` cells of :func:`true_occupancy` that a beam of the run hit (module doc,
    :func:`beam_hit_cells`), on ``grid``'s cells (its bounds must be ``world.bounds``)."""
    return true_occupancy(world, grid) & beam_hit_cells(world, sensor_poses, beam_angles, grid,
                                                        max_range)


def observable_cylinders(
    world: Any,
    true_sensor_poses: ArrayLike,
    beam_angles: ArrayLike,
    max_range: float,
    min_points: int,
) -> NDArray[np.bool_]:
    """``(len(world.circles),)`` True for each cylinder that got at least ``min_points``
    returns in one noiseless scan from one of ``true_sensor_poses`` (N, 3)."""
    from lidar_env.sensors import cast_rays

    circles = np.asarray(world.circles, dtype=np.float64).reshape(-1, 3)
    poses = np.asarray(true_sensor_poses, dtype=np.float64).reshape(-1, 3)
    angles = np.asarray(beam_angles, dtype=np.float64)
    ranges = cast_rays(world, poses, angles, max_range)
    directions = poses[:, 2:3] + angles
    ends = np.stack([poses[:, 0:1] + ranges * np.cos(directions),
                     poses[:, 1:2] + ranges * np.sin(directions)], axis=-1)
    observable = np.zeros(len(circles), dtype=bool)
    for i, (cx, cy, r) in enumerate(circles):
        on_surface = (ranges < max_range) & (np.abs(np.hypot(ends[..., 0] - cx,
                                                              ends[..., 1] - cy) - r) < 1e-6)
        observable[i] = np.max(on_surface.sum(axis=1), initial=0) >= min_points
    return observable


def score_cylinders(
    detected: ArrayLike,
    true_circles: ArrayLike,
    match_distance: float = 0.25,
    observable: ArrayLike | None = None,
) -> CylinderScores:
    """Detected circles ``(M, 3)`` (cx, cy, r [m]) against ``true_circles`` ``(N, 3)``.

    ``match_distance`` [m] (default 0.25: half the smallest gap a car could pass through, far
    above a usable centre error, far below the spacing of distinct cylinders) caps a match.
    ``observable`` (N,) bool limits the true cylinders recall counts; a detection matched to an
    unobservable cylinder is still a correct detection for precision."""
    found = np.asarray(detected, dtype=np.float64).reshape(-1, 3)
    true = np.asarray(true_circles, dtype=np.float64).reshape(-1, 3)
    if not (math.isfinite(match_distance) and match_distance > 0):
        raise ConfigError(
            f"match_distance: expected a positive distance [m], got {match_distance!r}"
        )
    counted = np.ones(len(true), bool) if observable is None else np.asarray(observable, bool)
    if counted.shape != (len(true),):
        raise EstimatorInputError(f"observable: expected shape ({len(true)},), got {counted.shape}")
    distances = np.hypot(found[:, None, 0] - true[None, :, 0], found[:, None, 1] - true[None, :, 1])
    rows, cols = linear_sum_assignment(np.where(distances <= match_distance, distances, 1e9))
    keep = distances[rows, cols] <= match_distance
    rows, cols = rows[keep], cols[keep]
    matched_counted = counted[cols]
    errors = distances[rows, cols][matched_counted]
    n_true = int(counted.sum())
    return CylinderScores(
        recall=float(matched_counted.sum() / n_true) if n_true else math.nan,
        precision=float(len(rows) / len(found)) if len(found) else math.nan,
        mean_error=float(errors.mean()) if len(errors) else math.nan,
        max_error=float(errors.max()) if len(errors) else math.nan,
        n_true=n_true,
        n_detected=len(found),
        n_matched=int(matched_counted.sum()),
    )


def return_agreement(
    grid: OccupancyGrid,
    trajectory: ArrayLike,
    observations: Sequence[Mapping[str, ArrayLike]],
    setup: SensorSetup,
    tolerance_cells: int = 1,
) -> float:
    """Share of the returns of ``observations``, placed at the car poses ``trajectory`` (N, 3),
    that fall within ``tolerance_cells`` of an occupied cell of ``grid``: a map score that
    needs no ground truth (for real logs).

    Give it the map built from the same scans and poses (:func:`from_estimator_run`): every
    return then marked its own cell occupied, and it only disagrees where other scans cleared
    that cell, which consistent poses do not do. Returns outside the grid disagree."""
    trajectory = np.asarray(trajectory, dtype=np.float64)
    if len(observations) != len(trajectory):
        raise EstimatorInputError(
            f"observations: expected one per trajectory row ({len(trajectory)}), "
            f"got {len(observations)}")
    points = []
    for observation, step_poses in zip(observations, sensor_poses(trajectory, setup),
                                       strict=True):
        scans = setup.check_observation(observation)
        for key, (x, y, heading) in zip(setup.keys, step_poses, strict=True):
            hit = scans[key] < setup.max_range
            angles = heading + setup.beam_angles[hit]
            points.append(np.column_stack([x + scans[key][hit] * np.cos(angles),
                                           y + scans[key][hit] * np.sin(angles)]))
    points = np.vstack(points) if points else np.zeros((0, 2))
    if len(points) == 0:
        return math.nan
    near = _dilate(grid.occupied(), tolerance_cells)
    cells = np.floor(grid.to_grid_coordinates(points)).astype(np.int64)
    rows, cols = grid.shape
    inside = (cells[:, 0] >= 0) & (cells[:, 0] < cols) & (cells[:, 1] >= 0) & (cells[:, 1] < rows)
    agree = np.zeros(len(points), dtype=bool)
    agree[inside] = near[cells[inside, 1], cells[inside, 0]]
    return float(agree.mean())
