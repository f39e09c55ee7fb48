"""Fuzz: env configs, reset options and actions, through the public Gymnasium API only.

Each property: a named project error (a DualLidarError) or a finite result, never another
exception."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

import lidar_env  # noqa: F401  (registers DualLidar-v0)
from tests.fuzz.conftest import named_or_result, scaled

KEYS = ["control_dt", "physics_substeps", "max_speed", "max_yaw_rate", "car_length",
        "car_width", "range_noise_std", "dropout_prob", "max_episode_time", "goal_tolerance",
        "n_beams", "max_range", "scan_frame", "lidar_mounts", "no_such_key"]
values = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-3, 400),
                   st.sampled_from(["world", "sensor", "x", None, True, [], [[0, 0, 0]]]))


def finite_step(env, action) -> None:
    observation, reward, terminated, truncated, info = env.step(action)
    assert np.isfinite(reward)
    assert np.all(np.isfinite(info["pose"]))
    for key, scan in observation.items():
        assert np.all(np.isfinite(scan)), key


def named_or_steps_finitely(config) -> None:
    """``config`` is refused by name, or the env it makes resets and steps finitely."""
    env = named_or_result(lambda: gym.make("DualLidar-v0", world="hallway", config=config))
    if env is None:
        return
    if named_or_result(lambda: env.reset(seed=0)) is None:
        return
    for _ in range(3):
        if named_or_result(lambda: finite_step(env, np.array([1.0, 0.3]))) is None:
            return


@settings(max_examples=scaled(15))
@example(config={"car_length": 3.0})
@given(config=st.dictionaries(st.sampled_from(KEYS), values, max_size=2))
def test_env_configs_are_named_or_step_finitely(config):
    named_or_steps_finitely(config)


@settings(max_examples=scaled(15))
@example(noise={"range_noise_std": 1e300, "dropout_prob": 0.999})
@given(noise=st.dictionaries(st.sampled_from(["range_noise_std", "dropout_prob"]), values,
                             max_size=2))
def test_per_lidar_noise_is_named_or_steps_finitely(noise):
    named_or_steps_finitely({"lidars": [{"mount": (0.25, 0.0, 0.0), **noise},
                                        {"mount": (-0.25, 0.0, 0.0)}]})


actions = st.one_of(
    st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=0, max_size=3),
    st.sampled_from(["forward", None, 1.0]),
    st.lists(st.sampled_from(["a", None]), min_size=2, max_size=2),
)


@pytest.fixture(scope="module")
def env():
    environment = gym.make("DualLidar-v0", world="hallway")
    environment.reset(seed=0)
    return environment


@settings(max_examples=scaled(30))
@example(action=["a", None])
@given(action=actions)
def test_actions_are_named_or_step_finitely(env, action):
    if named_or_result(lambda: finite_step(env, action)) is None:
        return


options = st.dictionaries(
    st.sampled_from(["world", "trace", "start", "bogus"]),
    st.one_of(st.sampled_from(["hallway", "zigzag", "straight", "origin", "moon", None]),
              st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=4)),
    max_size=2,
)


@settings(max_examples=scaled(15))
@example(reset_options={"start": "origin"})
@given(reset_options=options)
def test_reset_options_are_named_or_give_a_finite_start(env, reset_options):
    result = named_or_result(lambda: env.reset(seed=1, options=reset_options))
    if result is not None:
        assert np.all(np.isfinite(result[1]["pose"]))
