"""rgb_array frames without a window or pygame; the human mode's missing-extra error."""

import sys

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.error import DependencyNotInstalled

import lidar_env  # noqa: F401 - registers DualLidar-v0
from lidar_env.env import DualLidarEnv
from lidar_env.rendering.renderer import (
    CAR_COLOUR,
    LIDAR_COLOURS,
    MAP_ALPHA,
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
    assert max(before.shape[:2]) == 800  # config render_size
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


def test_pixels_follow_the_world_image_convention_on_a_non_square_world():
    """Pixel (r, c) of the frame is pixel (r, c) of ``world.to_image``, whose cell centres
    :class:`OccupancyGrid` documents independently; hallway's height is no whole number of
    pixels, so anchoring rows at ymax instead of ymin would shift every row."""
    from estimators.mapping.occupancy import OccupancyGrid

    env = gym.make("DualLidar-v0", world="hallway", render_mode="rgb_array")
    env.reset(seed=0)
    env.render()
    renderer = env.unwrapped._renderer
    world = env.unwrapped.world
    height = world.bounds[3] - world.bounds[1]
    assert height / renderer.resolution % 1 > 0.1  # the case that tells the anchors apart
    centres = OccupancyGrid(world.bounds, renderer.resolution).cell_centres()
    assert centres.shape[:2] == renderer.shape
    expected_rows, expected_cols = np.indices(renderer.shape).reshape(2, -1)
    for dx, dy in ((0, 0), (0.45, 0.45), (-0.45, -0.45), (0.45, -0.45)):  # anywhere in the cell
        shift = renderer.resolution * np.array([dx, dy])
        rows, cols = renderer.to_pixels(centres.reshape(-1, 2) + shift)
        np.testing.assert_array_equal(rows, expected_rows)
        np.testing.assert_array_equal(cols, expected_cols)
    rows, cols = expected_rows, expected_cols
    np.testing.assert_allclose(renderer.pixel_centres(rows, cols), centres.reshape(-1, 2))


def test_a_map_from_true_poses_overlays_the_world_obstacles(no_pygame):
    from scipy import ndimage

    from estimators import SensorSetup
    from estimators.mapping.occupancy import OccupancyGrid

    env = gym.make("DualLidar-v0", world="closed_to_open", render_mode="rgb_array")
    observation, info = env.reset(seed=0)
    env.render()
    renderer = env.unwrapped._renderer
    setup = SensorSetup.from_env(env)
    grid = OccupancyGrid(env.unwrapped.world.bounds, 0.05)
    env.unwrapped.set_render_map(grid)
    for _ in range(30):
        grid.integrate_observation(observation, info["pose"], setup)
        observation, *_, info = env.step(np.array([1.0, 0.2], dtype=np.float32))
    framed = env.render()  # the grid was filled after it was handed over
    env.unwrapped.set_render_map(None)
    plain = env.render()
    world_only = renderer.background
    overlaid = world_only.copy()
    renderer.overlay_map(overlaid, grid)
    untouched = np.all(plain == world_only, axis=-1)  # no car, hit or trace painted there
    np.testing.assert_array_equal(framed[untouched], overlaid[untouched])

    obstacles = np.all(world_only == OBSTACLE, axis=-1)
    changed = np.any(overlaid != world_only, axis=-1)
    # undo the blend: the map's own grey level, 255 (1 - p), where it observed something
    map_grey = (overlaid[..., 0] - (1.0 - MAP_ALPHA) * world_only[..., 0]) / MAP_ALPHA
    occupied = changed & (map_grey < 100)
    free = changed & (map_grey > 156)
    assert occupied.sum() > 200 and free.sum() > 10 * occupied.sum()
    near_obstacle = ndimage.binary_dilation(obstacles, iterations=1)
    assert (occupied & near_obstacle).sum() / occupied.sum() > 0.95
    assert (free & obstacles).sum() / free.sum() < 0.01
    assert np.any(framed != plain)
    with pytest.raises(TypeError, match="render map: expected an estimators.mapping.occupancy."
                                        "OccupancyGrid or None, got ndarray"):
        env.unwrapped.set_render_map(np.zeros((4, 4)))


def test_the_scoring_wrapper_builds_shows_and_scores_the_map_online(no_pygame):
    from agents.scripted import PurePursuitDriver
    from estimators import ScoreEstimator

    scores = {}
    for estimator in ("pc_fusion", "zero"):
        env = ScoreEstimator(gym.make("DualLidar-v0", world="open_cylinders", render_mode=
                                      "rgb_array", config={"max_episode_time": 4.0}),
                             estimator, map_resolution=0.1)
        driver = PurePursuitDriver()
        observation, info = env.reset(seed=0)
        driver.reset(env)
        assert env.unwrapped._render_map is env.grid  # what render() overlays
        done = False
        while not done:
            observation, _, terminated, truncated, info = env.step(driver.act(observation, info))
            done = terminated or truncated
        assert env.grid.occupied().sum() > 50
        shown = env.render()
        env.unwrapped.set_render_map(None)
        assert np.count_nonzero(np.any(shown != env.render(), axis=-1)) > 1000
        scores[estimator] = info["estimator"]
    assert scores["pc_fusion"]["map_iou"] > 0.8 and scores["pc_fusion"]["map_precision"] > 0.9
    assert scores["zero"]["map_iou"] < 0.5 * scores["pc_fusion"]["map_iou"]
    with pytest.raises(ValueError, match="map_resolution: expected a positive cell side"):
        ScoreEstimator(gym.make("DualLidar-v0"), "zero", map_resolution=0.0)
