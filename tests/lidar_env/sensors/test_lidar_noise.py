"""Range noise and dropout belong to each Lidar: the old top-level keys are refused
with a pointer to ``config["lidars"]``, ``lidars_with_noise`` sets them on a whole layout, and
each Lidar's own values are the ones its scans carry."""

import json

import gymnasium as gym
import numpy as np
import pytest

from lidar_env import EnvConfig, LidarConfig, lidars_with_noise
from lidar_env.core.errors import ConfigError

OLD_KEYS = [{"range_noise_std": 0.0}, {"dropout_prob": 0.1},
            {"range_noise_std": 0.02, "dropout_prob": 0.1}]


def _old_key_message(config: dict) -> str:
    """What the ConfigError for ``config``'s old keys must say: each key's new place, and the
    helper that sets it on every Lidar."""
    first = sorted(config)[0]
    return (rf"'{first}'.*moved into 'lidars'.*config\['lidars'\]\[k\]\['{first}'\]"
            r".*lidars_with_noise")


@pytest.mark.parametrize("config", OLD_KEYS)
def test_the_old_top_level_noise_keys_raise_a_config_error_naming_lidars(config):
    message = _old_key_message(config)
    with pytest.raises(ConfigError, match=message):
        EnvConfig.from_dict(config)
    with pytest.raises(ConfigError, match=message):
        EnvConfig().replace(**config)
    with pytest.raises(ConfigError, match=message):
        gym.make("DualLidar-v0", config={"scan_frame": "world", **config})
    with pytest.raises(ConfigError, match=message):
        gym.make_vec("DualLidar-v0", num_envs=2, vectorization_mode="vector_entry_point",
                     config=config)


def test_reset_options_take_no_config_so_an_old_key_there_is_refused_too():
    env = gym.make("DualLidar-v0")
    env.reset(seed=0)
    with pytest.raises(ConfigError, match=r"unknown reset option\(s\) 'range_noise_std'"):
        env.reset(seed=0, options={"range_noise_std": 0.0})


def test_following_the_error_message_gives_a_working_config():
    config = {"scan_frame": "world", "max_episode_time": 5.0}
    config["lidars"] = lidars_with_noise(config, range_noise_std=0.0)
    env = gym.make("DualLidar-v0", config=config)
    assert [lidar.range_noise_std for lidar in env.unwrapped.config.lidars] == [0.0, 0.0]
    assert env.unwrapped.config.scan_frame == "world"


def test_the_helper_gives_the_default_layout_with_the_noise_on_every_lidar():
    lidars = lidars_with_noise(range_noise_std=0.03, dropout_prob=0.2)
    default = EnvConfig().lidars
    assert len(lidars) == len(default) == 2
    for k, (entry, lidar) in enumerate(zip(lidars, default, strict=True)):
        assert entry == {**lidar.to_dict(), "range_noise_std": 0.03, "dropout_prob": 0.2}
        assert LidarConfig.from_value(entry, k).mount == lidar.mount
    # with no noise given, it is the default layout itself (0.01 m, no dropout)
    assert lidars_with_noise() == [lidar.to_dict() for lidar in default]
    assert [lidar.range_noise_std for lidar in default] == [0.01, 0.01]
    assert [lidar.dropout_prob for lidar in default] == [0.0, 0.0]


def test_the_helper_keeps_a_configs_own_layout_and_what_it_is_not_told_to_set():
    lidars = [{"mount": (0.3, 0.0, 0.0), "n_beams": 90, "fov": np.pi, "dropout_prob": 0.4},
              {"mount": (-0.3, 0.0, np.pi), "max_range": 6.0, "range_noise_std": 0.0}]
    config = {"lidars": lidars, "car_length": 1.0}
    noisy = lidars_with_noise(config, range_noise_std=0.05)
    assert [entry["mount"] for entry in noisy] == [[0.3, 0.0, 0.0], [-0.3, 0.0, np.pi]]
    assert [entry["n_beams"] for entry in noisy] == [90, 360]
    assert [entry["max_range"] for entry in noisy] == [10.0, 6.0]
    assert [entry["range_noise_std"] for entry in noisy] == [0.05, 0.05]
    assert [entry["dropout_prob"] for entry in noisy] == [0.4, 0.0]  # each Lidar's own
    assert lidars_with_noise(EnvConfig.from_dict(config), range_noise_std=0.05) == noisy
    assert "range_noise_std" not in lidars[0]  # the caller's list is left as it was
    # plain JSON values: a leaderboard Scenario read back from its database compares equal
    assert json.loads(json.dumps(noisy)) == noisy


def test_the_helper_names_a_bad_value_or_config():
    with pytest.raises(ConfigError, match=r"lidars\[0\].range_noise_std: expected a finite"):
        lidars_with_noise(range_noise_std=-0.01)
    with pytest.raises(ConfigError, match=r"lidars\[0\].dropout_prob: expected a number in"):
        lidars_with_noise(dropout_prob=1.0)
    with pytest.raises(ConfigError, match=r"config: expected an EnvConfig, a dict or None, "
                                          r"got list"):
        lidars_with_noise([{"mount": (0, 0, 0)}])
    with pytest.raises(ConfigError, match=r"'range_noise_std'.*moved into 'lidars'"):
        lidars_with_noise({"range_noise_std": 0.0}, range_noise_std=0.0)


def _scans(config, steps: int = 15) -> list[dict[str, np.ndarray]]:
    env = gym.make("DualLidar-v0", world="closed_to_open", config=config)
    observation, _ = env.reset(seed=4)
    scans = [observation]
    for _ in range(steps):
        observation, *_ = env.step(np.array([0.6, 0.2], dtype=np.float32))
        scans.append(observation)
    return scans


def test_the_default_noise_is_each_lidars_own_and_bit_identical_to_spelling_it_out():
    spelled = {"lidars": lidars_with_noise(range_noise_std=0.01, dropout_prob=0.0)}
    for default, explicit in zip(_scans(None), _scans(spelled), strict=True):
        for key in default:
            assert default[key].tobytes() == explicit[key].tobytes()


def test_each_lidar_carries_its_own_noise_and_dropout():
    exact = {"lidars": lidars_with_noise(range_noise_std=0.0)}
    mixed = {"lidars": [{"mount": (0.25, 0.0, 0.0), "range_noise_std": 0.0},
                        {"mount": (-0.25, 0.0, 0.0), "range_noise_std": 0.05,
                         "dropout_prob": 0.3}]}
    truth, noisy = _scans(exact), _scans(mixed)
    residuals, dropped, hits = [], 0, 0
    for clean, scan in zip(truth, noisy, strict=True):
        np.testing.assert_array_equal(scan["lidar_1"], clean["lidar_1"])  # its own 0 noise
        hit = clean["lidar_2"] < 10.0
        out = scan["lidar_2"] == 10.0
        dropped += int(np.sum(out & hit))
        hits += int(np.sum(hit))
        kept = hit & ~out
        residuals.append(scan["lidar_2"][kept].astype(np.float64) - clean["lidar_2"][kept])
    residual = np.concatenate(residuals)
    assert np.std(residual) == pytest.approx(0.05, rel=0.1)  # thousands of draws
    assert dropped / hits == pytest.approx(0.3, abs=0.03)
