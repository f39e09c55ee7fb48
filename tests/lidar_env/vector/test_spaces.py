"""The batched env's spaces, metadata, shapes and dtypes, checked the way Gymnasium's vector
API specifies them."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

import lidar_env  # noqa: F401 - registers DualLidar-v0
from lidar_env.vector import DualLidarVectorEnv

LIDARS = {"lidars": [{"mount": (0.2, 0.0, 0.0), "n_beams": 90},
                     {"mount": (-0.2, 0.0, 3.14), "n_beams": 40, "max_range": 5.0}]}


def test_make_vec_returns_the_batched_env_with_batched_spaces() -> None:
    env = gym.make_vec("DualLidar-v0", num_envs=4, vectorization_mode="vector_entry_point",
                       config=LIDARS)
    single = gym.make("DualLidar-v0", config=LIDARS)
    assert isinstance(env, VectorEnv) and isinstance(env.unwrapped, DualLidarVectorEnv)
    assert env.num_envs == 4
    assert env.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    assert env.single_observation_space == single.observation_space
    assert env.single_action_space == single.action_space
    assert env.observation_space == batch_space(single.observation_space, 4)
    assert env.action_space == batch_space(single.action_space, 4)
    assert env.observation_space["lidar_1"].shape == (4, 90)
    assert env.observation_space["lidar_2"].shape == (4, 40)
    assert env.action_space.shape == (4, 2) and env.action_space.dtype == np.float32


def test_reset_and_step_return_batched_arrays_in_their_spaces() -> None:
    env = gym.make_vec("DualLidar-v0", num_envs=3, vectorization_mode="vector_entry_point",
                       config=LIDARS)
    observation, info = env.reset(seed=0)
    assert env.observation_space.contains(observation)
    assert info["pose"].shape == (3, 3) and info["lidar_poses"].shape == (3, 2, 3)
    assert info["_pose"].dtype == np.bool_ and info["_pose"].all()
    env.action_space.seed(0)
    observation, reward, terminated, truncated, info = env.step(env.action_space.sample())
    assert env.observation_space.contains(observation)
    for key, space in env.observation_space.items():
        assert observation[key].dtype == np.float32 and observation[key].shape == space.shape
    assert reward.shape == (3,) and reward.dtype == np.float64
    assert terminated.shape == truncated.shape == (3,)
    assert terminated.dtype == truncated.dtype == np.bool_
    assert info["time"].dtype == np.float64 and np.allclose(info["time"], 0.1)
    assert info["collision"].dtype == np.bool_


def test_returned_arrays_are_copies() -> None:
    env = gym.make_vec("DualLidar-v0", num_envs=2, vectorization_mode="vector_entry_point")
    observation, info = env.reset(seed=0)
    first = observation["lidar_1"].copy()
    observation["lidar_1"][:] = -1.0
    info["pose"][:] = 99.0
    again, info_again = env.step(np.zeros((2, 2), np.float32))[0::4]
    assert np.all(again["lidar_1"] >= 0.0) and not np.any(info_again["pose"] == 99.0)
    assert first.min() >= 0.0
