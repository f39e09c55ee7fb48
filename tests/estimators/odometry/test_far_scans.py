"""Scans far apart: ``lidar_odometry`` on a simulated drive thinned to 1 Hz stays within
0.2 m per step; an ordinary 10 Hz drive never needs the far-apart search; a scan with no
overlap, or no returns, is flagged rather than passed off as a pose; the search windows."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import lidar_env  # noqa: F401  (registers DualLidar-v0)
from agents.scripted import PurePursuitDriver
from estimators import SensorSetup
from estimators.odometry.far_scans import SearchWindow, far_apart, reach_window
from estimators.odometry.local_map import LocalMapOdometry
from lidar_env import lidars_with_noise
from lidar_env.core.se2 import relative


def drive(world: str, trace: str, seed: int, speed: float, steps: int):
    """Scans, times and true poses of a pure-pursuit drive at 10 Hz (1 cm noise)."""
    env = gym.make("DualLidar-v0", world=world, trace=trace,
                   config={"scan_frame": "sensor",
                           "lidars": lidars_with_noise(range_noise_std=0.01)})
    driver = PurePursuitDriver(speed=speed)
    observation, info = env.reset(seed=seed)
    driver.reset(env)
    observations, times, truth = [observation], [info["time"]], [info["pose"]]
    for _ in range(steps):
        observation, _, terminated, truncated, info = env.step(driver.act(observation, info))
        observations.append(observation)
        times.append(info["time"])
        truth.append(info["pose"])
        if terminated or truncated:
            break
    setup = SensorSetup.from_env(env)
    env.close()
    return setup, observations, np.array(times), np.array(truth)


def step_errors(estimated: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Translation error [m] of each step's relative pose."""
    return np.array([
        np.hypot(*(relative(estimated[k], estimated[k + 1])[:2]
                   - relative(truth[k], truth[k + 1])[:2]))
        for k in range(len(truth) - 1)
    ])


def run(setup, observations, times, start) -> LocalMapOdometry:
    estimator = LocalMapOdometry()
    estimator.reset(setup, start)
    for observation, t in zip(observations, times, strict=True):
        estimator.update(observation, float(t))
    return estimator


def test_a_drive_thinned_to_1_hz_stays_within_0_2_m_per_step() -> None:
    setup, observations, times, truth = drive("closed_to_open", "zigzag", 0, 1.5, 200)
    keep = slice(0, None, 10)  # 1 Hz: steps of ~1.5 m, turns of up to ~50 deg
    estimator = run(setup, observations[keep], times[keep], truth[0])
    steps = np.diff(truth[keep][:, :2], axis=0)
    turns = np.abs(np.diff(np.unwrap(truth[keep][:, 2])))
    assert np.max(np.hypot(*steps.T)) > 1.4 and np.max(turns) > np.radians(40)
    errors = step_errors(estimator.trajectory, truth[keep])
    assert np.max(errors) < 0.2
    assert estimator.far_searches >= len(errors) - 1 and not estimator.poor_matches
    # the same drive, without the far-apart search (windows too small to reach), loses it
    blind = LocalMapOdometry(max_speed=0.1)
    blind.reset(setup, truth[0])
    for observation, t in zip(observations[keep], times[keep], strict=True):
        blind.update(observation, float(t))
    assert np.max(step_errors(blind.trajectory, truth[keep])) > 0.2


def test_an_ordinary_10_hz_drive_never_searches_far() -> None:
    setup, observations, times, truth = drive("open_cylinders", "right_turn", 0, 1.0, 60)
    estimator = run(setup, observations, times, truth[0])
    assert estimator.far_searches == 0 and estimator.fallbacks == 0
    assert not estimator.poor_matches
    assert np.max(step_errors(estimator.trajectory, truth)) < 0.02


def test_a_scan_with_no_overlap_or_no_returns_is_flagged() -> None:
    setup, observations, times, truth = drive("open_cylinders", "right_turn", 0, 1.0, 3)
    _, elsewhere, _, _ = drive("hallway", "zigzag", 1, 1.0, 0)  # another world entirely
    blank = {key: np.full_like(observations[0][key], setup.sensors[k].max_range)
             for k, key in enumerate(setup.keys)}
    estimator = LocalMapOdometry()
    estimator.reset(setup, truth[0])
    for observation, t in zip([*observations[:3], elsewhere[0], blank], np.arange(5) * 0.1,
                              strict=True):
        pose = estimator.update(observation, float(t))
        assert np.all(np.isfinite(pose))
    assert estimator.poor_matches == [3]
    assert estimator.health.skipped == [4]  # no returns: skipped before matching, counted


def test_the_search_window_covers_the_reach_of_the_car() -> None:
    assert reach_window(1.5, 1.5, 1.0, 1.0) == SearchWindow(1.5, 1.5)
    # a glitching stamp (0.01 s after a 1 s clock) must not shrink the window
    assert reach_window(1.5, 1.5, 0.01, 1.0) == SearchWindow(1.5, 1.5)
    assert reach_window(1.5, 1.5, float("nan"), 0.5).linear == pytest.approx(0.75)
    assert reach_window(1.5, 1.5, 4.0, 1.0).angular == pytest.approx(np.pi)
    assert far_apart(np.array([0.3, 0.0, 0.0]), 0.25, np.radians(30))
    assert far_apart(np.array([0.0, 0.0, np.radians(-32)]), 0.25, np.radians(30))
    assert not far_apart(np.array([0.15, 0.02, np.radians(20)]), 0.25, np.radians(30))


def test_speed_limits_must_be_positive() -> None:
    with pytest.raises(ValueError, match="max_speed: expected a positive value"):
        LocalMapOdometry(max_speed=0.0)
    with pytest.raises(ValueError, match="max_turn_rate: expected a positive value"):
        LocalMapOdometry(max_turn_rate=-1.0)
