"""The learned driver's observation: sector deltas (how it sees movers) and the shaped reward."""

import gymnasium as gym
import numpy as np
import pytest

import lidar_env  # noqa: F401
from agents.observation import TraceFollowingObservation
from lidar_env import lidars_with_noise

NOISELESS = {"lidars": lidars_with_noise(range_noise_std=0.0)}
MOVERS = {"moving_obstacles": 10, **NOISELESS}


def wrapped(config: dict | None = None, world: str = "open_cylinders",
            **kwargs) -> TraceFollowingObservation:
    env = gym.make("DualLidar-v0", world=world, trace="straight", config=config or {})
    return TraceFollowingObservation(env, **kwargs)


def pooled(env: TraceFollowingObservation, observation: dict) -> np.ndarray:
    """The sector minima [m] of both Lidars, computed here independently of the wrapper."""
    return np.concatenate([np.min(observation[key].reshape(36, 10), axis=1)
                           for key in ("lidar_1", "lidar_2")])


def test_deltas_are_the_sector_change_since_the_previous_frame() -> None:
    view = wrapped(MOVERS, sector_deltas=True, delta_scale=0.3)
    assert view.observation_space.shape == (158,)
    raw, info = view.env.reset(seed=3)
    first = view.observe(raw, info)
    np.testing.assert_array_equal(first[86:], 0.0)  # nothing to compare the first frame with
    plain = TraceFollowingObservation(view.env).observe(raw, info)
    np.testing.assert_array_equal(first[:86], plain)  # the other slices are unchanged
    previous = pooled(view, raw)
    moved = 0
    for _ in range(20):
        raw, _, terminated, truncated, info = view.env.step(np.array([0.5, 0.2], np.float32))
        deltas = view.observe(raw, info)[86:]
        expected = np.clip((pooled(view, raw) - previous) / 0.3, -1.0, 1.0)
        np.testing.assert_allclose(deltas, expected, atol=1e-6)
        moved += int(np.any(np.abs(deltas) > 0.01))
        previous = pooled(view, raw)
        assert not (terminated or truncated)
    assert moved == 20  # the car and the crowd move, so some sector changes at every frame


def test_a_reset_starts_the_deltas_afresh() -> None:
    view = wrapped(MOVERS, sector_deltas=True)
    view.reset(seed=0)
    for _ in range(10):
        observation, *_ = view.step(np.array([1.0, 0.0], np.float32))
    assert np.any(observation[86:] != 0.0)
    observation, _ = view.reset(seed=1)
    np.testing.assert_array_equal(observation[86:], 0.0)
    assert view.observation_space.contains(observation)


def test_a_stationary_car_among_static_obstacles_sees_no_motion() -> None:
    view = wrapped(NOISELESS, sector_deltas=True)
    view.reset(seed=0)
    for _ in range(5):
        observation, *_ = view.step(np.zeros(2, np.float32))
        np.testing.assert_array_equal(observation[86:], 0.0)


def test_collision_penalty_is_added_to_the_envs() -> None:
    plain = wrapped(world="hallway", collision_penalty=0.0)
    harsh = wrapped(world="hallway", collision_penalty=20.0)
    runs = []
    for view in (plain, harsh):
        view.reset(seed=0)
        for _ in range(10):  # turn 1.5 rad on the spot to face the hallway's side wall
            _, reward, *_ = view.step(np.array([0.0, 1.0], np.float32))
        rewards = [reward]
        info = {"collision": False}
        while not info["collision"]:  # then drive into it
            _, reward, terminated, truncated, info = view.step(np.array([1.0, 0.0], np.float32))
            assert not truncated
            rewards.append(reward)
        assert terminated
        runs.append(rewards)
    np.testing.assert_allclose(runs[1][:-1], runs[0][:-1])  # the same until the collision
    assert runs[1][-1] == pytest.approx(runs[0][-1] - 20.0)


def test_bad_delta_settings() -> None:
    with pytest.raises(ValueError, match="delta_scale"):
        wrapped(sector_deltas=True, delta_scale=0.0)
    with pytest.raises(ValueError, match="collision_penalty"):
        wrapped(collision_penalty=-1.0)
