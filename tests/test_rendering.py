"""rgb_array frames without a window or pygame; the human mode's missing-extra error."""

import sys

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.error import DependencyNotInstalled

import lidar_env  # noqa: F401 - registers DualLidar-v0
from lidar_env.env import DualLidarEnv
from lidar_env.rendering import (
    CAR_COLOUR,
    LIDAR_COLOURS,
    OBSTACLE,
    TRACE_COLOUR,
    TRAJECTORY_COLOURS,
    tile_frames,
    write_png,
)


def _count(frame, colour):
    return int(np.count_nonzero(np.all(frame == colour, axis=-1)))


@pytest.fixture
def no_pygame(monkeypatch):
    """Make ``import pygame`` fail, as on a machine without the ``human`` extra."""
    monkeypatch.setitem(sys.modules, "pygame", None)


def test_rgb_array_draws_world_trace_car_hits_and_trajectories(no_pygame):
    env = gym.make("DualLidar-v0", world="closed_to_open", render_mode="rgb_array")
    env.reset(seed=0)
    for _ in range(10):
        *_, info = env.step(np.array([1.0, 0.0], dtype=np.float32))
    before = env.render()
    assert before.dtype == np.uint8 and before.ndim == 3 and before.shape[2] == 3
    assert max(before.shape[:2]) == 640
    assert _count(before, OBSTACLE) > 1000
    assert _count(before, TRACE_COLOUR) > 100
    assert _count(before, CAR_COLOUR) > 10
    assert _count(before, LIDAR_COLOURS[0]) > 50 and _count(before, LIDAR_COLOURS[1]) > 50
    # the car is drawn where info says it is
    renderer = env.unwrapped._renderer
    rows, cols = renderer.to_pixels(info["pose"][None, :2])
    assert np.all(before[rows[0] - 1 : rows[0] + 2, cols[0] - 1 : cols[0] + 2] == CAR_COLOUR)
    env.unwrapped.set_render_trajectories({"estimate": [[5.0, -2.0, 0.0], [12.0, 2.0, 0.3]]})
    after = env.render()
    assert _count(after, TRAJECTORY_COLOURS[0]) > 50 and _count(before, TRAJECTORY_COLOURS[0]) == 0


def test_bad_trajectories_and_render_modes_are_readable():
    env = gym.make("DualLidar-v0", render_mode="rgb_array")
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"trajectory 'x': expected shape \(N, 2\) or \(N, 3\)"):
        env.unwrapped.set_render_trajectories({"x": np.zeros(5)})
    with pytest.raises(ValueError, match="render_mode: expected one of human, rgb_array"):
        DualLidarEnv(render_mode="video")


def test_human_mode_without_pygame_names_the_extra(no_pygame):
    env = gym.make("DualLidar-v0", render_mode="human")
    with pytest.raises(DependencyNotInstalled, match=r"duallidar\[human\]"):
        env.reset(seed=0)


def test_png_writer_round_trips_through_an_independent_reader(tmp_path):
    image = pytest.importorskip("matplotlib.image")
    rgb = np.random.default_rng(0).integers(0, 256, (37, 53, 3), dtype=np.uint8)
    write_png(tmp_path / "x.png", tile_frames([rgb, rgb[:20]], columns=2))
    back = np.round(image.imread(tmp_path / "x.png")[..., :3] * 255).astype(np.uint8)
    assert back.shape == (37, 106, 3)
    np.testing.assert_array_equal(back[:, :53], rgb)
    np.testing.assert_array_equal(back[:20, 53:], rgb[:20])
    assert np.all(back[20:, 53:] == 255)
    with pytest.raises(ValueError, match=r"image: expected \(H, W, 3\) uint8, got \(4, 4\)"):
        write_png(tmp_path / "y.png", np.zeros((4, 4), dtype=np.uint8))
