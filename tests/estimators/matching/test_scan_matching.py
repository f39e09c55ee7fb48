"""Local surface fits of the scan matchers' reference maps: denoised anchors and normals on
noisy walls and curved surfaces, checked against the true geometry, and the compiled fits
against the array form of the same math, the compiled voxel thinning against np.unique."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from estimators.matching.nearest import PointIndex
from estimators.matching.scan_matching import estimate_normals, fit_local_curves, voxel_downsample
from lidar_env.core.errors import ConfigError


def _noisy(points: np.ndarray, normals: np.ndarray, sigma: float, seed: int) -> np.ndarray:
    """``points`` moved along their true ``normals`` by Gaussian range noise ``sigma`` [m]."""
    rng = np.random.default_rng(seed)
    return points + sigma * rng.standard_normal(len(points))[:, None] * normals


def test_anchors_on_a_noisy_wall_average_the_noise_away():
    # A 3 m wall (y = 0) sampled every 5 cm with 1 cm noise, like a voxel-thinned local map.
    x = np.arange(0.0, 3.0, 0.05)
    wall = np.column_stack([x, np.zeros_like(x)])
    points = _noisy(wall, np.tile([0.0, 1.0], (len(x), 1)), 0.01, seed=0)
    normals, valid, anchors = fit_local_curves(points, PointIndex(points))
    inner = slice(5, -5)  # away from the wall's ends, where the fit is one-sided
    assert np.all(valid)
    raw_error = np.sqrt(np.mean(points[inner, 1] ** 2))
    anchor_error = np.sqrt(np.mean(anchors[inner, 1] ** 2))
    assert anchor_error < 0.75 * raw_error  # a parabola through 9 points: ~0.6 in theory
    # Anchors stay at their own place along the wall: the map keeps its sampling.
    np.testing.assert_allclose(anchors[:, 0], points[:, 0], atol=0.01)
    assert np.degrees(np.max(np.abs(np.arcsin(normals[inner, 0])))) < 5.0


def test_anchors_on_a_small_cylinder_are_not_pulled_to_its_centre():
    # A 0.3 m radius cylinder sampled every 5 cm, like the map: a straight line through 9
    # neighbours (~0.4 m of arc) would put every anchor ~3 cm inside the surface.
    radius = 0.3
    angle = np.linspace(0.0, 2.0 * np.pi, int(2.0 * np.pi * radius / 0.05), endpoint=False)
    radial = np.column_stack([np.cos(angle), np.sin(angle)])
    for seed in range(3):
        points = _noisy(radius * radial, radial, 0.01, seed)
        normals, valid, anchors = fit_local_curves(points, PointIndex(points))
        assert np.all(valid)
        radial_error = np.linalg.norm(anchors, axis=1) - radius
        raw_error = np.linalg.norm(points, axis=1) - radius
        assert abs(np.mean(radial_error)) < 0.002
        assert np.sqrt(np.mean(radial_error**2)) < 0.75 * np.sqrt(np.mean(raw_error**2))
        # The normals follow the surface, not a chord.
        facing = np.abs(np.einsum("ij,ij->i", normals, radial))
        assert np.degrees(np.max(np.arccos(np.minimum(facing, 1.0)))) < 8.0


def test_corners_are_not_fitted_and_keep_their_raw_points():
    corner = np.array([[0.05 * i, 0.0] for i in range(10)]
                      + [[0.0, 0.05 * i] for i in range(1, 10)])
    tree = PointIndex(corner)
    normals, valid, anchors = fit_local_curves(corner, tree, k=9)
    line_normals, line_valid = estimate_normals(corner, tree, k=9)
    np.testing.assert_array_equal(valid, line_valid)
    np.testing.assert_array_equal(anchors[~valid], corner[~valid])
    assert not valid[0]  # the corner point itself: a blob, not a line


def _wall_band(sigma: float, seed: int, recess: float = 0.0) -> np.ndarray:
    """A 4 m wall (y = 0) seen in many noisy scans (``sigma`` [m] across it) and thinned on
    5 cm voxels like a local map; between x = 2 and 3 m it is set back by ``recess`` [m]."""
    rng = np.random.default_rng(seed)
    x = rng.uniform(0.0, 4.0, 3000)
    y = np.where((x > 2.0) & (x < 3.0), recess, 0.0) + sigma * rng.standard_normal(len(x))
    return voxel_downsample(np.column_stack([x, y]), 0.05)


def test_a_noisy_wall_is_a_line_once_its_neighbourhoods_grow():
    # At 3 cm noise the thinned wall is a band 3-4 voxels thick: 9 neighbours span about as
    # much of it across as along, fail the line test, and would be paired on random lines.
    for seed in range(3):
        points = _wall_band(0.03, seed)
        tree = PointIndex(points)
        inner = (points[:, 0] > 0.5) & (points[:, 0] < 3.5)
        _, few = estimate_normals(points, tree, k=9)
        normals, grown = estimate_normals(points, tree, k=9, max_k=72)
        assert np.mean(few[inner]) < 0.2
        assert np.mean(grown[inner]) > 0.95
        tilt = np.degrees(np.arcsin(np.abs(normals[inner & grown, 0])))
        assert np.percentile(tilt, 95) < 5.0


def test_growing_does_not_smooth_a_recess_out_of_a_precise_wall():
    # A 10 cm recess (a doorway) in a 1 cm noise wall: its edges are what fixes the motion
    # along the wall, so they must stay "not a line" rather than be averaged into one.
    points = _wall_band(0.01, seed=0, recess=0.1)
    tree = PointIndex(points)
    _, valid = estimate_normals(points, tree, k=9)
    _, grown = estimate_normals(points, tree, k=9, max_k=72)
    edges = (np.abs(points[:, 0] - 2.0) < 0.08) | (np.abs(points[:, 0] - 3.0) < 0.08)
    assert np.mean(valid[edges]) < 0.5
    np.testing.assert_array_equal(grown[edges], valid[edges])


def test_anchors_match_a_parabola_fitted_point_by_point():
    # Independent oracle: per point, its 9 nearest neighbours by brute force, their principal
    # axis by eigh, and np.polyfit of the parabola in that axis' frame.
    radius = 1.0
    angle = np.arange(0.0, 2.0 * np.pi, 0.05 / radius)
    radial = np.column_stack([np.cos(angle), np.sin(angle)])
    points = _noisy(radius * radial, radial, 0.01, seed=4)
    normals, valid, anchors = fit_local_curves(points, PointIndex(points), k=9)
    assert np.mean(valid) > 0.9
    for i in np.flatnonzero(valid):
        neighbours = points[np.argsort(np.linalg.norm(points - points[i], axis=1))[:9]]
        mean = neighbours.mean(axis=0)
        normal = np.linalg.eigh(np.cov((neighbours - mean).T))[1][:, 0]
        tangent = np.array([normal[1], -normal[0]])
        along, across = (neighbours - mean) @ tangent, (neighbours - mean) @ normal
        c, b, _ = coefficients = np.polyfit(along, across, 2)
        s = (points[i] - mean) @ tangent
        expected = mean + s * tangent + np.polyval(coefficients, s) * normal
        np.testing.assert_allclose(anchors[i], expected, atol=1e-9)
        slope_normal = normal - (b + 2.0 * c * s) * tangent
        assert abs(normals[i] @ slope_normal) / np.linalg.norm(slope_normal) > 1.0 - 1e-9


def test_anchors_of_grown_neighbourhoods_average_a_noisy_wall():
    # Most of a 3 cm noise wall only forms lines through grown neighbourhoods (see above);
    # their anchors then average many readings: far closer to the wall than the raw points.
    points = _wall_band(0.03, seed=1)
    inner = (points[:, 0] > 0.5) & (points[:, 0] < 3.5)
    _, valid, anchors = fit_local_curves(points, PointIndex(points), k=9, max_k=72)
    assert np.mean(valid[inner]) > 0.95
    raw_error = np.sqrt(np.mean(points[inner, 1] ** 2))
    anchor_error = np.sqrt(np.mean(anchors[inner & valid, 1] ** 2))
    assert anchor_error < 0.3 * raw_error
    np.testing.assert_array_equal(anchors[~valid], points[~valid])


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31), noise=st.floats(0.0, 0.04), k=st.sampled_from([5, 9]),
       max_k=st.sampled_from([None, 18, 72]))
def test_compiled_fits_match_the_array_fits(seed: int, noise: float, k: int,
                                            max_k: int | None) -> None:
    """The numba line and parabola fits (estimators.matching.neighbourhood_fits) against the
    array form of the same math, on noisy walls, corners and a cylinder."""
    rng = np.random.default_rng(seed)
    s = np.linspace(0.0, 1.0, 80)
    angles = np.linspace(0.0, 2.0 * np.pi, 60, endpoint=False)
    points = np.concatenate([
        np.column_stack([4.0 * s, np.zeros_like(s)]),  # a wall
        np.column_stack([np.full_like(s, 4.0), 3.0 * s]),  # meeting another at a corner
        np.column_stack([2.0 + 0.3 * np.cos(angles), 1.5 + 0.3 * np.sin(angles)]),  # a post
        rng.uniform(-1.0, 5.0, (20, 2)),  # clutter
    ])
    points = voxel_downsample(points + rng.normal(0.0, noise, points.shape), 0.02)
    tree = PointIndex(points)
    compiled = fit_local_curves(points, tree, k, max_k=max_k)
    pure = fit_local_curves(points, tree, k, max_k=max_k, compiled=False)
    np.testing.assert_array_equal(compiled[1], pure[1])
    np.testing.assert_allclose(compiled[0], pure[0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(compiled[2], pure[2], rtol=0, atol=1e-9)
    normals, valid = estimate_normals(points, tree, k, max_k=max_k)
    pure_normals, pure_valid = estimate_normals(points, tree, k, max_k=max_k, compiled=False)
    np.testing.assert_array_equal(valid, pure_valid)
    np.testing.assert_allclose(normals, pure_normals, rtol=0, atol=1e-9)


def test_the_array_fits_take_any_tree_the_compiled_ones_a_point_index() -> None:
    x = np.arange(0.0, 1.0, 0.05)
    wall = np.column_stack([x, 0.01 * np.sin(7.0 * x)])
    pure = fit_local_curves(wall, cKDTree(wall), compiled=False)
    for expected, found in zip(pure, fit_local_curves(wall, PointIndex(wall)), strict=True):
        np.testing.assert_allclose(found, expected, rtol=0, atol=1e-9)
    with pytest.raises(ConfigError, match="PointIndex, got cKDTree"):
        fit_local_curves(wall, cKDTree(wall))


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31), n=st.integers(0, 3000), spread=st.floats(0.01, 1e4),
       voxel=st.floats(1e-3, 2.0), repeats=st.booleans())
def test_compiled_voxel_downsample_keeps_the_points_unique_keeps(
    seed: int, n: int, spread: float, voxel: float, repeats: bool,
) -> None:
    """The hash-set kernel keeps the same first point of every cell, in the same order, as
    ``np.unique`` does, on sparse, dense and repeated points, negative cells included."""
    rng = np.random.default_rng(seed)
    points = rng.uniform(-spread, spread, (n, 2))
    if repeats and n:
        points = points[rng.integers(0, n, n)]
    expected = voxel_downsample(points, voxel, compiled=False)
    np.testing.assert_array_equal(voxel_downsample(points, voxel), expected)
