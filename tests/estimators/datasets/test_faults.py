"""Faults for recorded logs (``estimators.datasets.faults``): a recording faulted as the env
wrapper would fault the live scans, lost observations left out with their truth."""

import numpy as np
import pytest

from estimators import SensorSetup
from estimators.datasets.faults import with_faults
from estimators.datasets.recording import Recording
from lidar_env.core import ConfigError
from lidar_env.faults import Blind, ClockJump, ScanLoss


def recording(count=30):
    setup = SensorSetup(np.zeros((2, 3)), 2 * np.pi * np.arange(36) / 36, 8.0)
    rng = np.random.default_rng(0)
    scans = {key: rng.uniform(1, 5, (count, 36)) for key in setup.keys}
    truth = np.c_[0.1 * np.arange(count), np.zeros(count), np.zeros(count)]
    return Recording("test", setup, 0.1 * np.arange(count), scans, setup.keys, setup.keys,
                     truth)


def test_blind_scans_read_max_range_and_the_rest_stay():
    clean = recording()
    out = with_faults(clean, [Blind(every=2)])
    for k in range(len(out)):
        for key in clean.setup.keys:
            if k % 2:
                assert np.all(out.scans[key][k] == 8.0)
            else:
                np.testing.assert_array_equal(out.scans[key][k], clean.scans[key][k])
    np.testing.assert_array_equal(out.times, clean.times)


def test_lost_scans_leave_rows_out_with_their_truth():
    out = with_faults(recording(), [ScanLoss(probability=0.0, every=10, offset=3, stretch=2)])
    assert len(out) == 30 - 6 and out.dropped == 6
    assert 0.3 not in np.round(out.times, 6) and out.truth is not None
    np.testing.assert_allclose(out.truth[:, 0], out.times)


def test_clock_faults_change_only_the_stamps_and_same_seed_same_faults():
    clean = recording()
    faults = [ClockJump(jump=3.0, every=None, probability=0.2)]
    out, again, other = (with_faults(clean, faults, 1), with_faults(clean, faults, 1),
                         with_faults(clean, faults, 2))
    np.testing.assert_array_equal(out.times, again.times)
    assert not np.array_equal(out.times, other.times)
    assert np.all(np.diff(out.times) > 0)
    np.testing.assert_array_equal(out.scans["lidar_1"], clean.scans["lidar_1"])


def test_losing_everything_but_the_first_keeps_one_and_bad_faults_are_named():
    assert len(with_faults(recording(), [ScanLoss(probability=1.0)])) == 1
    with pytest.raises(ConfigError, match="Fault"):
        with_faults(recording(), ["blind"])
