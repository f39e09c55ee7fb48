"""Multi-resolution branch-and-bound: the exhaustive search's optimum on random grids (with
and without a mask of allowed translations), pooled levels against a direct maximum, the
stamped likelihood grid against the distance-transform field, a pair of scans 1.5 m and 45 deg
apart recovered, and no overlap reported as "not found"."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.matching.branch_and_bound import (
    GridPyramid,
    Match,
    levels_for_window,
    likelihood_grid,
    match,
    max_pool_levels,
    search_headings,
)
from estimators.matching.icp import register
from estimators.matching.point_to_line import PointToLineReference
from estimators.matching.scan_matching import LikelihoodField
from lidar_env.core.errors import ConfigError, EstimatorInputError
from lidar_env.core.se2 import relative, wrap_angle
from tests.estimators.room_scans import scan_points


def brute_force_match(
    pyramid: GridPyramid, points: np.ndarray, center: np.ndarray, linear_window: float,
    angular_window: float, angular_step: float,
) -> Match:
    """The exhaustive search :func:`match` must agree with: every heading and translation of
    the same window scored on the grid (level 0), in arrays."""
    points, center = np.asarray(points, dtype=np.float64), np.asarray(center, dtype=np.float64)
    n = int(np.ceil(linear_window / pyramid.resolution - 1e-9))
    headings = search_headings(center[2], angular_window, angular_step)
    cells = pyramid.cells(points, center, headings)  # (H, M, 2)
    grid = pyramid.levels[0]
    shifts = np.arange(-n, n + 1)
    i = cells[:, None, None, :, 0] + shifts[None, :, None, None]  # (H, S, 1, M)
    j = cells[:, None, None, :, 1] + shifts[None, None, :, None]  # (H, 1, S, M)
    i, j = np.broadcast_arrays(i, j)
    inside = (i >= 0) & (i < grid.shape[0]) & (j >= 0) & (j < grid.shape[1])
    values = np.where(inside, grid[np.where(inside, i, 0), np.where(inside, j, 0)], 0.0)
    scores = values.mean(axis=-1)  # (H, S, S)
    h, a, b = np.unravel_index(int(np.argmax(scores)), scores.shape)
    pose = np.array([center[0] + shifts[a] * pyramid.resolution,
                     center[1] + shifts[b] * pyramid.resolution, float(wrap_angle(headings[h]))])
    return Match(pose, float(scores[h, a, b]), True, int(scores.size))


@pytest.mark.parametrize("seed", range(6))
def test_branch_and_bound_finds_the_exhaustive_optimum_on_random_grids(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for _ in range(5):
        grid = rng.random((int(rng.integers(15, 50)), int(rng.integers(15, 50)))) ** 3
        resolution = 0.1
        pyramid = GridPyramid(grid, rng.normal(size=2), resolution, int(rng.integers(1, 7)))
        points = rng.normal(size=(int(rng.integers(1, 30)), 2)) * 1.5
        center = np.array([*(pyramid.origin + rng.random(2) * 4), rng.uniform(-3, 3)])
        linear = rng.uniform(0, 1.6)
        angular = rng.choice([rng.uniform(0, 0.6), np.pi])
        fast = match(pyramid, points, center, linear, angular, 0.07)
        slow = brute_force_match(pyramid, points, center, linear, angular, 0.07)
        assert fast.found
        assert fast.score == pytest.approx(slow.score, abs=1e-12)
        np.testing.assert_allclose(fast.pose, slow.pose, atol=1e-9)
        assert fast.nodes <= slow.nodes or slow.nodes < 50


def test_a_mask_of_allowed_translations_is_honoured_exactly() -> None:
    rng = np.random.default_rng(7)
    grid = rng.random((40, 40)) ** 3
    pyramid = GridPyramid(grid, (0.0, 0.0), 0.1, 4)
    points = rng.normal(size=(12, 2))
    center = np.array([2.0, 2.0, 0.3])
    best = brute_force_match(pyramid, points, center, 0.8, 0.2, 0.05)
    n = 8
    shift = np.round((best.pose[:2] - center[:2]) / 0.1).astype(int)
    di, dj = np.meshgrid(np.arange(-n, n + 1), np.arange(-n, n + 1), indexing="ij")
    allowed = np.hypot(di - shift[0], dj - shift[1]) >= 3  # away from the optimum
    masked = match(pyramid, points, center, 0.8, 0.2, 0.05, allowed=allowed)
    # oracle: the exhaustive scores of the allowed translations only
    headings = search_headings(center[2], 0.2, 0.05)
    cells = pyramid.cells(points, center, headings)
    margin = 30  # cells outside the grid score 0
    padded = np.pad(pyramid.levels[0], margin)
    top = -1.0
    for h in range(len(headings)):
        for a, b in zip(*np.nonzero(allowed), strict=True):
            i, j = cells[h, :, 0] + a - n + margin, cells[h, :, 1] + b - n + margin
            top = max(top, float(padded[i, j].mean()))
    assert masked.score == pytest.approx(top, abs=1e-12)
    assert masked.score < best.score
    assert np.hypot(*((masked.pose[:2] - best.pose[:2]) / 0.1)) >= 3 - 1e-9


def test_pooled_levels_hold_the_maximum_of_their_window() -> None:
    rng = np.random.default_rng(3)
    grid = rng.random((13, 9))
    levels = max_pool_levels(grid, 4)
    for level in range(4):
        width = 2**level
        for i in range(13):
            for j in range(9):
                assert levels[level, i, j] == grid[i:i + width, j:j + width].max()


def test_stamped_grid_matches_the_distance_transform_field_within_three_sigma() -> None:
    rng = np.random.default_rng(4)
    points = rng.uniform(0, 5, size=(60, 2))
    field = LikelihoodField(points, resolution=0.05, sigma=0.1)
    stamped = likelihood_grid(points, field.origin, field.grid.shape, 0.05, 0.1)
    near = field.grid >= np.exp(-4.5) + 1e-12  # within 3 sigma of a point's cell
    np.testing.assert_allclose(stamped[near], field.grid[near], atol=1e-12)
    assert np.all(stamped[~near] <= field.grid[~near] + 1e-12)


def test_a_scan_1_5_m_and_45_degrees_away_is_found_and_refined() -> None:
    rng = np.random.default_rng(5)
    first, second = np.array([4.0, 3.0, 0.3]), np.array([5.2, 3.9, 0.3 + np.radians(45)])
    reference_points = scan_points(first, rng)
    query = scan_points(second, rng)
    field = LikelihoodField(reference_points, resolution=0.05)
    window = 1.6  # the true step is 1.5 m, the heading 45 deg off the guess (no motion)
    pyramid = GridPyramid.from_field(field, levels_for_window(window, 0.05))
    found = match(pyramid, query, np.zeros(3), window, np.radians(60), np.radians(0.5))
    truth = relative(first, second)
    assert found.found
    assert np.hypot(*(found.pose[:2] - truth[:2])) < 0.1
    assert abs(wrap_angle(found.pose[2] - truth[2])) < np.radians(1.0)
    exhaustive = len(search_headings(0.0, np.radians(60), np.radians(0.5))) * (2 * 32 + 1) ** 2
    assert found.nodes < exhaustive / 100
    reference = PointToLineReference.with_estimated_normals(reference_points, 9, True, 72)
    refined = register(reference, query, found.pose)
    assert np.hypot(*(refined.pose[:2] - truth[:2])) < 0.02
    assert abs(wrap_angle(refined.pose[2] - truth[2])) < np.radians(0.3)


def test_a_scan_with_no_overlap_is_not_found() -> None:
    rng = np.random.default_rng(6)
    reference_points = scan_points(np.array([4.0, 3.0, 0.0]), rng)
    pyramid = GridPyramid.from_field(LikelihoodField(reference_points), 5)
    far_away = scan_points(np.array([4.0, 3.0, 0.0]), rng) + [100.0, 0.0]
    result = match(pyramid, far_away, np.zeros(3), 1.0, np.pi, np.radians(1.0), 0.05)
    assert not result.found and result.score == 0.0
    np.testing.assert_array_equal(result.pose, np.zeros(3))


def test_bad_input_is_refused_with_a_readable_error() -> None:
    pyramid = GridPyramid(np.ones((5, 5)), (0.0, 0.0), 0.1, 2)
    with pytest.raises(EstimatorInputError, match="points: expected shape"):
        match(pyramid, np.zeros((0, 2)), np.zeros(3), 0.5, 0.1, 0.01)
    with pytest.raises(EstimatorInputError, match="center: expected a finite pose"):
        match(pyramid, np.zeros((3, 2)), [0.0, np.nan, 0.0], 0.5, 0.1, 0.01)
    with pytest.raises(EstimatorInputError, match="allowed: expected shape"):
        match(pyramid, np.zeros((3, 2)), np.zeros(3), 0.5, 0.1, 0.01, allowed=np.ones((3, 3)))
    with pytest.raises(ConfigError, match="levels: expected an integer"):
        GridPyramid(np.ones((5, 5)), (0.0, 0.0), 0.1, 0)
    with pytest.raises(EstimatorInputError, match="grid: expected finite scores"):
        GridPyramid(-np.ones((5, 5)), (0.0, 0.0), 0.1, 2)
    with pytest.raises(ConfigError, match="angular_step"):
        match(pyramid, np.zeros((3, 2)), np.zeros(3), 0.5, 0.1, 0.0)


def test_four_node_scores_are_the_means_under_the_shifted_points() -> None:
    from estimators.matching.branch_and_bound import _cell_bounds, _square_scores

    rng = np.random.default_rng(3)
    for trial in range(100):
        # half the trials on grids large enough for the unchecked sums
        size = 30 if trial % 2 else 80
        grid = rng.random(tuple(int(k) for k in rng.integers(1, size, size=2)))
        cells = rng.integers(-10, 40, size=(3, int(rng.integers(1, 40)), 2))
        h, di, dj, width = int(rng.integers(3)), *(int(k) for k in rng.integers(-8, 8, 2)), \
            int(rng.choice([1, 2, 4, 8]))
        out = np.empty(4)
        _square_scores(grid, cells, _cell_bounds(cells), h, di, dj, width, out)
        for a in range(2):
            for b in range(2):
                i, j = cells[h, :, 0] + di + a * width, cells[h, :, 1] + dj + b * width
                inside = (i >= 0) & (i < grid.shape[0]) & (j >= 0) & (j < grid.shape[1])
                expected = np.where(inside, grid[np.where(inside, i, 0),
                                                 np.where(inside, j, 0)], 0.0).mean()
                assert out[2 * a + b] == pytest.approx(expected, abs=1e-12)
        bounds = _cell_bounds(cells)
        assert np.array_equal(bounds, np.column_stack([
            cells[..., 0].min(axis=1), cells[..., 0].max(axis=1),
            cells[..., 1].min(axis=1), cells[..., 1].max(axis=1)]))


@pytest.mark.parametrize("seed", range(4))
def test_a_kept_window_pools_exactly_the_padded_grid(seed: int) -> None:
    """A pyramid kept on a window holds what pooling the whole padded grid holds there."""
    rng = np.random.default_rng(seed)
    for _ in range(10):
        grid = rng.random((int(rng.integers(1, 40)), int(rng.integers(1, 40))))
        levels = int(rng.integers(1, 6))
        pad = 2 ** (levels - 1) - 1
        padded = np.zeros((grid.shape[0] + pad, grid.shape[1] + pad))
        padded[pad:, pad:] = grid
        r0 = int(rng.integers(0, padded.shape[0]))
        c0 = int(rng.integers(0, padded.shape[1]))
        r1 = int(rng.integers(r0 + 1, padded.shape[0] + 1))
        c1 = int(rng.integers(c0 + 1, padded.shape[1] + 1))
        pyramid = GridPyramid(grid, (0.0, 0.0), 0.1, levels, ((r0, r1), (c0, c1)))
        kept = padded[r0:r1, c0:c1]
        for level in range(levels):
            width = 2**level
            expected = np.array([[kept[i:i + width, j:j + width].max()
                                  for j in range(kept.shape[1])] for i in range(kept.shape[0])])
            np.testing.assert_array_equal(pyramid.levels[level], expected)
