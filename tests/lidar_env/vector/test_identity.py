"""The batched env is bit-identical to N single ``DualLidar-v0`` envs in a ``SyncVectorEnv``:
same observations, rewards, terminations, truncations and infos, step by step, through
collisions, goal and time-limit ends and the autoresets after them."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest

from lidar_env import lidars_with_noise  # importing lidar_env registers DualLidar-v0

#: Short episodes, so 220 steps hold several time-limit ends besides the collisions.
SHORT = {"max_episode_time": 6.0}

THREE_LIDARS = {
    **SHORT, "scan_frame": "world",
    "lidars": lidars_with_noise({"lidars": [
        {"mount": (0.3, 0.0, 0.0)},
        {"mount": (-0.3, 0.1, 1.0), "n_beams": 100, "range_noise_std": 0.0},
        {"mount": (0.0, -0.2, 3.0), "max_range": 4.0, "fov": 4.0, "n_beams": 61}]},
        dropout_prob=0.05),
}

CASES = {
    "hallway": {"world": "hallway", "config": SHORT},
    "random world": {"world": "random", "config": SHORT},
    "one lidar": {"world": "open_cylinders", "trace": "zigzag",
                  "config": {**SHORT, "lidars": [{"mount": (0.2, 0.0, 0.0), "n_beams": 90}]}},
    "three lidars": {"world": "closed_to_open", "trace": "loop", "config": THREE_LIDARS},
}


def assert_same(batched: dict[str, Any], reference: dict[str, Any], what: str) -> None:
    assert set(batched) == set(reference), what
    for key, expected in reference.items():
        got, expected = np.asarray(batched[key]), np.asarray(expected)
        assert got.dtype == expected.dtype, f"{what}: {key} dtype"
        np.testing.assert_array_equal(got, expected, err_msg=f"{what}: {key}")


def pair(num_envs: int, **kwargs: Any) -> tuple[gym.vector.VectorEnv, gym.vector.VectorEnv]:
    batched = gym.make_vec("DualLidar-v0", num_envs, vectorization_mode="vector_entry_point",
                           **kwargs)
    reference = gym.make_vec("DualLidar-v0", num_envs, vectorization_mode="sync", **kwargs)
    return batched, reference


def wall_seeking_actions(rng: np.random.Generator, steer: np.ndarray) -> np.ndarray:
    """Full speed ahead (beyond 1 at times: clipped alike by both) on a wandering steer
    (``steer`` (N,), updated in place): the cars leave the trace and hit walls."""
    steer[:] = np.clip(steer + rng.normal(0.0, 0.35, steer.shape), -1.0, 1.0)
    speed = rng.uniform(0.8, 1.3, steer.shape)
    return np.stack([speed, steer], axis=1).astype(np.float32)


def step_alike(batched: gym.vector.VectorEnv, reference: gym.vector.VectorEnv,
               actions: np.ndarray, t: int) -> tuple[Any, ...]:
    """Step both with ``actions``; every output the same, dtypes too; the batched outputs."""
    got, expected = batched.step(actions), reference.step(actions)
    assert_same(got[0], expected[0], f"step {t} observation")
    for name, index in (("reward", 1), ("terminated", 2), ("truncated", 3)):
        assert got[index].dtype == expected[index].dtype, f"step {t} {name} dtype"
        np.testing.assert_array_equal(got[index], expected[index], f"step {t} {name}")
    assert_same(got[4], expected[4], f"step {t} info")
    return got


@pytest.mark.parametrize("case", list(CASES))
def test_batched_steps_are_bit_identical_to_single_envs(case: str) -> None:
    num_envs, steps = 3, 220
    batched, reference = pair(num_envs, **CASES[case])
    assert batched.metadata["autoreset_mode"] == reference.metadata["autoreset_mode"]
    observation, info = batched.reset(seed=11)
    expected_observation, expected_info = reference.reset(seed=11)
    assert_same(observation, expected_observation, "reset observation")
    assert_same(info, expected_info, "reset info")
    rng, steer = np.random.default_rng(5), np.zeros(num_envs)
    collisions = truncations = autoresets = 0
    for t in range(steps):
        actions = wall_seeking_actions(rng, steer)
        got = step_alike(batched, reference, actions, t)
        collisions += int(got[4]["collision"].sum())
        truncations += int(got[3].sum())
        autoresets += int((got[4]["time"] == 0.0).sum())
    # the comparison went through every kind of episode end and the autoreset after it
    assert collisions >= 5 and truncations >= 1 and autoresets >= 6, (collisions, truncations,
                                                                      autoresets)


def test_reseeding_and_reset_options_match_single_envs() -> None:
    batched, reference = pair(2, world="open_cylinders")
    for seed, options in ((3, None), ([7, None], {"trace": "zigzag"}),
                          (None, {"world": "random", "trace": "straight"})):
        got, expected = batched.reset(seed=seed, options=options), reference.reset(
            seed=seed, options=options)
        assert_same(got[0], expected[0], f"reset {seed} {options} observation")
        assert_same(got[1], expected[1], f"reset {seed} {options} info")
        actions = np.array([[1.0, 0.3], [0.5, -0.4]], np.float32)
        for _ in range(5):
            got, expected = batched.step(actions), reference.step(actions)
            assert_same(got[0], expected[0], "observation after reset")
            np.testing.assert_array_equal(got[1], expected[1])


@pytest.mark.parametrize("config", [{}, {"moving_obstacles": 4}], ids=["static", "movers"])
def test_a_masked_reset_resets_only_those_envs_like_sync(config: dict[str, int]) -> None:
    batched, reference = pair(3, world="hallway", config=config)
    batched.reset(seed=1)
    reference.reset(seed=1)
    actions = np.full((3, 2), 0.5, np.float32)
    for _ in range(4):
        batched.step(actions)
        reference.step(actions)
    mask = np.array([False, True, False])
    got = batched.reset(options={"reset_mask": mask.copy()})
    expected = reference.reset(options={"reset_mask": mask.copy()})
    assert_same(got[0], expected[0], "masked reset observation")
    assert_same(got[1], expected[1], "masked reset info")
    assert got[1]["time"][1] == 0.0 and got[1]["_time"].tolist() == [False, True, False]
    if config:  # only that sub-env's crowd respawns
        assert got[1]["_moving_obstacles"].tolist() == [False, True, False]
    for _ in range(5):
        got, expected = batched.step(actions), reference.step(actions)
        assert_same(got[0], expected[0], "observation after the masked reset")
        assert_same(got[4], expected[4], "info after the masked reset")


def test_reaching_the_goal_ends_and_autoresets_alike() -> None:
    batched, reference = pair(2, world="open_cylinders", trace="straight")
    batched.reset(seed=2)
    reference.reset(seed=2)
    actions = np.array([[1.0, 0.0], [1.0, 0.0]], np.float32)
    goals = 0
    for t in range(240):
        got, expected = batched.step(actions), reference.step(actions)
        assert_same(got[0], expected[0], f"step {t} observation")
        assert_same(got[4], expected[4], f"step {t} info")
        np.testing.assert_array_equal(got[1], expected[1])
        np.testing.assert_array_equal(got[2], expected[2])
        goals += int((got[2] & ~got[4]["collision"]).sum())
    assert goals >= 2


def test_a_user_world_and_a_waypoint_route_match_single_envs() -> None:
    grid = np.zeros((160, 400))  # 20 m x 8 m at 0.05 m per pixel: a walled room and a block
    grid[:4] = grid[-4:] = grid[:, :4] = grid[:, -4:] = 1
    grid[60:100, 250:270] = 1
    route = np.array([[2.0, 0.0], [8.0, 0.0], [12.0, 1.0]])
    for kwargs in ({"world": grid, "config": SHORT},
                   {"world": "hallway", "trace": route, "config": SHORT}):
        batched, reference = pair(2, **kwargs)
        got, expected = batched.reset(seed=3), reference.reset(seed=3)
        assert_same(got[0], expected[0], "reset observation")
        rng, steer, collisions = np.random.default_rng(1), np.zeros(2), 0
        for t in range(120):
            actions = wall_seeking_actions(rng, steer)
            got, expected = batched.step(actions), reference.step(actions)
            assert_same(got[0], expected[0], f"step {t} observation")
            assert_same(got[4], expected[4], f"step {t} info")
            np.testing.assert_array_equal(got[1], expected[1])
            collisions += int(got[4]["collision"].sum())
        assert collisions >= 1
