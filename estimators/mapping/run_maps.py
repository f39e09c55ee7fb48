"""The map of one run, built and scored in one place: :func:`from_estimator_run` builds the
occupancy grid at an estimator's poses (leaving out the returns on moving things when it is
given the scans' times, :mod:`estimators.mapping.moving_returns`), :func:`track_obstacles`
its cylinder map, :func:`map_truth` computes once per scenario what maps are scored against
(the true occupied cells, the visible ones, the observable cylinders), and
:func:`evaluate_run_map` builds and scores both (:mod:`estimators.mapping.map_scoring`).
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
from estimators.mapping.moving_returns import MovingStep, label_run
from estimators.mapping.obstacles import (
    DetectorParams,
    Obstacle,
    detect_in_observation,
    placed,
)
from estimators.mapping.occupancy import Bounds, OccupancyGrid, bounds_around, sensor_poses
from estimators.mapping.tracking import ObstacleTracker
from lidar_env.core import EstimatorInputError


def from_estimator_run(
    trajectory: ArrayLike,
    observations: Sequence[Mapping[str, ArrayLike]],
    setup: SensorSetup,
    resolution: float = 0.05,
    bounds: Bounds | None = None,
    times: ArrayLike | None = None,
    moving: Sequence[MovingStep] | None = None,
    **grid_params: float,
) -> OccupancyGrid:
    """The map built from ``observations[k]`` (scans keyed by ``setup.keys``) taken at car pose
    ``trajectory[k]`` (N, 3), e.g. an estimator's ``trajectory`` and the scans it was fed.

    With the scans' ``times`` [s] (or their ``moving`` labels, :func:`label_run`, already
    computed), the returns on tracks labelled moving clear the space before them but mark
    nothing occupied. ``bounds`` default to the trajectory's extent plus the largest max range
    on every side, which holds every return. ``grid_params`` go to :class:`OccupancyGrid`
    (``p_hit``, ...)."""
    trajectory = np.asarray(trajectory, dtype=np.float64)
    if trajectory.ndim != 2 or trajectory.shape[1] != 3:
        raise EstimatorInputError(f"trajectory: expected shape (N, 3), got {trajectory.shape}")
    if len(observations) != len(trajectory):
        raise EstimatorInputError(
            f"observations: expected one per trajectory row ({len(trajectory)}), "
            f"got {len(observations)}")
    if moving is None and times is not None:
        moving = label_run(trajectory, observations, setup, times)
    if moving is not None and len(moving) != len(trajectory):
        raise EstimatorInputError(
            f"moving: expected one step per trajectory row ({len(trajectory)}), got {len(moving)}")
    if bounds is None:
        reach = max(sensor.max_range for sensor in setup.sensors)
        bounds = bounds_around(sensor_poses(trajectory, setup)[..., :2].reshape(-1, 2), reach)
    grid = OccupancyGrid(bounds, resolution, **grid_params)
    for k, (observation, car_pose) in enumerate(zip(observations, trajectory, strict=True)):
        grid.integrate_observation(observation, car_pose, setup,
                                   None if moving is None else moving[k].beams)
    return grid


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
    moving: Sequence[MovingStep] | None = None,
    car_frame: Sequence[Sequence[Obstacle]] | None = None,
) -> ObstacleTracker:
    """Detect the obstacles of every scan at the (estimated) sensor poses of ``trajectory``
    (N, 3) and track them across steps (one tracker step per observation). With the steps'
    ``moving`` labels (:func:`label_run`), only the detections not on a moving track. With
    the observations' ``car_frame`` detections (:func:`car_frame_obstacles`, made once for
    every estimate of a run), they are placed at the poses instead of detected again."""
    tracker = ObstacleTracker(gate=gate)
    if moving is not None:
        for step in moving:
            tracker.update(step.static_obstacles)
        return tracker
    trajectory = np.asarray(trajectory, dtype=np.float64)
    if car_frame is not None:
        if len(car_frame) != len(trajectory):
            raise EstimatorInputError(f"car_frame: expected one list of obstacles per "
                                      f"trajectory row ({len(trajectory)}), got {len(car_frame)}")
        for found, car_pose in zip(car_frame, trajectory, strict=True):
            tracker.update([placed(obstacle, car_pose) for obstacle in found])
        return tracker
    for observation, car_pose in zip(observations, trajectory, strict=True):
        tracker.update(detect_in_observation(observation, car_pose, setup, params))
    return tracker


def car_frame_obstacles(observations: Sequence[Mapping[str, ArrayLike]], setup: SensorSetup,
                        params: DetectorParams | None = None) -> list[list[Obstacle]]:
    """The obstacles of each observation in the car frame (car pose ``(0, 0, 0)``): the
    detections :func:`track_obstacles` places at any estimate of the poses."""
    origin = np.zeros(3)
    return [detect_in_observation(observation, origin, setup, params)
            for observation in observations]


def evaluate_run_map(
    truth: MapTruth,
    estimated_trajectory: ArrayLike,
    observations: Sequence[Mapping[str, ArrayLike]],
    setup: SensorSetup,
    tolerance_cells: int = 1,
    params: DetectorParams | None = None,
    times: ArrayLike | None = None,
) -> RunMapEvaluation:
    """Map and track obstacles from ``observations`` at the car poses ``estimated_trajectory``
    (N, 3), and score both against ``truth`` (:func:`map_truth` of the same run): occupied cells
    at ``tolerance_cells`` over the visible cells, and cylinders
    (:meth:`~estimators.mapping.obstacles.ObstacleTracker.cylinders`) against the observable
    true ones. With the scans' ``times`` [s], both leave out the returns on moving things
    (:func:`from_estimator_run`)."""
    moving = None if times is None else label_run(estimated_trajectory, observations, setup,
                                                    times, params)
    grid = from_estimator_run(estimated_trajectory, observations, setup, truth.resolution,
                              bounds=truth.bounds, moving=moving)
    map_scores = score_occupancy(grid.occupied(), truth.image, tolerance_cells, truth.visible)
    tracker = track_obstacles(estimated_trajectory, observations, setup, params, moving=moving)
    cylinder_scores = None
    if len(truth.circles):
        cylinder_scores = score_cylinders(tracker.cylinders(), truth.circles,
                                          observable=truth.observable)
    return RunMapEvaluation(map_scores, cylinder_scores, grid, tracker)
