"""Occupancy grid -> ROS map -> world round trip (``estimators.mapping.ros_map_export``): the
map built from a drive reads back into a world whose walls are where the true walls are, and
the car can be driven again in it."""

import gymnasium as gym
import numpy as np

import lidar_env  # noqa: F401 - registers DualLidar-v0
from agents.scripted import PurePursuitDriver
from estimators.base import SensorSetup
from estimators.mapping.ros_map_export import save_grid_as_ros_map
from estimators.mapping.run_maps import from_estimator_run
from lidar_env import lidars_with_noise
from lidar_env.world.ros_map import read_ros_map
from lidar_env.world.world import World


def test_a_mapped_drive_saves_as_a_ros_map_that_drives_again(tmp_path):
    env = gym.make("DualLidar-v0", world="hallway", trace="straight",
                   config={"lidars": lidars_with_noise(range_noise_std=0.0),
                           "max_episode_time": 12.0})
    driver = PurePursuitDriver()
    observation, info = env.reset(seed=0)
    driver.reset(env)
    poses, observations = [info["pose"]], [observation]
    done = False
    while not done:
        observation, _, terminated, truncated, info = env.step(driver.act(observation, info))
        poses.append(info["pose"])
        observations.append(observation)
        done = terminated or truncated
    grid = from_estimator_run(np.array(poses), observations, SensorSetup.from_env(env))
    yaml_path, _ = save_grid_as_ros_map(grid, tmp_path / "hallway_map.yaml")
    ros = read_ros_map(yaml_path)
    np.testing.assert_array_equal(ros.cells == 100, grid.probabilities() > 0.65)
    world = World.from_ros_map(yaml_path)
    truth = env.unwrapped.world
    # every cell the map calls occupied is within two cells of a true wall
    rows, cols = np.nonzero(ros.cells == 100)
    xmin, ymin, _, _ = grid.bounds
    centres = np.stack([xmin + (cols + 0.5) * grid.resolution,
                        ymin + (ros.cells.shape[0] - rows - 0.5) * grid.resolution], axis=1)
    assert len(centres) > 100
    assert np.all(np.abs(truth.clearance(centres)) <= 2 * grid.resolution)
    # the start and the driven path are free in the map's world: it can be driven again
    again = gym.make("DualLidar-v0", world=world, trace="straight")
    _, info = again.reset(seed=0, options={"start": tuple(poses[0])})
    np.testing.assert_allclose(info["pose"], poses[0])
    for _ in range(10):
        *_, info = again.step(np.array([1.0, 0.0], dtype=np.float32))
        assert not info["collision"]
