"""Maps that leave movers out: the tracker's moving label keeps a walker's returns out of the
occupancy grid and the cylinder map, while the space before them is still cleared."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.base import SensorSetup
from estimators.mapping.moving_returns import MovingReturns, label_run
from estimators.mapping.occupancy import OccupancyGrid
from estimators.mapping.run_maps import from_estimator_run, track_obstacles
from lidar_env.core.errors import EstimatorInputError
from lidar_env.sensors.lidar import cast_rays
from lidar_env.world.world import World

ANGLES = 2 * np.pi * np.arange(360) / 360
MOUNTS = np.array([[0.25, 0.0, 0.0], [-0.25, 0.0, 0.0]])  # a standing car's two Lidars
SETUP = SensorSetup(MOUNTS, ANGLES, 10.0)
WALLS = [[-2.0, 6.0, 10.0, 6.0], [-2.0, -6.0, 10.0, -6.0]]
POST = (5.0, 2.0, 0.3)
BOUNDS = (-2.0, -6.5, 10.0, 6.5)


def walker_at(k: int) -> tuple[float, float]:
    """The walker's centre [m] at step ``k``: it comes straight at the standing car at 1 m/s,
    so its own body hides the cells it left."""
    return 5.5 - 0.1 * k, -2.0


def walk(steps: int = 30) -> tuple[np.ndarray, list[dict[str, np.ndarray]], np.ndarray]:
    """The walker (r = 0.25 m) and a post, seen from the standing car: car poses, observations,
    times [s]."""
    rng = np.random.default_rng(2)
    observations = []
    for k in range(steps):
        world = World(circles=[POST, (*walker_at(k), 0.25)], segments=WALLS)
        scans = cast_rays(world, MOUNTS, ANGLES, 10.0)
        observations.append({key: np.where(s < 10.0, s + 0.01 * rng.standard_normal(s.shape),
                                           s).astype(np.float32)
                             for key, s in zip(("lidar_1", "lidar_2"), scans, strict=True)})
    return np.zeros((steps, 3)), observations, 0.1 * np.arange(steps)


def occupied_near(grid: OccupancyGrid, x: float, y: float, radius: float) -> int:
    centres = grid.cell_centres()
    near = np.hypot(centres[..., 0] - x, centres[..., 1] - y) <= radius
    return int(np.count_nonzero(grid.occupied() & near))


def test_the_walker_is_left_out_of_the_grid_and_the_post_stays() -> None:
    poses, observations, times = walk()
    with_labels = from_estimator_run(poses, observations, SETUP, 0.05, BOUNDS, times=times)
    plain = from_estimator_run(poses, observations, SETUP, 0.05, BOUNDS)
    x, y = walker_at(29)
    centres = plain.cell_centres()
    trail = (np.abs(centres[..., 1] - y) < 0.4) & (centres[..., 0] > x - 0.4) & (
        centres[..., 0] < walker_at(3)[0])  # from its third detection (the label) on
    assert np.count_nonzero(plain.occupied() & trail) >= 8  # a smear behind the walker
    assert np.count_nonzero(with_labels.occupied() & trail) <= 2
    assert occupied_near(with_labels, *POST[:2], 0.4) == occupied_near(plain, *POST[:2], 0.4) > 5
    walls = with_labels.occupied() & (np.abs(with_labels.cell_centres()[..., 1]) > 5.8)
    assert np.count_nonzero(walls) == np.count_nonzero(
        plain.occupied() & (np.abs(plain.cell_centres()[..., 1]) > 5.8))


def test_the_cylinder_map_keeps_the_post_only() -> None:
    poses, observations, times = walk()
    moving = label_run(poses, observations, SETUP, times)
    assert sum(bool(step.moving.any()) for step in moving) >= 25  # labelled after 3 hits
    assert not any(step.moving.any() for step in moving[:2])
    (post,) = track_obstacles(poses, observations, SETUP, moving=moving).cylinders()
    np.testing.assert_allclose(post, POST, atol=0.03)


def test_a_moving_return_clears_before_it_and_marks_nothing() -> None:
    grid = OccupancyGrid((0.0, -0.5, 5.0, 0.5), 0.1)
    ranges, angles, pose = np.array([3.0]), np.array([0.0]), np.array([0.05, 0.0, 0.0])
    grid.integrate(ranges, angles, pose, 10.0, moving=np.array([True]))
    assert not grid.occupied().any()
    plain = OccupancyGrid((0.0, -0.5, 5.0, 0.5), 0.1)
    plain.integrate(ranges, angles, pose, 10.0)
    np.testing.assert_array_equal(grid.free(), plain.free())
    assert plain.occupied().sum() == 1


def test_bad_labels_are_named() -> None:
    poses, observations, times = walk(3)
    with pytest.raises(EstimatorInputError, match="moving: expected the shape of ranges"):
        OccupancyGrid(BOUNDS, 0.1).integrate(np.ones(4), np.zeros(4), np.zeros(3), 10.0,
                                             moving=np.ones(3, bool))
    with pytest.raises(EstimatorInputError, match="times: expected one of each per step"):
        label_run(poses, observations, SETUP, times[:2])
    with pytest.raises(EstimatorInputError, match="moving: expected one step per trajectory"):
        from_estimator_run(poses, observations, SETUP, moving=label_run(
            poses[:2], observations[:2], SETUP, times[:2]))
    with pytest.raises(ValueError, match="t: expected a finite time"):
        MovingReturns(SETUP).update(observations[0], poses[0], float("nan"))
