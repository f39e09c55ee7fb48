"""Imitation (DAgger) of the scan-aware expert: a short run saves a model the sb3 driver loads,
the same seed gives the same model, and an existing model is never replaced by accident."""

import json

import gymnasium as gym
import numpy as np
import pytest

import lidar_env  # noqa: F401 - registers DualLidar-v0
from agents.evaluate import drive_episode
from lidar_env.core.errors import ConfigError

pytest.importorskip("stable_baselines3", reason="the agents extra is not installed")

from agents.imitate import imitate  # noqa: E402
from agents.sb3_driver import SB3Driver  # noqa: E402
from agents.train import TrainingExistsError  # noqa: E402


def _weights(path):
    from stable_baselines3 import PPO

    policy = PPO.load(path, device="cpu").policy
    return [p.detach().numpy().copy() for p in policy.parameters()]


def test_a_short_run_is_reproducible_and_drives_as_the_sb3_driver(tmp_path):
    first = imitate(seed=3, out=tmp_path / "a.zip", iterations=2, steps=400, epochs=1)
    second = imitate(seed=3, out=tmp_path / "b.zip", iterations=2, steps=400, epochs=1)
    other = imitate(seed=4, out=tmp_path / "c.zip", iterations=2, steps=400, epochs=1)
    for a, b in zip(_weights(first), _weights(second), strict=True):
        np.testing.assert_array_equal(a, b)
    assert any(not np.array_equal(a, c)
               for a, c in zip(_weights(first), _weights(other), strict=True))
    record = json.loads(first.with_suffix(".json").read_text())
    assert [it["actor"] for it in record["iterations"]] == ["expert", "student"]
    assert record["iterations"][0]["steps"] == 400 and record["wall_seconds"] > 0
    env = gym.make("DualLidar-v0", world="hallway", trace="straight",
                   config={"max_episode_time": 2.0})
    episode = drive_episode(env, SB3Driver(first), seed=0)
    assert episode.time == pytest.approx(2.0) or episode.collided or episode.success


def test_an_existing_model_is_refused_before_any_work(tmp_path):
    out = tmp_path / "model.zip"
    out.write_bytes(b"keep me")
    with pytest.raises(TrainingExistsError, match="--overwrite"):
        imitate(out=out, iterations=1, steps=10)
    assert out.read_bytes() == b"keep me"
    with pytest.raises(ConfigError, match="expert: expected one of backing, braking"):
        imitate(out=tmp_path / "new.zip", iterations=1, steps=10, expert="timid")
