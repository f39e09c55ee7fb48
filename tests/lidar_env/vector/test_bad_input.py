"""Bad input to the batched env raises the errors the single env raises (``ConfigError`` from
:mod:`lidar_env.core.errors`), naming the argument; what it cannot batch is refused, not ignored."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import lidar_env  # noqa: F401 - registers DualLidar-v0
from lidar_env.core.errors import ConfigError, ResetNeededError
from lidar_env.vector import DualLidarVectorEnv
from lidar_env.vector.env import MAX_NUM_ENVS
from tests.lidar_env.vector.test_identity import assert_same, pair


def batched(num_envs: int = 2, **kwargs) -> gym.vector.VectorEnv:
    return gym.make_vec("DualLidar-v0", num_envs, vectorization_mode="vector_entry_point",
                        **kwargs)


@pytest.mark.parametrize("num_envs", [0, -3, 2.5, True, 10**20, MAX_NUM_ENVS + 1, 10**400])
def test_num_envs_below_one_too_large_or_not_an_integer_is_refused(num_envs) -> None:
    with pytest.raises(ConfigError, match=f"num_envs: expected an integer in 1 .. {MAX_NUM_ENVS}"):
        DualLidarVectorEnv(num_envs=num_envs)


def test_step_before_reset_is_ours_and_gymnasiums() -> None:
    env = batched()
    with pytest.raises(ResetNeededError, match=r"call reset\(\) before step\(\)"):
        env.step(np.zeros((2, 2)))
    with pytest.raises(gym.error.ResetNeeded):
        env.step(np.zeros((2, 2)))


@pytest.mark.parametrize("seed", [-1, -(2**70), [0, -1], [0, "1"], [0, 1.5], "7"])
def test_negative_or_non_integer_seeds_are_config_errors(seed) -> None:
    env = batched()
    with pytest.raises(ConfigError, match=r"seed(\[1\])?: expected an (integer >= 0|int)"):
        env.reset(seed=seed)
    env.reset(seed=[3, None])  # None: a fresh seed for that sub-env
    env.reset(seed=np.int64(2**40))


def test_config_errors_are_the_single_envs() -> None:
    with pytest.raises(ConfigError, match="max_speed"):
        batched(config={"max_speed": -1.0})
    with pytest.raises(ConfigError, match="unknown config key"):
        batched(config={"max_sped": 1.0})


def test_what_is_not_batched_yet_is_refused_by_name() -> None:
    with pytest.raises(ConfigError, match="render_mode"):
        DualLidarVectorEnv(2, render_mode="rgb_array")
    corner = {"mount": (0.4, 0.25, 0.785), "fov": 4.71, "n_beams": 90, "self_occlusion": True}
    with pytest.raises(ConfigError, match=r"lidars\[1\].self_occlusion: not batched yet"):
        batched(config={"lidars": [{"mount": (0.0, 0.0, 0.0)}, corner]})


#: (batched action for 2 envs, the same mistake made to one single env)
BAD_ACTIONS = {
    "three numbers per env": (np.zeros((2, 3)), np.zeros(3)),
    "one env's action": (np.zeros(2), np.zeros(1)),
    "one row too many": (np.zeros((3, 2)), np.zeros((2, 2))),
    "strings": ([["a", "b"], ["c", "d"]], ["a", "b"]),
    "NaN": (np.array([[0.1, np.nan], [0.0, 0.0]]), np.array([0.1, np.nan])),
    "inf": (np.array([[0.0, 0.0], [np.inf, 0.0]]), np.array([np.inf, 0.0])),
}


@pytest.mark.parametrize("mistake", list(BAD_ACTIONS))
def test_a_bad_action_is_a_config_error_like_the_single_envs(mistake: str) -> None:
    actions, action = BAD_ACTIONS[mistake]
    env = batched()
    env.reset(seed=0)
    with pytest.raises(ConfigError, match="action"):
        env.step(actions)
    single = gym.make("DualLidar-v0")
    single.reset(seed=0)
    with pytest.raises(ConfigError, match="action"):
        single.step(action)


def test_a_bad_action_moves_no_car() -> None:
    env = batched()
    _, info = env.reset(seed=0)
    with pytest.raises(ConfigError, match=r"actions\[1\]"):
        env.step(np.array([[1.0, 0.0], [np.nan, 0.0]]))
    _, _, _, _, after = env.step(np.zeros((2, 2)))
    np.testing.assert_array_equal(after["pose"], info["pose"])  # zero action: no motion
    assert np.allclose(after["time"], 0.1)


def test_the_ignored_action_of_an_autoresetting_env_may_be_anything() -> None:
    env = batched(world="hallway", config={"max_episode_time": 0.2})
    env.reset(seed=0)
    env.step(np.zeros((2, 2)))
    _, _, _, truncated, _ = env.step(np.zeros((2, 2)))
    assert truncated.all()
    _, reward, _, _, info = env.step(np.full((2, 2), np.nan))  # both autoreset: not used
    assert np.all(reward == 0.0) and np.all(info["time"] == 0.0)


def test_a_bad_action_leaves_an_ended_env_waiting_for_its_reset() -> None:
    env, reference = pair(2, world="hallway", config={"max_episode_time": 0.2})
    zeros, lagging = np.zeros((2, 2)), {"reset_mask": np.array([False, True])}
    for vector_env in (env, reference):  # sub-env 0 ends a step before sub-env 1
        vector_env.reset(seed=0)
        vector_env.step(zeros)
        vector_env.reset(options=lagging)
        _, _, _, truncated, _ = vector_env.step(zeros)
        assert truncated.tolist() == [True, False]
    with pytest.raises(ConfigError, match=r"actions\[1\]"):
        env.step(np.array([[0.0, 0.0], [np.nan, 0.0]]))
    actions = np.array([[0.0, 0.0], [0.5, 0.2]])
    got, expected = env.step(actions), reference.step(actions)  # sub-env 0 resets now
    assert_same(got[0], expected[0], "observation")
    assert_same(got[4], expected[4], "info")
    assert got[4]["time"].tolist() == [0.0, 0.2]
    for index in (1, 2, 3):
        np.testing.assert_array_equal(got[index], expected[index])


def test_step_before_reset_and_bad_reset_arguments() -> None:
    env = batched()
    with pytest.raises(gym.error.ResetNeeded):
        env.step(np.zeros((2, 2)))
    with pytest.raises(ConfigError, match="reset option"):
        env.reset(seed=0, options={"wrold": "hallway"})
    with pytest.raises(ConfigError, match="seed"):
        env.reset(seed=[1, 2, 3])
    env.reset(seed=0, options={"reset_mask": np.array([True, False])})
    with pytest.raises(gym.error.ResetNeeded, match=r"sub-envs \[1\] never were"):
        env.step(np.zeros((2, 2)))
    env.reset(seed=1, options={"reset_mask": np.array([False, True])})
    env.step(np.zeros((2, 2)))  # every sub-env was reset once: it steps
    with pytest.raises(ConfigError, match="reset_mask"):
        env.reset(options={"reset_mask": np.array([1, 0])})


def test_a_move_too_long_to_check_is_the_single_cars_error() -> None:
    config = {"max_speed": 1e6}  # a corner would move 1e5 m per step: 8e5 collision checks
    env = batched(config=config)
    env.reset(seed=0)
    with pytest.raises(ConfigError, match="car motion") as batched_error:
        env.step(np.array([[0.0, 0.0], [1.0, 0.0]]))
    single = gym.make("DualLidar-v0", config=config)
    single.reset(seed=0)
    with pytest.raises(ConfigError, match="car motion") as single_error:
        single.step(np.array([1.0, 0.0]))
    assert str(batched_error.value) == str(single_error.value)
    _, _, _, _, info = env.step(np.zeros((2, 2)))  # nothing moved: the envs step on
    assert np.allclose(info["time"], 0.1)
