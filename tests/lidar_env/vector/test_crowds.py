"""The batched env with moving obstacles is bit-identical to N single ``DualLidar-v0`` envs in
a ``SyncVectorEnv``: same observations, rewards, terminations, truncations and infos (the
movers' ``(M, 5)`` states included), through collisions with movers and walls, time limits
and the autoresets after them, for both mover models."""

from __future__ import annotations

import pickle
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

from lidar_env import lidars_with_noise  # importing lidar_env registers DualLidar-v0
from lidar_env.core.errors import ConfigError
from lidar_env.vehicle.car import box_touches_obstacles
from lidar_env.world.world import World
from tests.lidar_env.vector.test_identity import (
    assert_same,
    pair,
    step_alike,
    wall_seeking_actions,
)

#: Short episodes, so 220 steps hold time-limit ends besides the collisions.
SHORT = {"max_episode_time": 6.0}
#: [m] a 16 m square with nothing in it: the car's collisions there are with movers.
OPEN_ROOM = World(np.empty((0, 3)), np.empty((0, 4)), bounds=(0.0, 0.0, 16.0, 16.0))
#: [m] added to the car's half sizes when telling a mover collision from a wall's: the car
#: stops at its last free substep, at most a few cm from what it touched.
NEAR = 0.15

CASES = {
    "yielding, two lidars": {"world": "open_cylinders",
                             "config": {**SHORT, "moving_obstacles": 30}},
    "waypoints, one lidar, random world": {
        "world": "random",
        "config": {**SHORT, "moving_obstacles": 12, "mover_model": "waypoints",
                   "lidars": [{"mount": (0.2, 0.0, 0.0), "n_beams": 90}]}},
    "yielding, noisy dropping lidars, open room": {
        "world": OPEN_ROOM, "trace": np.array([[2.0, 8.0], [14.0, 8.0]]),
        "config": {**SHORT, "moving_obstacles": 25, "mover_speed_range": (1.0, 2.5),
                   "lidars": lidars_with_noise(range_noise_std=0.02, dropout_prob=0.05)}},
    "waypoints, hallway zigzag": {"world": "hallway", "trace": "zigzag",
                                  "config": {**SHORT, "moving_obstacles": 10,
                                             "mover_model": "waypoints"}},
}


def touched_a_mover(pose: np.ndarray, movers: np.ndarray, world: Any, car: Any) -> bool:
    """The car at ``pose`` is near a mover (rows x, y, vx, vy, r) and far from every wall."""
    hl, hw = car.half_length + NEAR, car.half_width + NEAR
    near_mover = box_touches_obstacles(*pose, hl, hw, movers[:, [0, 1, 4]].copy(),
                                       np.empty((0, 4)))
    near_static = box_touches_obstacles(*pose, hl, hw, world.circles, world.segments)
    return bool(near_mover and not near_static)


def compare(num_envs: int, steps: int, seed: int, **kwargs: Any) -> dict[str, int]:
    """Step both with wall-seeking actions; the counts of each kind of episode end."""
    batched, reference = pair(num_envs, **kwargs)
    got, expected = batched.reset(seed=seed), reference.reset(seed=seed)
    assert_same(got[0], expected[0], "reset observation")
    assert_same(got[1], expected[1], "reset info")
    m = batched.unwrapped.config.moving_obstacles
    assert got[1]["moving_obstacles"].shape == (num_envs, m, 5)
    rng, steer = np.random.default_rng(seed), np.zeros(num_envs)
    counts = {"mover collisions": 0, "collisions": 0, "truncations": 0, "autoresets": 0}
    for t in range(steps):
        actions = wall_seeking_actions(rng, steer)
        got = step_alike(batched, reference, actions, t)
        info = got[4]
        for i in np.flatnonzero(info["collision"]):
            counts["mover collisions"] += touched_a_mover(
                info["pose"][i], info["moving_obstacles"][i], batched.unwrapped.worlds[i],
                batched.unwrapped._car)
        counts["collisions"] += int(info["collision"].sum())
        counts["truncations"] += int(got[3].sum())
        counts["autoresets"] += int((info["time"] == 0.0).sum())
    return counts


@pytest.mark.parametrize("case", list(CASES))
def test_batched_movers_are_bit_identical_to_single_envs(case: str) -> None:
    counts = compare(3, 220, 11, **CASES[case])
    assert counts["mover collisions"] >= 1 and counts["collisions"] >= 2, counts
    assert counts["truncations"] >= 1 and counts["autoresets"] >= 4, counts


def test_the_same_seed_gives_the_same_crowds() -> None:
    config = {**SHORT, "moving_obstacles": 5, "mover_model": "waypoints"}
    runs = []
    for _ in range(2):
        env = gym.make_vec("DualLidar-v0", 2, vectorization_mode="vector_entry_point",
                           world="random", config=config)
        _, info = env.reset(seed=4)
        states = [info["moving_obstacles"]]
        for _ in range(30):
            states.append(env.step(np.full((2, 2), 0.3, np.float32))[4]["moving_obstacles"])
        runs.append(np.stack(states))
    np.testing.assert_array_equal(runs[0], runs[1])
    assert not np.array_equal(runs[0][0, 0], runs[0][0, 1])  # each sub-env its own crowd


def test_a_world_too_crowded_is_the_single_envs_error() -> None:
    config = {"moving_obstacles": 200, "mover_radius": 1.0}
    with pytest.raises(ConfigError, match="too crowded") as single_error:
        gym.make("DualLidar-v0", world="hallway", config=config).reset(seed=0)
    env = gym.make_vec("DualLidar-v0", 2, vectorization_mode="vector_entry_point",
                       world="hallway", config=config)
    with pytest.raises(ConfigError, match="too crowded") as batched_error:
        env.reset(seed=0)
    assert str(batched_error.value) == str(single_error.value)


def test_a_move_too_long_to_check_among_movers_is_the_single_cars_error() -> None:
    config = {"max_speed": 1e6, "moving_obstacles": 3}  # the checks count the movers too
    env = gym.make_vec("DualLidar-v0", 2, vectorization_mode="vector_entry_point",
                       config=config)
    env.reset(seed=0)
    with pytest.raises(ConfigError, match="car motion") as batched_error:
        env.step(np.array([[0.0, 0.0], [1.0, 0.0]]))
    single = gym.make("DualLidar-v0", config=config)
    single.reset(seed=1)  # sub-env 1's seed: its crowd, so its fastest mover
    with pytest.raises(ConfigError, match="car motion") as single_error:
        single.step(np.array([1.0, 0.0]))
    assert str(batched_error.value) == str(single_error.value)


def test_a_pickled_batched_env_steps_on_like_the_original() -> None:
    env = gym.make_vec("DualLidar-v0", 3, vectorization_mode="vector_entry_point",
                       world="random", config={"moving_obstacles": 4, "max_episode_time": 3.0})
    env.reset(seed=0)
    actions = np.tile(np.array([1.0, 0.2], np.float32), (3, 1))
    for _ in range(7):
        env.step(actions)
    copy = pickle.loads(pickle.dumps(env))
    for t in range(60):  # through time limits and autoresets (new random worlds, new crowds)
        got, expected = copy.step(actions), env.step(actions)
        assert_same(got[0], expected[0], f"step {t} observation")
        assert_same(got[4], expected[4], f"step {t} info")
        np.testing.assert_array_equal(got[1], expected[1])
    assert copy.unwrapped.worlds[0] is not env.unwrapped.worlds[0]
