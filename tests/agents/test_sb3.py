"""The learned driver: its observation wrapper, training loop, shipped model and evaluation."""

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import lidar_env  # noqa: F401
from agents.driver import make_driver
from agents.evaluate import drive_episode
from agents.observation import TraceFollowingObservation
from agents.sb3_driver import SHIPPED_MODEL, SB3Driver

pytest.importorskip("stable_baselines3", reason="the agents extra is not installed")


def wrapped(**kwargs) -> TraceFollowingObservation:
    return TraceFollowingObservation(gym.make("DualLidar-v0", trace="straight"), **kwargs)


def test_wrapped_env_passes_gymnasium_and_sb3_checks() -> None:
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        # The checker notes that a wrapper is applied: checking the wrapper is the point here.
        warnings.filterwarnings("ignore", message=".*different from the unwrapped.*")
        check_env(wrapped(randomize=True), skip_render_check=True)
        sb3_check_env(wrapped(randomize=True), warn=True)


def test_trace_points_are_in_the_car_frame() -> None:
    env = wrapped(n_points=4, point_spacing=0.5, lookahead_scale=3.0)
    observation, info = env.reset(seed=0)
    points = observation[72:80].reshape(4, 2)
    # On a straight trace starting at the car's pose, the points lie straight ahead.
    np.testing.assert_allclose(points[:, 0], np.array([0.5, 1.0, 1.5, 2.0]) / 3.0, atol=1e-3)
    np.testing.assert_allclose(points[:, 1], 0.0, atol=1e-3)
    assert np.all(observation[:72] > 0) and np.all(observation[:72] <= 1)
    np.testing.assert_allclose(observation[80:82], 0.0, atol=1e-3)  # on the line, aligned


def test_randomized_episodes_are_reproducible_from_the_seed() -> None:
    first, second = wrapped(randomize=True), wrapped(randomize=True)
    for seed in (3, 4):
        a, _ = first.reset(seed=seed)
        b, _ = second.reset(seed=seed)
        np.testing.assert_array_equal(a, b)
        assert first.unwrapped.world.name == second.unwrapped.world.name


def test_bad_wrapper_arguments() -> None:
    with pytest.raises(ValueError, match="divisor"):
        wrapped(n_sectors=7)
    with pytest.raises(ValueError, match="positive"):
        wrapped(point_spacing=0.0)
    with pytest.raises(ValueError, match="unknown driver"):
        make_driver("joystick")


def test_short_training_run_saves_and_reloads(tmp_path) -> None:
    from stable_baselines3 import PPO

    env = wrapped(randomize=True)
    model = PPO("MlpPolicy", env, n_steps=64, batch_size=32, n_epochs=1, seed=0, device="cpu")
    model.learn(total_timesteps=128)
    model.save(tmp_path / "model.zip")
    reloaded = PPO.load(tmp_path / "model.zip", device="cpu")
    observation, _ = env.reset(seed=1)
    np.testing.assert_array_equal(
        model.predict(observation, deterministic=True)[0],
        reloaded.predict(observation, deterministic=True)[0],
    )


@pytest.mark.slow
@pytest.mark.skipif(not SHIPPED_MODEL.is_file(), reason="no shipped model")
@pytest.mark.parametrize("trace", ["straight", "right_turn", "zigzag"])
def test_shipped_model_completes_each_trace_seed(trace: str) -> None:
    env = gym.make("DualLidar-v0", world="open_cylinders", trace=trace)
    episode = drive_episode(env, SB3Driver(), seed=0)
    assert episode.success and not episode.collided
    assert episode.cross_track_error < 0.3


@pytest.mark.skipif(not SHIPPED_MODEL.is_file(), reason="no shipped model")
@pytest.mark.parametrize("driver", ["scripted", "sb3"])
def test_the_recorder_takes_either_driver(driver: str) -> None:
    from estimators.leaderboard.recording import record
    from estimators.leaderboard.records import Scenario

    scenario = Scenario("hallway", "zigzag", 0, {"max_episode_time": 4.0}, driver)
    dataset = record(scenario)
    assert len(dataset.times) == 41  # the initial observation + 4 s at 10 Hz
    travelled = np.hypot(*np.diff(dataset.poses[:, :2], axis=0).T).sum()
    assert travelled > 3.0  # both drivers drive off along the trace at about 1 m/s or more


def test_the_driver_feeds_sector_deltas_to_a_model_trained_on_them(tmp_path) -> None:
    from stable_baselines3 import PPO

    for deltas, size in ((False, 86), (True, 158)):
        env = wrapped(sector_deltas=deltas)
        PPO("MlpPolicy", env, n_steps=64, seed=0, device="cpu").save(tmp_path / "m.zip")
        driver = SB3Driver(tmp_path / "m.zip")
        raw = gym.make("DualLidar-v0", trace="straight")
        observation, info = raw.reset(seed=0)
        driver.reset(raw)
        assert driver._view is not None and driver._view.sector_deltas == deltas
        assert driver._view.observation_space.shape == (size,)
        assert driver.act(observation, info).shape == (2,)


def test_evaluation_reports_how_close_the_movers_came() -> None:
    env = gym.make("DualLidar-v0", world="open_cylinders", trace="right_turn",
                   config={"moving_obstacles": 10, "mover_model": "waypoints"})
    # Seed 1_000_000: pure pursuit, blind to the scans, walks into a pedestrian after 3.7 s.
    episode = drive_episode(env, make_driver("scripted"), seed=1_000_000)
    assert episode.collided and not episode.success and episode.time < 5.0
    half_diagonal = np.hypot(env.unwrapped.config.car_length, env.unwrapped.config.car_width) / 2
    assert 0.0 <= episode.closest_mover <= half_diagonal  # touching: edge within the car's box
    static = gym.make("DualLidar-v0", world="open_cylinders", trace="right_turn")
    assert drive_episode(static, make_driver("scripted"), seed=0).closest_mover == np.inf


@pytest.mark.skipif(not SHIPPED_MODEL.is_file(), reason="no shipped model")
def test_the_shipped_policy_gives_way_to_a_pedestrian_that_pure_pursuit_runs_into():
    env = gym.make("DualLidar-v0", world="open_cylinders", trace="right_turn",
                   config={"moving_obstacles": 10, "mover_model": "yielding"})
    # Seed 3: pure pursuit, blind to the scans, drives into a crossing pedestrian after 15 s.
    blind = drive_episode(env, make_driver("scripted"), seed=3)
    assert blind.collided and blind.time < 20.0
    episode = drive_episode(env, SB3Driver(), seed=3)
    assert episode.success and not episode.collided
    assert episode.closest_mover < 1.0  # a pedestrian came close, and it was seen in time
