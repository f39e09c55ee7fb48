"""The SE(2) hand-eye solution against motions built from a known mount (the oracle:
``B = X^-1 A X`` exactly), with noise, and on a drive without rotation."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.calibration.hand_eye import interval_motions, solve_hand_eye
from lidar_env.core.errors import EstimatorInputError
from lidar_env.core.se2 import compose, inverse

MOUNT = np.array([-0.42, 0.17, 2.3])


def car_path(rng: np.random.Generator, n: int, turn: float) -> np.ndarray:
    """``(n, 3)`` poses of a car driving forward ~0.1 m per step, turning up to ``turn`` rad."""
    poses = [np.zeros(3)]
    for _ in range(n - 1):
        step = np.array([0.1 + 0.02 * rng.standard_normal(), 0.0, turn * rng.uniform(-1, 1)])
        poses.append(compose(poses[-1], step))
    return np.array(poses)


def sensor_motions(car: np.ndarray, mount: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Motions of a sensor at the origin of the car and of one at ``mount`` (windows 1, 5)."""
    sensor_k = np.array([compose(p, mount) for p in car])
    return interval_motions(car, (1, 5)), interval_motions(sensor_k, (1, 5))


def test_exact_motions_give_the_mount() -> None:
    a, b = sensor_motions(car_path(np.random.default_rng(0), 200, 0.2), MOUNT)
    np.testing.assert_allclose(b[:, 2], a[:, 2], atol=1e-12)  # yaw increments agree
    solution = solve_hand_eye(a, b, guess=MOUNT + [0.3, -0.2, 0.35])
    np.testing.assert_allclose(solution.mount, MOUNT, atol=1e-9)
    assert solution.unobservable == ()
    assert solution.residual_rms < 1e-9


def test_noisy_motions_stay_within_their_stated_uncertainty() -> None:
    rng = np.random.default_rng(1)
    a, b = sensor_motions(car_path(rng, 400, 0.2), MOUNT)
    noise = np.array([0.003, 0.003, 0.001])
    a = a + noise * rng.standard_normal(a.shape)
    b = b + noise * rng.standard_normal(b.shape)
    solution = solve_hand_eye(a, b)
    error = solution.mount - MOUNT
    assert np.all(np.abs(error) < 4 * solution.std)
    assert np.all(solution.std < [0.005, 0.005, np.radians(0.2)])
    assert solution.yaw_mismatch_rms == pytest.approx(np.sqrt(2) * 0.001, rel=0.2)


def test_a_drive_without_rotation_gives_the_heading_but_no_lever_arm() -> None:
    a, b = sensor_motions(car_path(np.random.default_rng(2), 100, 0.0), MOUNT)
    guess = np.array([0.0, 0.0, 0.0])
    solution = solve_hand_eye(a, b, guess=guess)
    assert solution.unobservable == ("x", "y")
    np.testing.assert_array_equal(solution.mount[:2], guess[:2])  # the guess, not an estimate
    assert np.all(np.isinf(solution.std[:2]))
    assert solution.mount[2] == pytest.approx(MOUNT[2], abs=1e-9)


def test_bad_motion_arrays_are_refused() -> None:
    with pytest.raises(EstimatorInputError, match="motions: expected two"):
        solve_hand_eye(np.zeros((5, 3)), np.zeros((4, 3)))
    with pytest.raises(EstimatorInputError, match="M >= 3"):
        solve_hand_eye(np.zeros((2, 3)), np.zeros((2, 3)))


def test_inverse_roles_give_the_inverse_mount() -> None:
    """Calibrating Lidar 1 against Lidar k gives X^-1: an oracle independent of the solver."""
    a, b = sensor_motions(car_path(np.random.default_rng(3), 150, 0.2), MOUNT)
    np.testing.assert_allclose(solve_hand_eye(b, a).mount, inverse(MOUNT), atol=1e-9)
