"""Routes the env refuses by name (a U-turn at one waypoint, no waypoints, coordinates beyond
any map) and corner radii that scale with the robot's body."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import lidar_env  # noqa: F401 - registers DualLidar-v0
from lidar_env.core.errors import ConfigError
from lidar_env.routes.user_traces import check_waypoints, rounded_path


def test_a_u_turn_at_one_waypoint_is_refused_not_cut_short() -> None:
    env = gym.make("DualLidar-v0", world="hallway", trace=[[2, 0], [15, 0], [2, 0]])
    with pytest.raises(ConfigError, match=r"turns by 180.0 degrees at waypoint 1 \(15, 0\)"):
        env.reset(seed=0)


@pytest.mark.parametrize("route", [np.zeros((0, 2)), [], [[1e300, 0.0], [0.0, 0.0]],
                                   [[0.0, 0.0], [-1e300, 1e300]]])
def test_empty_and_far_away_routes_are_named(route) -> None:
    expected = r"trace: (expected at least 2|expected \(N, 2\)|waypoint \d is .*finite coord)"
    with pytest.raises(ConfigError, match=expected):
        check_waypoints(route)


@settings(max_examples=50, deadline=None)
@given(st.lists(st.tuples(st.floats(width=64), st.floats(width=64)), max_size=5))
def test_any_route_is_checked_or_refused_by_name(points) -> None:
    try:
        checked = check_waypoints(np.array(points, dtype=np.float64).reshape(-1, 2))
    except ConfigError:
        return
    assert checked.shape[0] >= 2 and np.all(np.abs(checked) <= 1e6)


def test_corner_radius_scales_with_the_body() -> None:
    corner = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0]])
    for radius in (1.0, 0.24):
        path = rounded_path(corner, radius)
        # a 90-degree arc of radius r passes r (sqrt 2 - 1) from the corner
        gap = np.min(np.hypot(path[:, 0] - 4.0, path[:, 1]))
        assert gap == pytest.approx(radius * (np.sqrt(2) - 1), abs=0.02)
    burger = gym.make("DualLidar-v0", world="hallway", trace=0.5 * corner + (2.0, -1.0),
                      config={"robot": "turtlebot3_burger"})
    burger.reset(seed=0)
    path = burger.unwrapped.trace.waypoints
    gap = np.min(np.hypot(path[:, 0] - 4.0, path[:, 1] + 1.0))
    assert gap == pytest.approx(burger.unwrapped.config.body_scale * (np.sqrt(2) - 1), abs=0.02)
