"""Routes the user brings (``trace=`` / ``options["trace"]`` as waypoints or a Trace): clearance
checked with the first blocked segment named, corners rounded into a drivable path, and the
scripted driver completing such a route in a ROS-map world."""

import math

import gymnasium as gym
import numpy as np
import pytest

import lidar_env  # noqa: F401 - registers DualLidar-v0
from agents.scripted import PurePursuitDriver
from lidar_env.core.errors import ConfigError
from lidar_env.routes.trace_geometry import WAYPOINT_SPACING
from lidar_env.routes.traces import TraceFitError
from lidar_env.routes.user_traces import rounded_path
from lidar_env.world.ros_map import save_ros_map
from lidar_env.world.world import World

#: Around the 2 m x 2 m block at x 5..7, y 4..6 of the 16 m x 10 m room, clear of the walls.
ROUTE = [(2.0, 2.0), (10.0, 2.0), (10.0, 8.0), (3.0, 8.0)]


def room_probabilities() -> np.ndarray:
    """The room at 0.05 m/px as occupancy probabilities, row 0 at the top (y = 10 m)."""
    grid = np.full((200, 320), 0.05)
    grid[:3] = grid[-3:] = grid[:, :3] = grid[:, -3:] = 0.95
    grid[80:120, 100:140] = 0.95
    return grid


def test_the_scripted_driver_completes_a_waypoint_route_in_a_ros_map_world(tmp_path):
    yaml_path, _ = save_ros_map(tmp_path / "room.yaml", room_probabilities(), 0.05)
    env = gym.make("DualLidar-v0", world=str(yaml_path), trace=np.array(ROUTE))
    observation, info = env.reset(seed=0)
    trace = env.unwrapped.trace
    np.testing.assert_allclose(info["pose"][:2], ROUTE[0])
    assert info["pose"][2] == pytest.approx(0.0)  # along the first leg
    driver = PurePursuitDriver()
    driver.reset(env)
    terminated = truncated = False
    worst = 0.0
    while not (terminated or truncated):
        observation, _, terminated, truncated, info = env.step(driver.act(observation, info))
        assert not info["collision"]
        worst = max(worst, abs(info["cross_track_error"]))
    assert terminated and info["progress"] > 0.95
    assert np.hypot(*(info["pose"][:2] - np.array(ROUTE[-1]))) < 0.5
    assert worst < 0.1
    assert trace.length == pytest.approx(8 + 6 + 7 - 2 * 2 * (1 - math.pi / 4), abs=0.02)


def test_corners_are_rounded_into_a_dense_smooth_path():
    path = rounded_path(np.array(ROUTE, dtype=float))
    steps = np.hypot(*np.diff(path, axis=0).T)
    assert steps.max() <= WAYPOINT_SPACING + 1e-9
    headings = np.unwrap(np.arctan2(*np.diff(path, axis=0).T[::-1]))
    assert np.max(np.abs(np.diff(headings))) < 0.1  # no kink: the corners became arcs
    assert headings[-1] - headings[0] == pytest.approx(math.pi)  # two left turns
    # each arc of radius 1 m passes 1 / cos(45 deg) - 1 = 0.414 m inside its corner
    assert np.min(np.hypot(*(path - np.array(ROUTE[1])).T)) == pytest.approx(0.414, abs=0.01)


def test_routes_in_built_in_worlds_from_options_and_as_a_trace():
    env = gym.make("DualLidar-v0", world="hallway")
    _, info = env.reset(seed=0, options={"trace": [(2.0, 0.0), (20.0, 0.0), (20.0, 4.0)]})
    first = env.unwrapped.trace
    assert first.seed == "waypoints" and info["pose"][:2].tolist() == [2.0, 0.0]
    env.reset(seed=1, options={"trace": [(2.0, 0.0), (20.0, 0.0), (20.0, 4.0)]})
    assert env.unwrapped.trace is first  # cached per world and route
    env.reset(seed=0, options={"trace": first})
    assert env.unwrapped.trace is first
    with pytest.raises(ConfigError, match="fixed world"):
        gym.make("DualLidar-v0", world="random", trace=np.array(ROUTE)).reset(seed=0)


@pytest.mark.parametrize(
    ("route", "error", "message"),
    [
        ([(2.0, 2.0), (np.nan, 3.0)], ConfigError, r"waypoint 1 is \[nan, 3.0\]"),
        ([(2.0, 2.0)], ConfigError, "at least 2 distinct waypoints, got 1"),
        ([(2.0, 2.0), (2.0, 2.0)], ConfigError, "at least 2 distinct waypoints, got 1"),
        ([[1, 2, 3]], ConfigError, r"expected \(N, 2\) waypoints"),
        ([(2.0, 2.0), (10.0, 2.0), (2.0, 8.0)], TraceFitError,
         r"segment 1 from \(10.00, 2.00\) to \(2.00, 8.00\) is blocked .* expected >= 0.77 m"),
        ([(2.0, 5.0), (12.0, 5.0)], TraceFitError, r"segment 0 .*is blocked"),
        ([(2.0, 2.0), (20.0, 2.0)], TraceFitError, r"segment 0 .*is blocked"),  # off the map
    ],
)
def test_bad_routes_raise_readable_errors(route, error, message):
    world = World.from_image((room_probabilities() > 0.5).astype(np.uint8), 0.05)
    env = gym.make("DualLidar-v0", world=world)
    with pytest.raises(error, match=message):
        env.reset(seed=0, options={"trace": route})
