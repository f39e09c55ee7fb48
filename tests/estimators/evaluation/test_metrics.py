"""Trajectory metrics on closed-form trajectories with known errors."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.evaluation.metrics import accuracy, align_se2, eq11_error, evaluate
from lidar_env.core.se2 import compose


def _straight(n: int = 11, step: float = 0.1, heading: float = 0.0) -> np.ndarray:
    """``n`` poses along x, ``step`` [m] apart."""
    poses = np.zeros((n, 3))
    poses[:, 0] = step * np.arange(n)
    poses[:, 2] = heading
    return poses


def _arc(n: int = 40) -> np.ndarray:
    """A quarter circle of radius 5 m, heading tangent."""
    angle = np.linspace(0.0, np.pi / 2, n)
    return np.column_stack([5 * np.sin(angle), 5 - 5 * np.cos(angle), angle])


def test_perfect_estimate_scores_zero_error_and_full_accuracy() -> None:
    truth = _arc()
    metrics = evaluate(truth, truth)
    assert metrics.eq11_error_percent == 0.0 and metrics.accuracy_percent == 100.0
    assert metrics.ate_rmse_m == metrics.heading_rmse_deg == metrics.drift_percent == 0.0
    assert metrics.rpe_translation_rmse_m == pytest.approx(0.0, abs=1e-12)
    assert metrics.n_poses == 40 and metrics.n_steps_scored == 39


def test_ten_percent_long_steps_give_eq11_ten_and_accuracy_ninety() -> None:
    truth = _straight()
    estimate = _straight(step=0.11)
    metrics = evaluate(estimate, truth)
    assert metrics.eq11_error_percent == pytest.approx(10.0)
    assert metrics.accuracy_percent == pytest.approx(90.0)
    # end point 0.1 m off after 1 m travelled
    assert metrics.drift_percent == pytest.approx(10.0)
    assert metrics.distance_m == pytest.approx(1.0)
    # position errors 0, 0.01, ..., 0.1 m
    assert metrics.ate_rmse_m == pytest.approx(np.sqrt(np.mean((0.01 * np.arange(11)) ** 2)))
    assert metrics.rpe_translation_rmse_m == pytest.approx(0.01)


def test_eq11_ignores_direction_but_ate_does_not() -> None:
    truth = _straight()
    backwards = _straight(step=-0.1)
    metrics = evaluate(backwards, truth)
    assert metrics.eq11_error_percent == pytest.approx(0.0)
    assert metrics.ate_rmse_m == pytest.approx(2 * np.sqrt(np.mean((0.1 * np.arange(11)) ** 2)))
    assert metrics.drift_percent == pytest.approx(200.0)


def test_accuracy_is_floored_at_zero() -> None:
    assert evaluate(_straight(step=0.35), _straight()).accuracy_percent == 0.0
    assert accuracy(250.0) == 0.0 and accuracy(8.9) == pytest.approx(91.1)


def test_short_steps_are_left_out_of_eq11() -> None:
    truth = np.repeat(_straight(6), 2, axis=0)  # every second step stands still
    estimate = truth.copy()
    estimate[1::2, 0] += 0.001  # 1 mm where the car stands: 1 mm / 0 is undefined
    estimate[2::2, 0] += 0.001
    assert eq11_error(estimate, truth, min_step=0.01) == pytest.approx(0.0)
    still = np.zeros((5, 3))
    assert np.isnan(eq11_error(still, still))
    metrics = evaluate(still, still)
    assert np.isnan(metrics.accuracy_percent) and np.isnan(metrics.drift_percent)


def test_heading_and_rotational_rpe_in_degrees() -> None:
    truth = _straight()
    constant_offset = _straight(heading=np.deg2rad(3.0))
    metrics = evaluate(constant_offset, truth)
    assert metrics.heading_rmse_deg == pytest.approx(3.0)
    assert metrics.rpe_rotation_rmse_deg == pytest.approx(0.0, abs=1e-9)
    turning = truth.copy()
    turning[:, 2] = np.deg2rad(0.5) * np.arange(11)  # 0.5 degree wrong turn per step
    assert evaluate(turning, truth).rpe_rotation_rmse_deg == pytest.approx(0.5)


def test_se2_alignment_removes_a_rigid_motion() -> None:
    truth = _arc()
    moved = compose(np.array([1.0, -2.0, 0.4]), truth)
    assert evaluate(moved, truth).ate_rmse_m > 1.0
    aligned = evaluate(moved, truth, align="se2")
    assert aligned.ate_rmse_m == pytest.approx(0.0, abs=1e-9)
    assert aligned.heading_rmse_deg == pytest.approx(0.0, abs=1e-6)
    np.testing.assert_allclose(align_se2(moved, truth), truth, atol=1e-9)


def test_bad_input_is_a_readable_error() -> None:
    with pytest.raises(ValueError, match=r"estimated: expected poses of shape \(N, 3\)"):
        evaluate(np.zeros((5, 2)), np.zeros((5, 3)))
    with pytest.raises(ValueError, match="equal numbers of poses, got 4 and 5"):
        evaluate(np.zeros((4, 3)), np.zeros((5, 3)))
    with pytest.raises(ValueError, match="truth: expected finite"):
        evaluate(np.zeros((5, 3)), np.full((5, 3), np.nan))
    with pytest.raises(ValueError, match="unknown align 'umeyama': expected one of none, se2"):
        evaluate(np.zeros((5, 3)), np.zeros((5, 3)), align="umeyama")
    with pytest.raises(ValueError, match="min_step"):
        evaluate(np.zeros((5, 3)), np.zeros((5, 3)), min_step=0.0)
