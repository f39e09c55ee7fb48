"""The constant-velocity prediction's uncertainty shared by lidar_odometry and pc_fusion."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimators.health import BLIND_STRETCH
from estimators.odometry.local_map import LocalMapOdometry
from estimators.odometry.motion_prior import (
    MIN_PREDICTION_SIGMA,
    ScanClock,
    clock_jitter,
    constant_velocity_increment,
    mean_translation,
    median,
    midpoint_velocity,
    missed_sigma,
    no_sideslip_information,
    one_turn_increment,
    prediction_sigma,
    sorted_median_deviation,
)
from estimators.odometry.velocity_model import _symmetric_eigh
from lidar_env.core.se2 import rotate


def test_a_steady_clock_has_no_jitter_and_glitches_do_not_count() -> None:
    assert clock_jitter([0.1] * 20) == 0.0
    # Half the stamps 10 ms off the median interval: jitter 10 ms; one 3 s gap changes nothing.
    intervals = [0.09, 0.1, 0.11] * 10
    assert clock_jitter(intervals) == pytest.approx(0.01)
    assert clock_jitter([*intervals, 3.0]) == pytest.approx(0.01)


def test_the_jitter_about_a_given_centre_is_the_median_deviation_from_it() -> None:
    rng = np.random.default_rng(4)
    intervals = 0.1 + 0.003 * rng.standard_normal(201)
    assert clock_jitter(intervals, float(np.median(intervals))) == clock_jitter(intervals)
    assert clock_jitter([0.1, 0.12, 0.14], centre=0.1) == pytest.approx(0.02)


def test_prediction_sigma_is_acceleration_dt2_plus_speed_jitter_within_bounds() -> None:
    assert prediction_sigma(0.1, 0.0, 0.0, 0.5, 0.05) == pytest.approx(0.005)
    assert prediction_sigma(0.1, 1.0, 0.002, 0.5, 0.05) == pytest.approx(0.007)
    assert prediction_sigma(0.01, 0.0, 0.0, 0.5, 0.05) == MIN_PREDICTION_SIGMA
    assert prediction_sigma(1.0, 1.0, 0.1, 0.5, 0.05) == 0.05


@settings(max_examples=200, deadline=None)
@given(st.floats(1e-4, 0.05), st.lists(st.floats(0.0, 1.0), max_size=6), st.floats(1e-4, 0.1))
def test_a_large_recent_miss_widens_the_prediction_to_it(
    sigma: float, misses: list[float], max_sigma: float
) -> None:
    sigma = min(sigma, max_sigma)  # as prediction_sigma clips it
    widened = missed_sigma(sigma, misses, max_sigma)
    if max(misses, default=0.0) <= 2.0 * sigma:
        assert widened == sigma  # misses within what the prediction assumes change nothing
    else:
        assert widened == min(max(misses), max_sigma)
    assert sigma <= widened <= max_sigma


def test_scan_clock_statistics_are_those_of_its_last_intervals() -> None:
    """``ScanClock`` keeps the last finite intervals and positive steps, and its cached
    median, jitter and typical step are recomputed as soon as one is added."""
    rng = np.random.default_rng(0)
    clock = ScanClock(max_intervals=7, max_steps=3)
    seen: list[float] = []
    for dt in [*rng.uniform(-0.05, 0.3, 20), np.nan, np.inf, 0.0]:
        clock.add(float(dt))
        if np.isfinite(dt):
            seen.append(float(dt))
        assert list(clock.intervals) == seen[-7:]
        steps = [value for value in seen if value > 0][-3:]
        assert clock.median == np.median(seen[-7:])
        assert clock.jitter == clock_jitter(seen[-7:])
        assert clock.typical_step == np.median(steps)
    clock.extend([0.5, 0.5])
    assert clock.median == np.median([*seen[-5:], 0.5, 0.5])
    fresh = ScanClock()
    for k in range(5):  # settled from the fifth finite interval on
        assert not fresh.settled
        fresh.add(0.1 if k != 2 else np.nan)
    fresh.add(0.1)
    assert fresh.settled
    assert clock.typical_step == np.median([value for value in seen if value > 0][-3:])


def test_scan_clock_medians_stay_numpys_over_many_repeated_intervals() -> None:
    """The medians ``ScanClock`` reads off its sorted intervals and steps are ``np.median`` of
    the last ones, bit for bit, while repeated values (a logger's quantised stamps) come and
    fall out of the window in any order, odd and even counts alike."""
    rng = np.random.default_rng(1)
    clock = ScanClock(max_intervals=10, max_steps=5)
    seen: list[float] = []
    for dt in rng.choice([0.0, 0.1, 0.1, 0.2, 0.25, -0.1, 0.3], 300):
        clock.add(float(dt))
        seen.append(float(dt))
        steps = [value for value in seen if value > 0][-5:]
        assert clock.median == float(np.median(seen[-10:]))
        assert clock.typical_step == float(np.median(steps))


@settings(max_examples=200, deadline=None)
@given(values=st.lists(st.floats(-1e3, 1e3) | st.sampled_from([0.0, -0.0, 0.1, 0.1, 0.2]),
                       min_size=1, max_size=60),
       centre=st.none() | st.floats(-1e3, 1e3) | st.sampled_from([0.0, 0.1]))
def test_sorted_median_deviation_is_clock_jitter_bit_for_bit(values: list[float],
                                                            centre: float | None) -> None:
    """The jitter a ``ScanClock`` reads off its sorted intervals is :func:`clock_jitter`'s
    partition of all of them, bit for bit: odd and even counts, repeated values, a centre
    off the median or outside the values."""
    centre = float(np.median(values)) if centre is None else centre
    assert sorted_median_deviation(sorted(values), centre) == clock_jitter(values, centre)


def test_scan_clock_jitter_stays_clock_jitters_over_a_sliding_window() -> None:
    """Quantised stamps coming and falling out of the window: the cached jitter is always
    :func:`clock_jitter` of the last intervals."""
    rng = np.random.default_rng(2)
    clock = ScanClock(max_intervals=9)
    seen: list[float] = []
    for dt in rng.choice([0.0, 0.1, 0.1, 0.1, 0.2, 0.25, -0.1, 0.3], 300):
        clock.add(float(dt))
        seen.append(float(dt))
        assert clock.jitter == clock_jitter(seen[-9:])


@settings(max_examples=80, deadline=None)
@given(values=st.lists(st.floats(-1e3, 1e3) | st.sampled_from([0.1, np.inf, -np.inf]),
                       min_size=1, max_size=60))
def test_median_is_numpys_bit_for_bit(values: list[float]) -> None:
    array = np.array(values)
    with np.errstate(invalid="ignore"):  # inf and -inf in the middle: NaN, no warning wanted
        expected = np.median(array)
    assert median(array) == expected or np.isnan(expected)


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), rows=st.integers(1, 8), dt=st.sampled_from([1.0, 0.1, 0.37]))
def test_float_forms_are_the_array_forms_bit_for_bit(seed: int, rows: int, dt: float) -> None:
    """The Python-float forms of the per-scan prior (what lidar_odometry calls every scan)
    against the numpy expressions they replace: rotations by ``se2.rotate``, the mean by
    ``np.mean``, the clip by ``np.clip``, no sideslip by the outer product times 0."""
    rng = np.random.default_rng(seed)
    motion = rng.normal(0.0, [0.3, 0.05, 0.4])
    bits = np.ndarray.tobytes
    array_midpoint = np.array([*rotate(-0.5 * motion[2], motion[:2]), motion[2]]) / dt
    assert bits(midpoint_velocity(motion, dt)) == bits(array_midpoint)
    turn = motion[2] * dt
    array_increment = np.array([*rotate(0.5 * turn, motion[:2] * dt), turn])
    assert bits(constant_velocity_increment(motion, dt)) == bits(array_increment)
    translations = [rng.normal(0.0, 0.2, 2) for _ in range(rows)]
    assert bits(np.array(mean_translation(translations))) == bits(np.mean(translations, axis=0))
    value = rng.normal(0.0, 0.05)
    assert prediction_sigma(1.0, 0.0, 0.0, value, 0.03) == float(
        np.clip(value, MIN_PREDICTION_SIGMA, 0.03))
    information, heading, forward = rng.uniform(0.1, 10.0, 3), motion[2], motion[0]
    jacobian = np.array([-np.sin(heading), np.cos(heading), -0.5 * forward])
    full = np.diag(information) + 0.0 * np.outer(jacobian, jacobian)
    assert bits(no_sideslip_information(information, heading, forward, 0.0)) == bits(full)


@pytest.mark.parametrize("heading", [0.0, np.pi / 2])
def test_a_weakly_pinned_direction_moves_the_speed_in_proportion(heading: float) -> None:
    # The car heads along world x (heading 0) or y (pi / 2); the scan pins world x with 2
    # points' worth and world y with 200. Along the weak direction the measured speed moves
    # the held one by 2 / (2 + 10); along the pinned one by 200 / 210.
    model = LocalMapOdometry()
    model._velocity = np.array([0.1, 0.0, 0.0])
    measured = np.array([0.04, 0.01])
    held = model._weakly_seen_held(measured, np.diag([2.0, 200.0]), heading)
    forward, sideways = (2.0 / 12.0, 200.0 / 210.0) if heading == 0.0 else (200 / 210, 2 / 12)
    np.testing.assert_allclose(held, [0.1 + forward * (0.04 - 0.1), sideways * 0.01], atol=1e-12)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-1e6, 1e6, allow_nan=False), min_size=3, max_size=3))
def test_the_speed_hold_s_eigendecomposition_is_numpy_s_bit_for_bit(entries) -> None:
    a, b, c = entries
    matrix = np.array([[a, b], [b, c]])
    values, vectors = _symmetric_eigh(matrix)
    expected_values, expected_vectors = np.linalg.eigh(matrix)
    np.testing.assert_array_equal(values, expected_values)
    np.testing.assert_array_equal(vectors, expected_vectors)


@pytest.mark.parametrize("skipped", [0, BLIND_STRETCH - 1, BLIND_STRETCH, 80])
def test_after_a_long_blind_stretch_the_guess_turns_the_car_once(skipped: int) -> None:
    # Driving at 0.05 m and turning 0.0117 rad per scan (one noisy match's heading change),
    # then ``skipped`` scans without returns: a short gap extrapolates the turn over every
    # interval, a long blind stretch turns the car by one interval's turn only.
    model = LocalMapOdometry()
    model._velocity = np.array([0.05, 0.0, -0.0117])
    dt = 1.0 + skipped
    predicted = model._predicted(dt, skipped)
    turn = -0.0117 if skipped >= BLIND_STRETCH else -0.0117 * dt
    assert predicted[2] == pytest.approx(turn, abs=1e-12)
    assert np.hypot(predicted[0], predicted[1]) == pytest.approx(0.05 * dt, rel=1e-3)


def test_one_turn_increment_keeps_the_translation_and_turns_once() -> None:
    # 20 intervals at 0.05 m and 0.01 rad an interval: the translation of 20 intervals along
    # the chord of one interval's turn
    increment = one_turn_increment(np.array([0.05, 0.0, 0.01]), 20.0)
    assert increment[2] == pytest.approx(0.01, abs=1e-15)
    assert np.hypot(increment[0], increment[1]) == pytest.approx(1.0, rel=1e-12)
    assert np.array_equal(increment, constant_velocity_increment([0.05, 0.0, 0.01 / 20.0], 20.0))
