"""The scripted pure-pursuit driver finishes every trace seed (a loop: one lap) in every world."""

import gymnasium as gym
import numpy as np
import pytest

import lidar_env  # noqa: F401 - registers DualLidar-v0
from agents import Driver, PurePursuitDriver
from lidar_env.routes.traces import TRACE_NAMES
from lidar_env.world.built_in import WORLD_NAMES

BUILT_IN = [name for name in WORLD_NAMES if name != "random"]


def _drive(env, driver, seed=0, options=None):
    observation, info = env.reset(seed=seed, options=options)
    driver.reset(env)
    worst = 0.0
    while True:
        observation, _, terminated, truncated, info = env.step(driver.act(observation, info))
        worst = max(worst, abs(info["cross_track_error"]))
        if terminated or truncated:
            return info, terminated, worst


@pytest.mark.parametrize("world", BUILT_IN)
@pytest.mark.parametrize("trace", TRACE_NAMES)
def test_every_seed_in_every_built_in_world_is_finished_without_collision(world, trace):
    env = gym.make("DualLidar-v0", world=world, trace=trace)
    info, terminated, worst = _drive(env, PurePursuitDriver())
    assert terminated and not info["collision"]
    unwrapped = env.unwrapped
    assert info["progress"] >= 1.0 - unwrapped.config.goal_tolerance / unwrapped.trace.length
    assert worst < unwrapped.config.trace_margin  # never left the trace's safety margin


@pytest.mark.parametrize(("seed", "trace"), list(enumerate(TRACE_NAMES, start=11)))
def test_random_worlds_are_finished_too(seed, trace):
    env = gym.make("DualLidar-v0", world="random", trace=trace)
    info, terminated, _ = _drive(env, PurePursuitDriver(), seed=seed)
    assert terminated and not info["collision"]


def test_the_driver_keeps_within_the_action_box_and_follows_the_protocol():
    env = gym.make("DualLidar-v0", world="hallway")
    driver = PurePursuitDriver(speed=5.0)  # faster than the car: capped at max_speed
    assert isinstance(driver, Driver)
    observation, info = env.reset(seed=0)
    driver.reset(env)
    for _ in range(50):
        action = driver.act(observation, info)
        assert action.dtype == np.float32 and env.action_space.contains(action)
        observation, *_, info = env.step(action)


def test_driver_errors_are_readable():
    with pytest.raises(ValueError, match="lookahead: expected a positive number, got 0"):
        PurePursuitDriver(lookahead=0)
    with pytest.raises(RuntimeError, match=r"call reset\(env\) before act\(\)"):
        PurePursuitDriver().act({}, {"pose": np.zeros(3)})
    with pytest.raises(TypeError, match="expected a DualLidar-v0 env reset to a trace"):
        PurePursuitDriver().reset(gym.make("CartPole-v1"))
