"""Loop-closure verification: descriptor invariance, exact branch-and-bound, recovered loop
poses on ray-cast scans (more accurate on a denoised place), rejection of wrong places with a
reason."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.matching.scan_matching import scan_to_points
from estimators.slam.loop_closure import (
    CorrelativeMatch,
    LoopClosureParams,
    PlaceMap,
    correlative_match,
    verify_loop,
)
from estimators.slam.place_descriptor import descriptor_distance, range_histogram
from lidar_env.core.se2 import relative, transform_points, wrap_angle
from lidar_env.sensors.lidar import cast_rays
from tests.estimators.room_scans import ANGLES, scan_points


def test_range_histogram_ignores_rotation_and_tells_places_apart() -> None:
    rng = np.random.default_rng(0)
    points = scan_points(np.array([3.0, 3.0, 0.0]), rng)
    turned = transform_points([0.0, 0.0, 1.3], points)
    np.testing.assert_allclose(range_histogram(turned), range_histogram(points), atol=1e-12)
    elsewhere = scan_points(np.array([13.0, 5.0, 0.0]), rng)
    nearby = scan_points(np.array([3.2, 3.1, 2.0]), rng)
    assert descriptor_distance(range_histogram(points), range_histogram(nearby)) < \
        descriptor_distance(range_histogram(points), range_histogram(elsewhere))
    assert range_histogram(points).sum() == pytest.approx(1.0)


def test_branch_and_bound_finds_the_exhaustive_optimum() -> None:
    rng = np.random.default_rng(1)
    params = LoopClosureParams(angular_window=np.radians(6.0))
    place = PlaceMap(scan_points(np.array([4.0, 3.0, 0.2]), rng), params)
    query = scan_points(np.array([4.3, 3.2, 0.3]), rng)[::4]
    guess = np.array([0.1, 0.0, 0.05])
    pose, score, _ = correlative_match(place, query, guess, 0.6, params)
    # oracle: every heading and every fine translation the window holds, scored directly
    best = -1.0
    step = (2 * params.coarse_factor + 1) * params.resolution
    reach = int(np.ceil(0.6 / step)) * step + params.coarse_factor * params.resolution
    offsets = params.resolution * np.arange(-round(reach / params.resolution),
                                            round(reach / params.resolution) + 1)
    for heading in guess[2] + params.angular_step * np.arange(-6, 7):
        c, s = np.cos(heading), np.sin(heading)
        rotated = query @ np.array([[c, s], [-s, c]]) + guess[:2]
        for dx in offsets:
            base = rotated + [dx, 0.0]
            scores = [place.field.score(base + [0.0, dy]).mean() for dy in offsets]
            best = max(best, max(scores))
    assert score == pytest.approx(best, abs=1e-12)
    assert place.field.score(transform_points(pose, query)).mean() == pytest.approx(score)


def test_verification_recovers_the_loop_pose() -> None:
    rng = np.random.default_rng(2)
    old, new = np.array([4.0, 3.0, 0.4]), np.array([4.6, 2.7, 2.2])
    place = PlaceMap(scan_points(old, rng), LoopClosureParams())
    truth = relative(old, new)
    guess = truth + np.array([0.5, -0.4, np.radians(9.0)])  # the drifted graph's belief
    result = verify_loop(place, scan_points(new, rng), guess, linear_window=1.0)
    assert result.accepted, result.reason
    assert np.hypot(*(result.pose[:2] - truth[:2])) < 0.02
    assert abs(wrap_angle(result.pose[2] - truth[2])) < np.radians(0.3)
    assert np.all(np.linalg.eigvalsh(result.information) > 0)
    assert result.quality > 0.9


def loop_errors(params: LoopClosureParams, noise: float, draws: int = 12) -> np.ndarray:
    """Position errors [m] of loop poses: a scan from a lane 1.5 m beside the old path
    matched against the old place as slam builds it (5 scans 0.5 m apart, exact poses)."""
    errors = []
    for seed in range(draws):
        rng = np.random.default_rng(seed)
        old = [np.array([3.0 + 0.5 * k, 2.5, 0.0]) for k in range(5)]
        points = np.concatenate([transform_points(relative(old[2], pose),
                                                  scan_points(pose, rng, noise))
                                 for pose in old])
        truth = relative(old[2], np.array([4.2 + 0.1 * seed, 4.0, 0.1]))
        result = verify_loop(PlaceMap(points, params),
                             scan_points(np.array([4.2 + 0.1 * seed, 4.0, 0.1]), rng, noise),
                             truth + np.array([0.1, -0.1, 0.03]), 0.5, params)
        assert result.accepted, result.reason
        errors.append(np.hypot(*(result.pose[:2] - truth[:2])))
    return np.array(errors)


def test_a_denoised_place_gives_more_accurate_loop_edges() -> None:
    """Lines through points moved onto the curve through their 9 neighbours carry less of
    the old scans' range noise into the loop pose than lines through raw readings (the
    error a loop edge adds to a good front end's map)."""
    raw = LoopClosureParams(normal_neighbours=5, denoise_reference=False)
    for noise in (0.01, 0.02):
        denoised = np.sqrt(np.mean(loop_errors(LoopClosureParams(), noise) ** 2))
        assert denoised < 0.9 * np.sqrt(np.mean(loop_errors(raw, noise) ** 2))
        assert denoised < 0.2 * noise


def test_a_different_place_fails_verification_with_a_reason() -> None:
    rng = np.random.default_rng(3)
    place = PlaceMap(scan_points(np.array([3.0, 2.0, 0.0]), rng), LoopClosureParams())
    # the other side of the inner wall: believed to be 0.5 m from the old place
    result = verify_loop(place, scan_points(np.array([12.5, 6.0, 0.0]), rng),
                         np.array([0.5, 0.0, 0.0]), linear_window=1.0)
    assert not result.accepted
    assert "ICP inlier share" in result.reason or "likelihood score" in result.reason
    few = verify_loop(place, np.zeros((4, 2)), np.zeros(3), 1.0)
    assert not few.accepted and "too few query points" in few.reason
    assert np.all(np.linalg.eigvalsh(result.information) > 0)  # measured by default
    unmeasured = verify_loop(place, scan_points(np.array([12.5, 6.0, 0.0]), rng),
                             np.array([0.5, 0.0, 0.0]), 1.0, measure_rejected=False)
    assert not unmeasured.accepted and not unmeasured.information.any()


def test_an_accepted_match_is_measured_either_way() -> None:
    rng = np.random.default_rng(2)
    old, new = np.array([4.0, 3.0, 0.4]), np.array([4.6, 2.7, 2.2])
    place = PlaceMap(scan_points(old, rng), LoopClosureParams())
    query, guess = scan_points(new, rng), relative(old, new) + np.array([0.3, -0.2, 0.1])
    measured = verify_loop(place, query, guess, 1.0)
    lean = verify_loop(place, query, guess, 1.0, measure_rejected=False)
    assert measured.accepted and lean.accepted
    np.testing.assert_array_equal(lean.information, measured.information)
    np.testing.assert_array_equal(lean.pose, measured.pose)


def test_corridor_match_carries_no_information_along_the_corridor() -> None:
    """Two long parallel walls fix the lateral offset and the heading, never the position
    along them: the loop edge's information matrix must say so."""
    walls = np.array([[-50, -1.5, 50, -1.5], [-50, 1.5, 50, 1.5]], dtype=float)
    ranges = cast_rays((np.zeros((0, 3)), walls), np.zeros(3), ANGLES, 8.0)[0]
    points = scan_to_points(ranges, ANGLES, 8.0)
    result = verify_loop(PlaceMap(points, LoopClosureParams()), points,
                         np.array([0.3, 0.1, 0.02]), linear_window=2.0)
    covariance = np.linalg.inv(result.information)
    assert np.sqrt(covariance[0, 0]) > 1.0  # along the corridor: metres of doubt
    assert np.sqrt(covariance[1, 1]) < 0.05  # across it: centimetres
    assert abs(result.pose[1]) < 0.01 and abs(result.pose[2]) < np.radians(0.2)


def test_a_noisy_place_still_has_wall_lines() -> None:
    # At 3 cm range noise 9 neighbours of a wall are a blob; grown neighbourhoods find the wall
    # (without them a third of the wall's points get a line, two thirds of those within 5 deg).
    rng = np.random.default_rng(5)
    origin = np.array([3.5, 3.0, 0.0])
    points = np.concatenate([
        transform_points(relative(origin, pose), scan_points(pose, rng, noise=0.03))
        for pose in (np.array([3.0 + 0.25 * i, 3.0, 0.0]) for i in range(5))])
    reference = PlaceMap(points, LoopClosureParams()).reference
    on_wall = np.abs(reference.points[:, 1] + origin[1]) < 0.15  # the wall y = 0
    valid = reference.valid_normals[on_wall]
    tilt = np.degrees(np.arccos(np.minimum(1.0, np.abs(reference.normals[on_wall, 1]))))
    assert valid.mean() > 0.8
    assert np.mean(tilt[valid] < 5.0) > 0.8


def test_bad_inputs_are_named() -> None:
    place = PlaceMap(scan_points(np.array([3.0, 3.0, 0.0]), np.random.default_rng(4)),
                     LoopClosureParams())
    with pytest.raises(ValueError, match=r"query points: expected shape \(M, 2\)"):
        verify_loop(place, np.zeros((10, 3)), np.zeros(3), 1.0)
    with pytest.raises(ValueError, match="guess: expected a finite pose"):
        verify_loop(place, np.zeros((10, 2)), np.zeros(2), 1.0)
    with pytest.raises(ValueError, match="linear_window"):
        verify_loop(place, np.zeros((10, 2)), np.zeros(3), -1.0)
    with pytest.raises(ValueError, match=r"min_quality: expected a share in \[0, 1\]"):
        LoopClosureParams(min_quality=1.5)
    with pytest.raises(ValueError, match="normal_neighbours: expected an integer >= 3"):
        LoopClosureParams(normal_neighbours=2)
    with pytest.raises(ValueError, match="max_normal_neighbours: expected None or at least"):
        LoopClosureParams(max_normal_neighbours=5)
    with pytest.raises(ValueError, match="loss_scale: expected a positive value"):
        LoopClosureParams(loss_scale=0.0)
    with pytest.raises(ValueError, match=r"reference points: expected shape \(N >= 3, 2\)"):
        PlaceMap(np.zeros((2, 2)), LoopClosureParams())


@pytest.mark.parametrize("ratio", [0.0, 0.5, 0.9, 0.99])
def test_the_pruned_ambiguity_search_makes_the_unpruned_ones_call(ratio: float) -> None:
    """The runner-up is searched only above ``ambiguity_ratio`` of the best: where the full
    search's share exceeds the ratio it is the same share, else 0."""
    from estimators.matching.branch_and_bound import match

    rng = np.random.default_rng(7)
    params = LoopClosureParams(angular_window=np.radians(4.0), ambiguity_ratio=ratio)
    for _ in range(4):
        place = PlaceMap(scan_points(np.array([4.0, 3.0, 0.2]), rng), params)
        query = scan_points(np.array([4.0, 3.0, 0.2]) + rng.normal(0, [0.3, 0.3, 0.05]),
                            rng)[::3]
        guess = rng.normal(0, [0.1, 0.1, 0.02])
        found = CorrelativeMatch(place, query, guess, 1.0, params)
        share = found.runner_up()
        # the unpruned search over the same far blocks
        n = found._n
        block = 2 * params.coarse_factor + 1
        shift = np.round((found.pose[:2] - guess[:2]) / params.resolution).astype(int)
        blocks = (np.arange(-n, n + 1) + params.coarse_factor) // block
        best_block = (shift + params.coarse_factor) // block
        far = np.hypot(block * (blocks[:, None] - best_block[0]),
                       block * (blocks[None, :] - best_block[1])) >= (
            params.ambiguity_distance / params.resolution + block)
        full = match(*found._window, -0.5, allowed=far).score / found.score
        if full > ratio:
            assert share == pytest.approx(full, abs=1e-12)
        else:
            assert share == 0.0
