"""Stable-Baselines3 on the batched env: the adapter gives what ``DummyVecEnv`` over single
envs gives (observations, float32 rewards, dones, terminal observations), the learned
driver's view of it matches its wrapper on single envs, and PPO trains on both."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3", reason="the agents extra is not installed")

from stable_baselines3 import PPO  # noqa: E402
from stable_baselines3.common.vec_env import DummyVecEnv  # noqa: E402

import lidar_env  # noqa: E402, F401 - registers DualLidar-v0
from agents.observation import TraceFollowingObservation  # noqa: E402
from agents.vec_adapter import SB3VecEnv, TraceFollowingVecEnv  # noqa: E402
from lidar_env.core.errors import ConfigError  # noqa: E402

SHORT = {"max_episode_time": 4.0}


def batched(num_envs: int, **kwargs: Any) -> gym.vector.VectorEnv:
    return gym.make_vec("DualLidar-v0", num_envs, vectorization_mode="vector_entry_point",
                        **kwargs)


def assert_same_observation(got: Any, expected: Any, what: str) -> None:
    if isinstance(expected, dict):
        assert set(got) == set(expected), what
        for key in expected:
            np.testing.assert_array_equal(got[key], expected[key], err_msg=f"{what}: {key}")
    else:
        assert got.dtype == expected.dtype, what
        np.testing.assert_array_equal(got, expected, err_msg=what)


def compare(adapter: Any, reference: DummyVecEnv, steps: int, seed: int) -> int:
    """Step both with the same random actions; return the number of episode ends seen."""
    adapter.seed(seed)
    reference.seed(seed)
    assert_same_observation(adapter.reset(), reference.reset(), "reset")
    rng, steer, ends = np.random.default_rng(seed), np.zeros(adapter.num_envs), 0
    for t in range(steps):
        steer = np.clip(steer + rng.normal(0.0, 0.4, steer.shape), -1.0, 1.0)
        actions = np.stack([rng.uniform(0.5, 1.0, steer.shape), steer], 1).astype(np.float32)
        adapter.step_async(actions)
        reference.step_async(actions)
        (obs, rewards, dones, infos), expected = adapter.step_wait(), reference.step_wait()
        assert_same_observation(obs, expected[0], f"step {t}")
        assert rewards.dtype == expected[1].dtype == np.float32
        np.testing.assert_array_equal(rewards, expected[1], err_msg=f"step {t} rewards")
        np.testing.assert_array_equal(dones, expected[2], err_msg=f"step {t} dones")
        for i in np.flatnonzero(dones):
            assert_same_observation(infos[i]["terminal_observation"],
                                    expected[3][i]["terminal_observation"], f"step {t} final")
        for i in range(adapter.num_envs):
            assert infos[i]["TimeLimit.truncated"] == expected[3][i]["TimeLimit.truncated"]
            np.testing.assert_array_equal(infos[i]["pose"], expected[3][i]["pose"])
        ends += int(dones.sum())
    return ends


def test_the_adapter_matches_dummy_vec_env_over_single_envs() -> None:
    adapter = SB3VecEnv(batched(3, world="hallway", config=SHORT))
    reference = DummyVecEnv([lambda: gym.make("DualLidar-v0", world="hallway", config=SHORT)] * 3)
    assert adapter.observation_space == reference.observation_space
    assert compare(adapter, reference, 120, seed=4) >= 3


def test_the_drivers_view_matches_its_wrapper_on_single_envs() -> None:
    kwargs = {"randomize": True, "cross_track_weight": 10.0}

    def single() -> gym.Env:
        return TraceFollowingObservation(gym.make("DualLidar-v0", config=SHORT), **kwargs)

    adapter = TraceFollowingVecEnv(batched(3, config=SHORT), **kwargs)
    reference = DummyVecEnv([single] * 3)
    assert adapter.observation_space == reference.observation_space
    assert compare(adapter, reference, 150, seed=9) >= 4  # randomised worlds and traces redrawn


def test_ppo_learns_on_the_batched_env() -> None:
    for env, policy in ((SB3VecEnv(batched(4, config=SHORT)), "MultiInputPolicy"),
                        (TraceFollowingVecEnv(batched(4, config=SHORT), randomize=True),
                         "MlpPolicy")):
        model = PPO(policy, env, n_steps=64, batch_size=64, n_epochs=1, seed=0, device="cpu")
        model.learn(total_timesteps=300)
        assert model.num_timesteps >= 300
        action, _ = model.predict(env.reset(), deterministic=True)
        assert action.shape == (4, 2)


def test_a_vector_env_without_next_step_autoreset_is_refused() -> None:
    venv = gym.make_vec("DualLidar-v0", 2, vectorization_mode="sync",
                        vector_kwargs={"autoreset_mode": gym.vector.AutoresetMode.SAME_STEP})
    with pytest.raises(ConfigError, match="autoreset_mode"):
        SB3VecEnv(venv)


def test_training_steps_batched_unless_asked_for_single_envs() -> None:
    from stable_baselines3.common.vec_env import VecMonitor

    from agents.train import make_training_vec_env

    auto = make_training_vec_env(2, 0, dict(SHORT), {}, "auto")
    assert isinstance(auto, VecMonitor) and isinstance(auto.venv, TraceFollowingVecEnv)
    single = make_training_vec_env(2, 0, dict(SHORT), {}, "single")
    assert isinstance(single, DummyVecEnv)
    movers = make_training_vec_env(2, 0, {**SHORT, "moving_obstacles": 1}, {}, "auto")
    assert isinstance(movers, VecMonitor) and isinstance(movers.venv, TraceFollowingVecEnv)
    with pytest.raises(ConfigError, match="vectorization"):
        make_training_vec_env(2, 0, dict(SHORT), {}, "threads")
