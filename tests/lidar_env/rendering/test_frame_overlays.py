"""A frame a person can read: sized by render_size, cropped to a ROS map's known area, unknown
cells apart from obstacles, a scale bar and a legend."""

from __future__ import annotations

import sys

import gymnasium as gym
import numpy as np
import pytest

import lidar_env  # noqa: F401 - registers DualLidar-v0
from lidar_env.core.errors import ConfigError
from lidar_env.rendering.overlays import UNKNOWN, nice_length
from lidar_env.rendering.renderer import CAR_COLOUR, LIDAR_COLOURS, OBSTACLE, TRACE_COLOUR
from lidar_env.world.ros_map import save_ros_map


def _has(region: np.ndarray, colour: np.ndarray) -> bool:
    return bool(np.any(np.all(region == colour, axis=-1)))


@pytest.fixture
def ros_map(tmp_path):
    """A 4 x 3 m walled room in the middle of a 10 x 10 m map of unknown cells."""
    grid = np.full((200, 200), np.nan)
    grid[70:130, 60:140] = 1.0
    grid[73:127, 63:137] = 0.0
    return save_ros_map(tmp_path / "room.yaml", grid, 0.05)[0]


def test_a_frame_shows_scale_bar_legend_and_unknown_apart_from_obstacles(ros_map, monkeypatch):
    monkeypatch.setitem(sys.modules, "pygame", None)  # rgb_array needs no window
    env = gym.make("DualLidar-v0", world=str(ros_map), render_mode="rgb_array",
                   config={"robot": "turtlebot3_burger"})
    env.reset(seed=0)
    frame = env.render()
    assert max(frame.shape[:2]) == 800
    # cropped to the known 4 x 3 m room (+ a margin), not the 10 x 10 m map
    assert frame.shape[1] / frame.shape[0] == pytest.approx(4.24 / 3.24, rel=0.03)
    assert _has(frame, UNKNOWN) and _has(frame, OBSTACLE)
    assert not np.array_equal(UNKNOWN, OBSTACLE)
    height, width = frame.shape[:2]
    top_right = frame[: height // 3, width // 2:]
    for colour in (CAR_COLOUR, TRACE_COLOUR, LIDAR_COLOURS[0], UNKNOWN, OBSTACLE):
        assert _has(top_right, colour)
    bottom_left = frame[-40:, : width // 2]
    black_run = np.all(bottom_left == 0, axis=-1).sum(axis=1).max()
    length = nice_length(0.2 * width * 4.24 / width)  # [m] at the frame's metres per pixel
    assert black_run >= round(length * width / 4.24) - 2  # the bar spans its length


def test_render_size_sets_the_long_side(ros_map) -> None:
    env = gym.make("DualLidar-v0", world="hallway", render_mode="rgb_array",
                   config={"render_size": 1200})
    env.reset(seed=0)
    assert max(env.render().shape[:2]) == 1200
    for size in (8, 10**6, 800.5):
        with pytest.raises(ConfigError, match="render_size: expected an integer in"):
            gym.make("DualLidar-v0", config={"render_size": size})
