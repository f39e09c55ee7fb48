"""The constant-velocity prediction's uncertainty shared by lidar_odometry and pc_fusion."""

import pytest

from estimators.odometry.motion_prior import MIN_PREDICTION_SIGMA, clock_jitter, prediction_sigma


def test_a_steady_clock_has_no_jitter_and_glitches_do_not_count() -> None:
    assert clock_jitter([0.1] * 20) == 0.0
    # Half the stamps 10 ms off the median interval: jitter 10 ms; one 3 s gap changes nothing.
    intervals = [0.09, 0.1, 0.11] * 10
    assert clock_jitter(intervals) == pytest.approx(0.01)
    assert clock_jitter([*intervals, 3.0]) == pytest.approx(0.01)


def test_prediction_sigma_is_acceleration_dt2_plus_speed_jitter_within_bounds() -> None:
    assert prediction_sigma(0.1, 0.0, 0.0, 0.5, 0.05) == pytest.approx(0.005)
    assert prediction_sigma(0.1, 1.0, 0.002, 0.5, 0.05) == pytest.approx(0.007)
    assert prediction_sigma(0.01, 0.0, 0.0, 0.5, 0.05) == MIN_PREDICTION_SIGMA
    assert prediction_sigma(1.0, 1.0, 0.1, 0.5, 0.05) == 0.05
