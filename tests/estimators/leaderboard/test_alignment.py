"""Aligning a real-log trajectory to the reference before drawing its map."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.leaderboard.alignment import align_to_reference
from lidar_env.core.errors import EstimatorInputError
from lidar_env.core.se2 import compose, inverse


def a_drive(times: np.ndarray) -> np.ndarray:
    """A curving drive [m, m, rad] sampled at ``times`` [s]."""
    return np.stack([3 * np.sin(0.2 * times) + 0.5 * times, 2 * np.cos(0.15 * times),
                     0.3 * times], axis=1)


def test_a_rotated_and_shifted_estimate_lands_on_the_reference() -> None:
    rng = np.random.default_rng(4)
    reference_times = np.arange(0.0, 60.0, 0.5)  # keyframes
    times = np.arange(0.013, 60.0, 0.1)  # the estimator's own scan times
    truth = a_drive(times)
    frame = np.array([4.0, -2.0, np.radians(30.0)])  # the estimate's arbitrary start frame
    estimate = compose(inverse(frame), truth)
    estimate[:, :2] += rng.normal(0.0, 0.01, size=(len(times), 2))
    result = align_to_reference(times, estimate, reference_times, a_drive(reference_times))
    np.testing.assert_allclose(result.transform, frame, atol=0.01)
    assert result.matched == len(reference_times)
    # the reference sampled 0.013 s off the estimate's times: motion of ~0.02 m plus the noise
    assert result.residual_m < 0.05
    np.testing.assert_allclose(result.poses[:, :2], truth[:, :2], atol=0.05)


def test_too_few_matching_times_is_a_clear_error() -> None:
    times = np.arange(0.0, 10.0, 0.1)
    with pytest.raises(EstimatorInputError, match="at least two reference times"):
        align_to_reference(times, a_drive(times), times + 100.0, a_drive(times))
    with pytest.raises(EstimatorInputError, match="poses: expected finite"):
        align_to_reference(times, a_drive(times)[:, :2], times, a_drive(times))
