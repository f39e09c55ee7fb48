"""A TurtleBot3 Burger in ROS maps of its own scale: it resets, drives its default trace and a
route with 90-degree corners 0.3 m clear of obstacles without collision, and lidar_odometry on
the drive stays within 5 cm ATE and 1 % drift."""

from __future__ import annotations

import math
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import estimators
import lidar_env  # noqa: F401 - registers DualLidar-v0
from agents.scripted import PurePursuitDriver
from estimators.base import SensorSetup
from estimators.evaluation.metrics import evaluate
from lidar_env.world.ros_map import save_ros_map

RESOLUTION = 0.05  # [m/px]
#: Between the hexagon's pillar rows: 0.4 m from the pillars' surfaces.
HEXAGON_ROUTE = [[-1.65, -0.55], [1.65, -0.55], [1.65, 0.55], [-1.65, 0.55]]
#: Along the depot's bottom aisle, up a 2 m aisle, across and up another: >= 1 m clear.
DEPOT_ROUTE = [[2.0, 1.0], [12.0, 1.0], [12.0, 7.5], [6.0, 7.5], [6.0, 12.0]]


def _cell_centres(width: float, height: float, origin: tuple[float, float]) -> tuple:
    xs = origin[0] + (np.arange(round(width / RESOLUTION)) + 0.5) * RESOLUTION
    ys = origin[1] + (np.arange(round(height / RESOLUTION))[::-1] + 0.5) * RESOLUTION
    return np.meshgrid(xs, ys)


def hexagon_map(path: Path) -> Path:
    """A 5.5 m (across flats) hexagon walled 0.1 m thick, a 3 x 3 grid of 0.3 m pillars 1.1 m
    apart at its centre, unknown outside (turtlebot3_world's layout features)."""
    x, y = _cell_centres(7.0, 7.0, (-3.5, -3.5))
    inside, walled = np.ones(x.shape, bool), np.ones(x.shape, bool)
    for k in range(6):
        along = x * math.cos(k * math.pi / 3) + y * math.sin(k * math.pi / 3)
        inside &= along < 2.75
        walled &= along < 2.85
    grid = np.where(inside, 0.0, np.where(walled, 1.0, np.nan))
    for cx in (-1.1, 0.0, 1.1):
        for cy in (-1.1, 0.0, 1.1):
            grid[np.hypot(x - cx, y - cy) <= 0.15] = 1.0
    return save_ros_map(path, grid, RESOLUTION, origin=(-3.5, -3.5, 0.0))[0]


def depot_map(path: Path) -> Path:
    """A 30 x 15 m depot: outer walls, rows of 1 x 1.5 m shelf units with 0.5 m gaps along 2 m
    aisles, unknown outside."""
    x, y = _cell_centres(31.0, 16.0, (-0.5, -0.5))
    inside = (x > 0) & (x < 30) & (y > 0) & (y < 15)
    walled = (x > -0.1) & (x < 30.1) & (y > -0.1) & (y < 15.1)
    grid = np.where(inside, 0.0, np.where(walled, 1.0, np.nan))
    for x0 in np.arange(4.0, 27.0, 3.0):
        for y0 in (2.0, 4.0, 9.0, 11.0):
            grid[(x > x0) & (x < x0 + 1.0) & (y > y0) & (y < y0 + 1.5)] = 1.0
    return save_ros_map(path, grid, RESOLUTION, origin=(-0.5, -0.5, 0.0))[0]


def drive(world: Path, trace, odometry: bool) -> dict:
    """Drive the Burger along ``trace`` (None: its default) with pure pursuit at full speed."""
    env = gym.make("DualLidar-v0", world=str(world), trace=trace,
                   config={"robot": "turtlebot3_burger", "max_episode_time": 300.0})
    observation, info = env.reset(seed=0)
    driver = PurePursuitDriver(speed=0.22, lookahead=0.2)
    driver.reset(env)
    estimator = estimators.make("lidar_odometry") if odometry else None
    if estimator is not None:
        estimator.reset(SensorSetup.from_env(env), info["pose"])
        estimator.update(observation, info["time"])
    poses, terminated, truncated = [info["pose"]], False, False
    while not (terminated or truncated):
        observation, _, terminated, truncated, info = env.step(driver.act(observation, info))
        assert not info["collision"], f"collision at {info['pose']}"
        poses.append(info["pose"])
        if estimator is not None:
            estimator.update(observation, info["time"])
    result = {"finished": terminated, "length": env.unwrapped.trace.length}
    if estimator is not None:
        metrics = evaluate(estimator.trajectory, np.array(poses))
        result |= {"ate": metrics.ate_rmse_m, "drift": metrics.drift_percent}
    return result


@pytest.fixture(scope="module")
def maps(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("robot_maps")
    return {"hexagon": hexagon_map(folder / "hexagon.yaml"),
            "depot": depot_map(folder / "depot.yaml")}


@pytest.mark.parametrize("name", ["hexagon", "depot"])
def test_the_burger_drives_its_default_trace_without_collision(maps, name) -> None:
    result = drive(maps[name], None, odometry=name == "depot")
    assert result["finished"] and result["length"] > 1.0
    if name == "depot":
        assert result["ate"] <= 0.05 and result["drift"] <= 1.0


def test_the_burger_drives_a_route_with_right_angles_and_odometry_follows(maps) -> None:
    result = drive(maps["hexagon"], HEXAGON_ROUTE, odometry=True)
    assert result["finished"]
    assert result["ate"] <= 0.05 and result["drift"] <= 1.0


def test_the_burger_drives_the_depot_route_without_collision(maps) -> None:
    assert drive(maps["depot"], DEPOT_ROUTE, odometry=False)["finished"]
