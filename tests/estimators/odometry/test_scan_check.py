"""The scan-to-scan check of ``lidar_odometry``'s map match: a poorly explained map match that
turns the car away from what the scans show is replaced by the map match from the
scan-to-scan pose; an agreeing or better-explained one stands."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.matching.icp import ICPParams, MatchResult, register
from estimators.matching.point_to_line import PointToLineReference
from estimators.odometry.scan_check import MIN_POINTS, check_against_scan, turn_between
from lidar_env.core.se2 import compose, relative

PARAMS = ICPParams(max_iterations=20, max_correspondence_distance=0.5)
NO_PRIOR = np.zeros(3)


def room() -> np.ndarray:
    """World points [m] of a 12 x 4 m corridor-like room with a box and a recess, 5 cm apart."""
    walls = []
    for (x0, y0), (x1, y1) in [((-6, -2), (6, -2)), ((6, -2), (6, 2)), ((6, 2), (-6, 2)),
                               ((-6, 2), (-6, -2)), ((1, -2), (1, -1.2)), ((1, -1.2), (1.6, -1.2)),
                               ((1.6, -1.2), (1.6, -2)), ((-2, 2), (-2, 1.5)),
                               ((-2, 1.5), (-1.2, 1.5))]:
        n = int(np.hypot(x1 - x0, y1 - y0) / 0.05) + 1
        walls.append(np.column_stack([np.linspace(x0, x1, n), np.linspace(y0, y1, n)]))
    return np.concatenate(walls)


def scan(world: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """The points a front 180-degree Lidar at ``pose`` sees (car frame, no occlusion)."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    shifted = world - pose[:2]
    car = np.column_stack([c * shifted[:, 0] + s * shifted[:, 1],
                           -s * shifted[:, 0] + c * shifted[:, 1]])
    return car[(car[:, 0] > 0) & (np.hypot(car[:, 0], car[:, 1]) < 8.0)]


@pytest.fixture(scope="module")
def scene():
    world = room()
    previous_pose = np.array([-3.0, 0.2, 0.1])
    increment = np.array([0.2, 0.0, np.radians(12.0)])  # a fast turn's scan interval
    pose = compose(previous_pose, increment)
    reference = PointToLineReference.with_estimated_normals(world, 9)
    return world, reference, previous_pose, pose, scan(world, previous_pose), scan(world, pose)


def test_a_poor_flipped_map_match_gives_way_to_the_scans_turn(scene) -> None:
    _, reference, previous_pose, pose, previous_points, points = scene
    flipped = MatchResult(compose(pose, np.array([0.0, 0.0, np.pi])), 0.3, 0.02, 5, True)
    guess = compose(previous_pose, np.array([0.2, 0.0, 0.0]))  # the turn not yet in the model
    checked = check_against_scan(flipped, reference, points, previous_points, previous_pose,
                                 np.array([0.2, 0.0, 0.0]), PARAMS, guess, NO_PRIOR, 0.5)
    assert checked.replaced
    assert checked.scan_match is not None and checked.scan_match.quality > 0.9
    error = relative(pose, checked.result.pose)
    assert np.hypot(error[0], error[1]) < 0.02 and abs(error[2]) < np.radians(0.5)


def test_an_agreeing_map_match_stands_as_it_is(scene) -> None:
    _, reference, previous_pose, pose, previous_points, points = scene
    result = register(reference, points, pose, PARAMS)
    checked = check_against_scan(result, reference, points, previous_points, previous_pose,
                                 np.zeros(3), PARAMS, pose, NO_PRIOR, 0.5)
    assert checked.result is result and not checked.replaced
    assert abs(turn_between(previous_pose, result.pose) - checked.scan_match.pose[2]) < 0.01


def test_a_map_match_explaining_more_than_the_scan_match_stands(scene) -> None:
    _, reference, previous_pose, pose, previous_points, points = scene
    # the map explains every point of a pose 20 degrees off: the scans' 90 % do not overrule it
    confident = MatchResult(compose(pose, np.array([0.0, 0.0, np.radians(20.0)])), 1.0, 0.01, 3,
                            True)
    checked = check_against_scan(confident, reference, points, previous_points, previous_pose,
                                 np.zeros(3), PARAMS, pose, NO_PRIOR, 0.5)
    assert checked.result is confident and not checked.replaced


def test_too_few_points_on_the_previous_scan_skip_the_check(scene) -> None:
    _, reference, previous_pose, pose, previous_points, points = scene
    flipped = MatchResult(compose(pose, np.array([0.0, 0.0, np.pi])), 0.3, 0.02, 5, True)
    for previous in (None, previous_points[: MIN_POINTS - 1]):
        checked = check_against_scan(flipped, reference, points, previous, previous_pose,
                                     np.zeros(3), PARAMS, pose, NO_PRIOR, 0.5)
        assert checked.result is flipped and checked.scan_match is None and not checked.replaced
