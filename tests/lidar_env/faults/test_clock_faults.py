"""Clock and delivery faults (``lidar_env.faults.clock_faults``): stamps stay increasing,
jumps stay ahead, stalls catch up, lost scans leave gaps."""

import numpy as np
import pytest

from lidar_env.core import ConfigError
from lidar_env.faults import ClockJitter, ClockJump, ClockStall, ScanLoss, apply_faults
from lidar_env.faults.clock_faults import MIN_STEP
from lidar_env.faults.frames import Frame

MAX = {"lidar_1": 10.0}


def frames(count=100):
    return [Frame({"lidar_1": np.full(8, 2.0)}, 0.1 * k, k) for k in range(count)]


def stamps(faults, seed=0, count=100):
    return np.array([f.time for f in apply_faults(frames(count), faults, seed, MAX)])


def test_jitter_moves_stamps_by_about_sigma_and_keeps_them_increasing():
    t = stamps([ClockJitter(sigma=0.01)])
    assert np.all(np.diff(t) >= MIN_STEP * 0.999)
    assert 0.005 < np.std(t - 0.1 * np.arange(100)) < 0.02


def test_a_jump_stays_ahead():
    t = stamps([ClockJump(jump=3.0, every=50, offset=20)])
    np.testing.assert_allclose(t - 0.1 * np.arange(100),
                               np.where(np.arange(100) >= 70, 6.0,
                                        np.where(np.arange(100) >= 20, 3.0, 0.0)), atol=1e-9)


def test_a_stall_creeps_then_catches_up():
    t = stamps([ClockStall(every=None, probability=0.0)])
    np.testing.assert_allclose(t, 0.1 * np.arange(100))
    t = stamps([ClockStall(every=50, stretch=5, offset=10)])
    assert np.all(np.diff(t[10:15]) < 2 * MIN_STEP)
    assert t[15] == pytest.approx(1.5)


def test_lost_scans_leave_gaps_and_the_first_always_arrives():
    out = list(apply_faults(frames(), [ScanLoss(probability=0.0, every=30, offset=5,
                                                stretch=4)], 0, MAX))
    steps = [f.step for f in out]
    assert steps[0] == 0 and 5 not in steps and 8 not in steps and 9 in steps
    assert len(out) == 100 - 4 * 4
    assert len(list(apply_faults(frames(), [ScanLoss(probability=1.0)], 0, MAX))) == 1


def test_same_seed_same_stamps():
    fault = [ClockJitter(0.02), ScanLoss(0.1), ClockJump(probability=0.05, every=None)]
    np.testing.assert_array_equal(stamps(fault, 3), stamps(fault, 3))
    assert not np.array_equal(stamps(fault, 3), stamps(fault, 4))


@pytest.mark.parametrize("build", [lambda: ClockJitter(-1.0), lambda: ClockJump(jump=0.0),
                                   lambda: ClockJump(jump=float("inf")),
                                   lambda: ClockStall(stretch=0), lambda: ScanLoss(2.0)])
def test_bad_settings_are_config_errors(build):
    with pytest.raises(ConfigError):
        build()
