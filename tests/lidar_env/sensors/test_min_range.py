"""min_range: a reading below it is invalid and reads max_range, in the single env, the vector
env and the layout kernel alike; out-of-range Lidar settings are named errors."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import lidar_env  # noqa: F401 - registers DualLidar-v0
from lidar_env.core.errors import ConfigError
from lidar_env.sensors.lidar_config import LidarConfig
from lidar_env.sensors.lidar_layout import LidarLayout
from lidar_env.world.world import World


def test_readings_below_min_range_read_max_range() -> None:
    world = World(circles=[[0.5, 0.0, 0.2], [0.0, 2.0, 0.2]], bounds=(-5, -5, 5, 5))
    plain = LidarLayout([LidarConfig((0.0, 0.0, 0.0), n_beams=8, range_noise_std=0.0)])
    limited = LidarLayout([LidarConfig((0.0, 0.0, 0.0), n_beams=8, range_noise_std=0.0,
                                       min_range=0.5, max_range=5.0)])
    rng = np.random.default_rng(0)
    exact = plain.scan(world, np.zeros((1, 3)), rng)[0]
    scan = limited.scan(world, np.zeros((1, 3)), rng)[0]
    assert exact[0] == pytest.approx(0.3) and scan[0] == 5.0  # 0.3 m < 0.5 m: invalid
    assert exact[2] == pytest.approx(1.8) and scan[2] == pytest.approx(1.8)  # valid, kept
    assert np.all((scan >= 0.5) & (scan <= 5.0))


def test_the_vector_env_honours_min_range_like_single_envs() -> None:
    config = {"robot": "turtlebot3_burger"}
    single = [gym.make("DualLidar-v0", world="hallway", config=config) for _ in range(2)]
    vector = gym.make_vec("DualLidar-v0", num_envs=2, vectorization_mode="vector_entry_point",
                          world="hallway", config=config)
    observations, _ = vector.reset(seed=[3, 4])
    expected = [env.reset(seed=seed)[0]["lidar_1"] for env, seed in zip(single, (3, 4),
                                                                        strict=True)]
    rng = np.random.default_rng(0)
    for _ in range(5):
        actions = rng.uniform(-1, 1, (2, 2)).astype(np.float32)
        np.testing.assert_array_equal(observations["lidar_1"], np.stack(expected))
        low = observations["lidar_1"][observations["lidar_1"] < 3.5]
        assert np.all(low >= 0.12)
        observations = vector.step(actions)[0]
        expected = [env.step(action)[0]["lidar_1"] for env, action in zip(single, actions,
                                                                          strict=True)]


@settings(max_examples=40, deadline=None)
@given(st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                 st.integers(min_value=-10**400, max_value=10**400)))
def test_lidar_settings_outside_their_ranges_are_named(value: float) -> None:
    for key, valid in (("max_range", 0.01 <= value <= 1000),
                       ("n_beams", isinstance(value, int) and 3 <= value <= 100_000),
                       ("min_range", 0 <= value < 10.0)):
        if key == "n_beams" and valid and value > 5000:
            continue  # valid, just large
        try:
            LidarConfig((0.0, 0.0, 0.0), **{key: value})
        except ConfigError as error:
            assert not valid and f"lidars[0].{key}: expected" in str(error)
            assert len(str(error)) < 200
        else:
            assert valid, (key, value)


@pytest.mark.parametrize("value", [1e39, 1e-300, 10**400, 0.0, float("nan")])
def test_max_range_a_float32_scan_cannot_hold_is_refused(value: float) -> None:
    with pytest.raises(ConfigError, match=r"lidars\[0\].max_range: expected a number in"):
        gym.make("DualLidar-v0", config={"lidars": [{"mount": (0, 0, 0), "max_range": value}]})
