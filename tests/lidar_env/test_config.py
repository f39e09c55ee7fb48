"""EnvConfig: defaults, validation with readable errors, and its use through gym.make."""

import gymnasium as gym
import numpy as np
import pytest

import lidar_env  # noqa: F401 - registers DualLidar-v0
from lidar_env.config import EnvConfig
from lidar_env.core.errors import ConfigError


def test_defaults_match_the_documented_car_and_sensors():
    config = EnvConfig()
    assert config.control_dt == 0.1 and config.physics_substeps == 4
    assert config.n_beams == 360 and config.max_range == 10.0
    mounts = config.mounts_array
    assert mounts.shape == (2, 3)
    assert np.linalg.norm(mounts[0, :2] - mounts[1, :2]) == pytest.approx(0.5)
    assert config.car_half_diagonal == pytest.approx(0.5 * np.hypot(0.8, 0.5))
    assert config.trace_clearance == pytest.approx(config.car_half_diagonal + config.trace_margin)


def test_from_dict_round_trips_and_replace_keeps_the_original():
    lidars = [{"mount": [0.3, 0.1, 0.0], "max_range": 8.0},
              {"mount": (-0.3, 0, 0), "max_range": 8.0, "fov": np.pi, "range_noise_std": 0.0}]
    config = EnvConfig.from_dict({"lidars": lidars})
    assert EnvConfig.from_dict(config.to_dict()) == config
    changed = config.replace(scan_frame="world")
    assert changed.scan_frame == "world" and config.scan_frame == "sensor"
    assert changed.lidar_mounts == ((0.3, 0.1, 0.0), (-0.3, 0.0, 0.0))
    assert [lidar.range_noise_std for lidar in config.lidars] == [0.01, 0.0]  # default, own
    assert config.max_range == 8.0 and config.lidars[1].fov == pytest.approx(np.pi)


def test_unknown_keys_are_named_with_the_valid_ones():
    with pytest.raises(ValueError, match=r"unknown config key\(s\) 'max_rnage'.*lidars"):
        EnvConfig.from_dict({"max_rnage": 5.0})
    with pytest.raises(ValueError, match="'speed'.*control_dt"):
        EnvConfig().replace(speed=1.0)


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("control_dt", 0.0, "control_dt: expected a positive finite number, got 0.0"),
        ("control_dt", float("nan"), "control_dt: expected a positive finite number"),
        ("physics_substeps", 0, r"physics_substeps: expected an integer >= 1, got 0"),
        ("physics_substeps", 2.5, r"physics_substeps: expected an integer >= 1, got 2.5"),
        ("scan_frame", "car", "scan_frame: expected one of sensor, world, got 'car'"),
        ("lidars", [], r"lidars: expected 1 to 8 Lidars, got 0"),
        ("lidars", [{"mount": (0, 0, 0)}] * 9, r"lidars: expected 1 to 8 Lidars, got 9"),
        ("lidars", {"mount": (0, 0, 0)}, r"lidars: expected a list of 1 to 8 dicts, got dict"),
        ("lidars", [{"mount": (0, 0, 0), "fvo": 1.0}], r"lidars\[0\]: unknown key\(s\) 'fvo'"),
        ("lidars", [{"n_beams": 90}], r"lidars\[0\]: expected a 'mount'"),
        ("lidars", [{"mount": (0, 0, 0)}, {"mount": (0, 0, 0), "fov": 0.0}],
         r"lidars\[1\].fov: expected a field of view in \(0, 2 pi\]"),
        ("lidars", [{"mount": (0, 0, 0), "fov": 7.0}], r"lidars\[0\].fov: expected"),
        ("lidars", [{"mount": (0, 0, 0), "n_beams": 2}], r"lidars\[0\].n_beams: expected an int"),
        ("lidars", [{"mount": (0, 0, 0), "max_range": -1.0}], r"lidars\[0\].max_range: expected"),
        ("lidars", [{"mount": (0, np.inf, 0)}], r"lidars\[0\].mount: expected 3 finite numbers"),
        ("lidars", [{"mount": (0, 0)}], r"lidars\[0\].mount: expected 3 finite numbers"),
        ("lidars", [{"mount": (2.0, 0, 0)}], r"lidars\[0\].mount: \(2, 0\) lies 2.000 m .*reach"),
        ("lidars", [{"mount": (0, 0, 0), "dropout_prob": 1.0}],
         r"lidars\[0\].dropout_prob: expected a number in \[0, 1\), got 1.0"),
        ("lidars", [{"mount": (0, 0, 0)}, {"mount": (0, 0, 0), "range_noise_std": -0.1}],
         r"lidars\[1\].range_noise_std: expected a finite number >= 0 \[m\], got -0.1"),
        ("lidars", [{"mount": (0, 0, 0), "range_noise_std": None}],
         r"lidars\[0\].range_noise_std: expected a finite number >= 0 \[m\], got None"),
        ("lidar_mounts", [[0, 0, 0]], r"'lidar_mounts' moved into 'lidars'"),
        ("n_beams", 90, r"'n_beams' moved into 'lidars'"),
        ("max_range", 8.0, r"'max_range' moved into 'lidars'"),
    ],
)
def test_bad_values_raise_readable_errors(key, value, message):
    with pytest.raises(ConfigError, match=message):
        EnvConfig.from_dict({key: value})


def test_gym_make_takes_a_config_dict_and_rebuilds_spaces():
    lidars = [{"mount": (0.25, 0, 0), "n_beams": 90, "max_range": 6.0},
              {"mount": (-0.25, 0, 0), "n_beams": 45, "fov": np.pi, "max_range": 4.0}]
    env = gym.make("DualLidar-v0", config={"lidars": lidars})
    box = env.observation_space["lidar_1"]
    assert box.shape == (90,) and box.high.max() == pytest.approx(6.0)
    assert env.observation_space["lidar_2"].shape == (45,)
    observation, _ = env.reset(seed=0)
    assert observation["lidar_2"].shape == (45,) and observation["lidar_2"].max() <= 4.0
    assert observation in env.observation_space
    with pytest.raises(ValueError, match="unknown config key"):
        gym.make("DualLidar-v0", config={"beams": 90})
    with pytest.raises(TypeError, match="config: expected an EnvConfig or a dict, got list"):
        gym.make("DualLidar-v0", config=[("n_beams", 90)])
