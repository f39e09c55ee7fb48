"""Worlds the user brings (``world=`` and ``options["world"]``): a World, a grayscale matrix,
an image file and a ROS map_server YAML; their starts, cached scenes and env checks."""

import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from PIL import Image

import lidar_env  # noqa: F401 - registers DualLidar-v0
from lidar_env import lidars_with_noise
from lidar_env.core.errors import ConfigError
from lidar_env.scenes import StartPoseError
from lidar_env.world.ros_map import save_ros_map
from lidar_env.world.world import World


def room() -> np.ndarray:
    """A 16 m x 10 m room at 0.05 m/px: walls 3 px thick, a 2 m x 2 m block at x 5..7, y 4..6."""
    pixels = np.zeros((200, 320), dtype=np.uint8)
    pixels[:3] = pixels[-3:] = 1
    pixels[:, :3] = pixels[:, -3:] = 1
    pixels[80:120, 100:140] = 1
    return pixels


def ros_room(tmp_path):
    probabilities = np.where(room() > 0, 0.95, 0.05).astype(np.float64)
    probabilities[:10, 150:170] = np.nan  # an unmapped patch in the top wall
    return save_ros_map(tmp_path / "room.yaml", probabilities, 0.05, (-2.0, 1.0, 0.0))[0]


def _rollout(env, seed, steps=25):
    observation, info = env.reset(seed=seed)
    record = [info["pose"], *observation.values()]
    for _ in range(steps):
        observation, reward, terminated, truncated, info = env.step(np.array([0.8, 0.2],
                                                                             np.float32))
        record += [info["pose"], [reward], *observation.values()]
        if terminated or truncated:
            break
    return np.concatenate([np.asarray(r, dtype=np.float64).ravel() for r in record])


@pytest.mark.parametrize("kind", ["array", "ros_map"])
def test_env_checks_on_user_worlds(kind, tmp_path):
    world = room() if kind == "array" else ros_room(tmp_path)
    env = gym.make("DualLidar-v0", world=world,
                   config={"lidars": lidars_with_noise(dropout_prob=0.05)})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped, skip_render_check=True)
    assert _rollout(env, 3).tobytes() == _rollout(env, 3).tobytes()
    clone = pickle.loads(pickle.dumps(env))
    action = np.array([0.5, -0.1], dtype=np.float32)
    for _ in range(3):
        a, b = env.step(action), clone.step(action)
        np.testing.assert_array_equal(a[0]["lidar_1"], b[0]["lidar_1"])
    envs = gym.make_vec("DualLidar-v0", num_envs=2, vectorization_mode="sync", world=world)
    try:
        observations, infos = envs.reset(seed=[0, 1])
        assert observations["lidar_2"].shape == (2, 360) and infos["pose"].shape == (2, 3)
    finally:
        envs.close()


def test_every_world_form_gives_the_same_map(tmp_path):
    Image.fromarray(room() * 255).save(tmp_path / "room.png")
    world = World.from_image(room(), 0.05)
    poses = []
    for value in (world, room(), str(tmp_path / "room.png"), tmp_path / "room.png"):
        env = gym.make("DualLidar-v0", world=value,
                       config={"lidars": lidars_with_noise(range_noise_std=0.0)})
        observation, info = env.reset(seed=0)
        poses.append(info["pose"])
        np.testing.assert_allclose(env.unwrapped.world.bounds, (0, 0, 16, 10))
    np.testing.assert_array_equal(poses, [poses[0]] * 4)
    # a start clear of everything, with the largest clearance near the centre
    assert world.clearance(poses[0][None, :2])[0] >= 0.77
    # a coarser pixel size scales the map
    env = gym.make("DualLidar-v0", world=room(), config={"map_resolution": 0.1})
    env.reset(seed=0)
    np.testing.assert_allclose(env.unwrapped.world.bounds, (0, 0, 32, 20))


def test_reset_option_world_and_scenes_cached_per_world_object(tmp_path):
    env = gym.make("DualLidar-v0")
    world = World.from_image(room(), 0.05)
    env.reset(seed=0, options={"world": world, "trace": "zigzag"})
    first = env.unwrapped.trace
    assert env.unwrapped.world is world and first.seed == "zigzag"
    env.reset(seed=1, options={"world": world, "trace": "zigzag"})
    assert env.unwrapped.trace is first  # cached, not fitted again
    env.reset(seed=0)
    assert env.unwrapped.world.name == "open_cylinders"  # the env's own world again
    env.reset(seed=0, options={"world": ros_room(tmp_path)})
    assert env.unwrapped.world.name == "room"


@pytest.mark.parametrize("trace", ["straight", "right_turn", "zigzag", "loop", "out_and_back"])
def test_every_trace_seed_fits_a_user_world_or_says_where_it_is_tight(trace):
    big = np.zeros((400, 600), dtype=np.uint8)
    big[:3] = big[-3:] = 1
    big[:, :3] = big[:, -3:] = 1
    env = gym.make("DualLidar-v0", world=big, trace=trace)
    _, info = env.reset(seed=0)
    world = env.unwrapped.world
    waypoints = env.unwrapped.trace.waypoints
    assert np.all(world.clearance(waypoints) >= env.unwrapped.config.trace_clearance - 1e-9)
    assert info["progress"] == pytest.approx(0.0, abs=0.05)


def test_bad_worlds_and_starts_raise_readable_errors(tmp_path):
    with pytest.raises(ConfigError, match="no such image file"):
        gym.make("DualLidar-v0", world=str(tmp_path / "none.png"))
    with pytest.raises(ValueError, match="unknown world"):
        gym.make("DualLidar-v0", world="no_such_world")
    with pytest.raises(ConfigError, match="expected one of .*a World, a 2-D array"):
        gym.make("DualLidar-v0", world=3.0)
    env = gym.make("DualLidar-v0", world=room())
    with pytest.raises(StartPoseError, match="outside the map"):
        env.reset(options={"start": (20.0, 5.0, 0.0)})
    with pytest.raises(StartPoseError, match="into an obstacle"):
        env.reset(options={"start": (6.0, 5.0, 0.0)})
    _, info = env.reset(options={"start": (3.0, 8.0, 0.0)})
    np.testing.assert_allclose(info["pose"], (3.0, 8.0, 0.0))


def test_a_start_outside_a_built_in_world_is_named():
    env = gym.make("DualLidar-v0", world="hallway")
    with pytest.raises(StartPoseError, match=r"start pose \(90, 0, 0\) is outside the map "
                                             r"'hallway'"):
        env.reset(options={"start": (90.0, 0.0, 0.0)})
