"""GraphSlam's step check (:meth:`GraphSlam._checked_step`): where walkers hide the walls
two keyframes share, a front-end step the keyframes' match agrees with within their
uncertainties is kept, and a turn the front end lost is replaced by the match."""

from __future__ import annotations

import numpy as np

from estimators import SensorSetup
from estimators.matching.point_to_line import PointToLineReference
from estimators.matching.scan_matching import scan_to_points
from estimators.slam.graph_slam import GraphSlam
from lidar_env.core.se2 import compose, relative
from lidar_env.sensors.lidar import cast_rays

ANGLES = 2 * np.pi * np.arange(360) / 360
MAX_RANGE = 12.0
WALLS = np.array([[0, 0, 20, 0], [20, 0, 20, 14], [20, 14, 0, 14], [0, 14, 0, 0],
                  [7, 0, 7, 3], [13, 14, 13, 11], [0, 7, 2.5, 7]], dtype=float)
PILLARS = np.array([[5, 10, 0.4], [15, 4, 0.3], [10, 7, 1.0], [16.5, 10.5, 0.25]])
PREVIOUS, CURRENT = np.array([6.0, 5.0, 0.3]), np.array([6.45, 5.2, 0.35])


def keyframe_points(pose: np.ndarray, walkers: np.ndarray, seed: int) -> np.ndarray:
    """Car-frame points (M, 2) of a scan at ``pose`` (3,) among the room's walls and pillars
    and the ``walkers`` (K, 3: x, y, radius [m]), 1 cm range noise."""
    ranges = cast_rays((np.vstack([PILLARS, walkers]), WALLS), pose[None], ANGLES, MAX_RANGE)[0]
    noisy = ranges + np.random.default_rng(seed).normal(0.0, 0.01, ranges.shape)
    return scan_to_points(np.where(ranges < MAX_RANGE, noisy, ranges), ANGLES, MAX_RANGE)


def checked(step: np.ndarray) -> tuple[GraphSlam, np.ndarray]:
    """A reset GraphSlam's check of the front-end ``step`` (3,) from PREVIOUS to CURRENT,
    with walkers around CURRENT that the previous keyframe did not see."""
    slam = GraphSlam()
    slam.reset(SensorSetup(np.zeros((1, 3)), ANGLES, MAX_RANGE), PREVIOUS)
    angles = CURRENT[2] + np.radians([30.0, 100.0, 160.0, 200.0, 250.0, 320.0])
    walkers = np.column_stack([CURRENT[0] + 0.8 * np.cos(angles),
                               CURRENT[1] + 0.8 * np.sin(angles), np.full(6, 0.25)])
    previous = keyframe_points(PREVIOUS, np.zeros((0, 3)), 0)
    points = keyframe_points(CURRENT, walkers, 1)
    reference = PointToLineReference.with_estimated_normals(
        previous, slam.loop_params.normal_neighbours, slam.loop_params.denoise_reference)
    return slam, slam._checked_step(reference, previous, points, step)


def test_a_step_the_match_agrees_with_is_kept() -> None:
    truth = relative(PREVIOUS, CURRENT)
    step = compose(truth, np.array([0.04, -0.02, np.radians(0.3)]))  # a few cm off
    slam, kept = checked(step)
    assert len(slam.step_checks) == 1  # the walkers hid enough walls to check the step
    _, share, result = slam.step_checks[0]
    assert share < slam.loop_params.min_quality and result.accepted
    assert np.array_equal(kept, step)


def test_a_lost_turn_is_replaced_by_the_match() -> None:
    truth = relative(PREVIOUS, CURRENT)
    step = compose(truth, np.array([0.0, 0.0, np.radians(-40.0)]))
    slam, kept = checked(step)
    assert len(slam.step_checks) == 1
    error = relative(truth, kept)
    assert np.hypot(error[0], error[1]) < 0.05 and abs(error[2]) < np.radians(1.0)
