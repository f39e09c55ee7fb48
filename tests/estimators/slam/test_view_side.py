"""Seen from behind: a match that lays one side of a shelf onto its other side is refused;
a revisit from the same side is not."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.matching.scan_matching import scan_to_points
from estimators.slam.loop_closure import LoopClosureParams, PlaceMap, verify_loop
from estimators.slam.view_side import far_side_pairs, far_side_share, without_far_side
from lidar_env.core import EstimatorInputError
from lidar_env.sensors.lidar import cast_rays

ANGLES = 2 * np.pi * np.arange(360) / 360
MAX_RANGE = 3.5
# a 3 m x 0.6 m shelf unit (south face y = 0, north face y = 0.6) and one post to its east
SHELF = (np.array([[2.6, 0.3, 0.1]]),
         np.array([[-1.5, 0, 1.5, 0], [1.5, 0, 1.5, 0.6], [1.5, 0.6, -1.5, 0.6],
                   [-1.5, 0.6, -1.5, 0]], dtype=float))


def points_at(pose: np.ndarray, seed: int) -> np.ndarray:
    ranges = cast_rays(SHELF, pose, ANGLES, MAX_RANGE)[0]
    noise = np.random.default_rng(seed).normal(0, 0.01, ranges.shape)
    return scan_to_points(np.where(ranges < MAX_RANGE, ranges + noise, ranges), ANGLES, MAX_RANGE)


SOUTH = np.array([0.0, -1.2, 0.0])  # the old place, in the south aisle
NORTH = np.array([0.0, 1.8, 0.0])  # the query, in the north aisle: 3 m from it


def test_the_far_side_of_a_shelf_is_told_from_a_revisit() -> None:
    place = PlaceMap(points_at(SOUTH, 0), LoopClosureParams())
    north = points_at(NORTH, 1)
    # the north face laid onto the south face: the query 0.6 m south of where it is
    alias = NORTH - SOUTH - np.array([0.0, 0.6, 0.0])
    assert far_side_share(place.reference, place.viewpoints, north, alias, 0.1) > 0.9
    revisit = np.array([0.4, -1.1, 0.2])
    same_side = points_at(revisit, 2)
    assert far_side_share(place.reference, place.viewpoints, same_side, revisit - SOUTH,
                          0.1) < 0.1
    with pytest.raises(EstimatorInputError, match="viewpoints"):
        far_side_share(place.reference, place.viewpoints[:-1], north, alias, 0.1)


def test_a_loop_match_onto_the_far_side_is_refused_with_a_reason() -> None:
    place = PlaceMap(points_at(SOUTH, 0), LoopClosureParams())
    north = points_at(NORTH, 1)
    guess = NORTH - SOUTH - np.array([0.1, 0.5, 0.0])  # the graph's estimate, drifted
    result = verify_loop(place, north, guess, 0.5, LoopClosureParams())
    assert not result.accepted and "seen from behind" in result.reason
    assert result.far_side > 0.9
    blind = verify_loop(place, north, guess, 0.5, LoopClosureParams(max_far_side=1.0))
    assert blind.accepted  # every other test passes: the side is what tells
    revisit = np.array([0.4, -1.1, 0.2])
    honest = verify_loop(place, points_at(revisit, 2), revisit - SOUTH + [0.2, 0.1, 0.0], 0.5)
    assert honest.accepted and honest.far_side < 0.1
    np.testing.assert_allclose(honest.pose[:2], (revisit - SOUTH)[:2], atol=0.03)


def test_points_on_the_far_side_are_left_out_and_the_rest_kept() -> None:
    place = PlaceMap(points_at(SOUTH, 0), LoopClosureParams())
    north = points_at(NORTH, 1)
    alias = NORTH - SOUTH - np.array([0.0, 0.6, 0.0])  # the north face on the south face
    counted, far = far_side_pairs(place.reference, place.viewpoints, north, alias, 0.1)
    kept = without_far_side(place.reference, place.viewpoints, north, alias, 0.1)
    assert far.sum() > 0.9 * counted.sum() > 0 and len(kept) == len(north) - far.sum()
    revisit = np.array([0.4, -1.1, 0.2])
    same_side = points_at(revisit, 2)
    kept = without_far_side(place.reference, place.viewpoints, same_side, revisit - SOUTH, 0.1)
    assert len(kept) > 0.95 * len(same_side)
