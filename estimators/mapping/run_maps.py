"""The map of one run, built and scored in one place: :func:`map_truth` computes once per scenario
what its maps are scored against (the true occupied cells, the visible ones, the observable
cylinders), :func:`evaluate_run_map` builds the occupancy grid at an estimator's poses, tracks
its obstacles and scores both (:mod:`estimators.mapping.map_scoring`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimators.base import SensorSetup
from estimators.mapping.map_scoring import (
    CylinderScores,
    MapScores,
    beam_hit_cells,
    observable_cylinders,
    score_cylinders,
    score_occupancy,
    true_occupancy,
)
from estimators.mapping.obstacles import DetectorParams, detect_in_observation
from estimators.mapping.occupancy import Bounds, OccupancyGrid, from_estimator_run, sensor_poses
from estimators.mapping.tracking import ObstacleTracker
from lidar_env.errors import EstimatorInputError


@dataclass(frozen=True)
class MapTruth:
    """What a map of one run is scored against, computed once per true run.

    Attributes:
        image: ``(rows, cols)`` uint8 :func:`true_occupancy` of the world, 255 = obstacle.
        visible: ``(rows, cols)`` the true occupied cells a noiseless beam of the run hit.
        circles: ``(N, 3)`` true cylinders ``cx, cy, r`` [m].
        observable: ``(N,)`` cylinders with enough returns in one true scan.
        bounds: ``world.bounds`` [m], over which maps are built.
        resolution: [m] cell size.
    """

    image: NDArray[np.uint8]
    visible: NDArray[np.bool_]
    circles: NDArray[np.float64]
    observable: NDArray[np.bool_]
    bounds: Bounds
    resolution: float


def map_truth(
    world: Any,
    true_trajectory: ArrayLike,
    setup: SensorSetup,
    resolution: float = 0.05,
    min_circle_points: int = DetectorParams().min_circle_points,
) -> MapTruth:
    """The :class:`MapTruth` of ``world`` seen by the Lidars of ``setup`` along the true car
    poses ``true_trajectory`` (N, 3); cylinders need ``min_circle_points`` returns in one scan
    to count as observable (the detector's own threshold by default)."""
    true_trajectory = np.asarray(true_trajectory, dtype=np.float64)
    if true_trajectory.ndim != 2 or true_trajectory.shape[1] != 3:
        raise EstimatorInputError(
            f"true_trajectory: expected shape (N, 3), got {true_trajectory.shape}")
    true_poses = sensor_poses(true_trajectory, setup).reshape(-1, 3)
    grid = OccupancyGrid(world.bounds, resolution)
    true = true_occupancy(world, grid)
    circles = np.asarray(world.circles, dtype=np.float64).reshape(-1, 3)
    observable = observable_cylinders(world, true_poses, setup.beam_angles, setup.max_range,
                                      min_circle_points)
    return MapTruth(
        image=np.where(true, np.uint8(255), np.uint8(0)),
        visible=true & beam_hit_cells(world, true_poses, setup.beam_angles, grid,
                                      setup.max_range),
        circles=circles,
        observable=observable,
        bounds=grid.bounds,
        resolution=grid.resolution,
    )


@dataclass(frozen=True)
class RunMapEvaluation:
    """What :func:`evaluate_run_map` measured, and the map and tracker it built."""

    map_scores: MapScores
    cylinder_scores: CylinderScores | None  # None for worlds without cylinders
    grid: OccupancyGrid
    tracker: ObstacleTracker


def track_obstacles(
    trajectory: ArrayLike,
    observations: Sequence[Mapping[str, ArrayLike]],
    setup: SensorSetup,
    params: DetectorParams | None = None,
    gate: float = 0.5,
) -> ObstacleTracker:
    """Detect the obstacles of every scan at the (estimated) sensor poses of ``trajectory``
    (N, 3) and track them across steps (one tracker step per observation)."""
    tracker = ObstacleTracker(gate=gate)
    for observation, car_pose in zip(observations, np.asarray(trajectory), strict=True):
        tracker.update(detect_in_observation(observation, car_pose, setup, params))
    return tracker


def evaluate_run_map(
    truth: MapTruth,
    estimated_trajectory: ArrayLike,
    observations: Sequence[Mapping[str, ArrayLike]],
    setup: SensorSetup,
    tolerance_cells: int = 1,
    params: DetectorParams | None = None,
) -> RunMapEvaluation:
    """Map and track obstacles from ``observations`` at the car poses ``estimated_trajectory``
    (N, 3), and score both against ``truth`` (:func:`map_truth` of the same run): occupied cells
    at ``tolerance_cells`` over the visible cells, and cylinders
    (:meth:`~estimators.mapping.obstacles.ObstacleTracker.cylinders`) against the observable
    true ones."""
    grid = from_estimator_run(estimated_trajectory, observations, setup, truth.resolution,
                              bounds=truth.bounds)
    map_scores = score_occupancy(grid.occupied(), truth.image, tolerance_cells, truth.visible)
    tracker = track_obstacles(estimated_trajectory, observations, setup, params)
    cylinder_scores = None
    if len(truth.circles):
        cylinder_scores = score_cylinders(tracker.cylinders(), truth.circles,
                                          observable=truth.observable)
    return RunMapEvaluation(map_scores, cylinder_scores, grid, tracker)
