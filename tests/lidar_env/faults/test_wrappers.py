"""FaultInjection (``lidar_env.faults.wrappers``): the env's scans and clock faulted, same
seed same faults, the env's own draws untouched, lost scans skipped."""

import gymnasium as gym
import numpy as np
import pytest

import lidar_env  # noqa: F401  (registers DualLidar-v0)
from lidar_env.core import ConfigError
from lidar_env.faults import BeamDropout, Blind, ClockJump, FaultInjection, ScanLoss

ACTION = np.array([0.5, 0.1], dtype=np.float32)


def rollout(env, seed, steps=12):
    observation, info = env.reset(seed=seed)
    out = [(observation, info)]
    for _ in range(steps):
        observation, _, _, _, info = env.step(ACTION)
        out.append((observation, info))
    return out


def test_the_wrapper_faults_scans_and_leaves_the_world_as_it_was():
    clean = rollout(gym.make("DualLidar-v0"), 0)
    faulted = rollout(FaultInjection(gym.make("DualLidar-v0"), Blind(every=2),
                                     ClockJump(jump=3.0, every=5, offset=4)), 0)
    for k, ((o, i), (fo, fi)) in enumerate(zip(clean, faulted, strict=True)):
        assert fo["lidar_1"].dtype == o["lidar_1"].dtype
        if k % 2:
            assert np.all(fo["lidar_1"] == 10.0)
        else:  # the env's own noise is that of the clean run
            np.testing.assert_array_equal(fo["lidar_1"], o["lidar_1"])
        np.testing.assert_array_equal(fi["pose"], i["pose"])
        assert fi["true_time"] == i["time"]
        assert fi["time"] == pytest.approx(i["time"] + 3.0 * (k >= 4) + 3.0 * (k >= 9))


def test_same_seed_same_faults():
    def make():
        return FaultInjection(gym.make("DualLidar-v0"), BeamDropout(0.3, burst=4))
    first, again, other = rollout(make(), 1), rollout(make(), 1), rollout(make(), 2)
    assert all(np.array_equal(a[0]["lidar_2"], b[0]["lidar_2"])
               for a, b in zip(first, again, strict=True))
    masks = [[o["lidar_2"] == 10.0 for o, _ in run] for run in (first, other)]
    assert any(not np.array_equal(a, b) for a, b in zip(*masks, strict=True))


def test_a_lost_scan_is_stepped_over():
    env = FaultInjection(gym.make("DualLidar-v0"), ScanLoss(probability=0.0, every=3,
                                                             offset=2, stretch=2))
    times = [info["time"] for _, info in rollout(env, 0, steps=6)]
    np.testing.assert_allclose(np.diff(times), [0.1, 0.3, 0.3, 0.3, 0.3, 0.3])  # 2-3, 5-6, .. lost


def test_faults_are_required_and_checked():
    with pytest.raises(ConfigError):
        FaultInjection(gym.make("DualLidar-v0"))
    with pytest.raises(ConfigError, match="Fault"):
        FaultInjection(gym.make("DualLidar-v0"), "blind")
