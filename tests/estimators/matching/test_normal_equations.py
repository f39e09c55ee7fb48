"""The compiled ICP iterations against the pure functions they replace: the normal equations
``J^T W J`` and ``-J^T W r`` built from ``correspond`` / ``project``, the Jacobian and the
robust weights agree to 1e-9 on random scans, poses and references of every kind, and so
does the whole compiled registration loop with its Python form."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from estimators.matching.curve_refinement import (
    INLIER_DISTANCE,
    LOSS_SCALE,
    MAX_PAIR_DISTANCE,
    CurveReference,
)
from estimators.matching.icp import ICPParams, register
from estimators.matching.normal_equations import fresh_neighbours, point_to_curve_system
from estimators.matching.point_to_line import (
    LOSSES,
    PointToLineReference,
    point_to_line_jacobian,
    robust_weights,
)
from lidar_env.core.se2 import transform_points


def _room_scan(rng: np.random.Generator, n_beams: int = 360, noise: float = 0.01) -> tuple:
    """Ranges [m] of a 6 m x 4 m room with a round pillar seen from near its centre."""
    angles = np.linspace(-np.pi, np.pi, n_beams, endpoint=False)
    direction = np.column_stack([np.cos(angles), np.sin(angles)])
    walls = np.minimum(np.abs(3.0 / np.where(direction[:, 0] == 0, 1e-9, direction[:, 0])),
                       np.abs(2.0 / np.where(direction[:, 1] == 0, 1e-9, direction[:, 1])))
    centre, radius = np.array([1.2, 0.4]), 0.3
    along = direction @ centre
    disc = along**2 - (centre @ centre - radius**2)
    pillar = np.where(disc > 0, along - np.sqrt(np.maximum(disc, 0.0)), np.inf)
    ranges = np.minimum(walls, np.where(pillar > 0, pillar, np.inf))
    ranges = ranges + noise * rng.standard_normal(n_beams)
    ranges[rng.random(n_beams) < 0.05] = 20.0  # some beams with no return
    return ranges, angles


def _room_reference(rng: np.random.Generator, kind: str) -> tuple:
    """A room scan's returns (N, 2), its beam angles and its reference of ``kind``."""
    ranges, angles = _room_scan(rng)
    hit = ranges < 20.0
    points = np.column_stack([ranges[hit] * np.cos(angles[hit]), ranges[hit] * np.sin(angles[hit])])
    reference = (PointToLineReference(points) if kind == "censi" else
                 PointToLineReference.with_estimated_normals(points, 9, kind == "denoised", 72))
    return points, angles, reference


def _pure_system(reference: PointToLineReference, query: np.ndarray, pose: np.ndarray,
                 max_distance: float, loss: str, scale: float):
    world = transform_points(pose, query)
    pairs = reference.correspond(world, max_distance)
    moved = world[pairs.index]
    residuals = np.einsum("ij,ij->i", moved - pairs.anchors, pairs.normals)
    jacobian = point_to_line_jacobian(moved, pose[:2], pairs.normals)
    weighted = jacobian * robust_weights(residuals, loss, scale)[:, None]
    per_point = np.full(len(query), np.nan)
    per_point[pairs.index] = residuals
    lever = np.sqrt(np.mean(jacobian[:, 2] ** 2)) if len(jacobian) else 0.0
    return weighted.T @ jacobian, -weighted.T @ residuals, len(pairs.index), lever, per_point


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**31), kind=st.sampled_from(["censi", "normals", "denoised"]),
    loss=st.sampled_from(LOSSES), scale=st.floats(0.01, 1.0),
    max_distance=st.floats(0.02, 2.0), shift=st.floats(-0.3, 0.3), turn=st.floats(-0.3, 0.3),
)
def test_point_to_line_normal_equations_match_the_pure_pairs(
    seed: int, kind: str, loss: str, scale: float, max_distance: float, shift: float,
    turn: float,
) -> None:
    rng = np.random.default_rng(seed)
    ranges, angles = _room_scan(rng)
    hit = ranges < 20.0
    points = np.column_stack([ranges[hit] * np.cos(angles[hit]), ranges[hit] * np.sin(angles[hit])])
    if kind == "censi":
        reference = PointToLineReference(points)
    else:
        reference = PointToLineReference.with_estimated_normals(
            points, k=9, denoise=kind == "denoised", max_k=36)
        assert not np.all(reference.valid_normals)  # both kinds of pairs are exercised
    query_ranges, _ = _room_scan(rng)
    keep = query_ranges < 20.0
    query = np.column_stack([query_ranges[keep] * np.cos(angles[keep]),
                             query_ranges[keep] * np.sin(angles[keep])])
    pose = np.array([shift, -0.5 * shift, turn])
    expected = _pure_system(reference, query, pose, max_distance, loss, scale)
    found = reference.normal_equations(query, pose, max_distance, loss, scale)
    np.testing.assert_allclose(found[0], expected[0], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(found[1], expected[1], rtol=1e-9, atol=1e-9)
    assert found[2] == expected[2]
    assert found[3] == pytest.approx(expected[3], rel=1e-9, abs=1e-12)
    np.testing.assert_allclose(found[4], expected[4], rtol=0, atol=1e-12)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31), shift=st.floats(-0.3, 0.3), turn=st.floats(-0.3, 0.3))
def test_point_to_curve_normal_equations_match_project(seed: int, shift: float,
                                                       turn: float) -> None:
    rng = np.random.default_rng(seed)
    reference = CurveReference(*_room_scan(rng), 20.0)
    query = CurveReference(*_room_scan(rng), 20.0).smoothed
    pose = np.array([shift, 0.3 * shift, turn])
    moved = transform_points(pose, query)
    # the pure pairs, from a k-d tree
    distance, nearest = cKDTree(reference.points).query(moved,
                                                        distance_upper_bound=MAX_PAIR_DISTANCE)
    index = np.flatnonzero(np.isfinite(distance))
    index = index[~reference.pointlike[nearest[index]]]
    k = nearest[index]
    found_index, found_k = reference.nearest_returns(moved)
    np.testing.assert_array_equal(found_index, index)
    np.testing.assert_array_equal(found_k, k)
    anchors, normals = reference.project(moved, index, k)
    residuals = np.einsum("ij,ij->i", moved[index] - anchors, normals)
    jacobian = point_to_line_jacobian(moved[index], pose[:2], normals)
    weighted = jacobian * robust_weights(residuals, "cauchy", LOSS_SCALE)[:, None]
    hessian, gradient, inliers = point_to_curve_system(
        moved, pose[:2], index, k, reference.points, reference.tangents, reference.normals,
        reference.a, reference.b, reference.c, LOSS_SCALE, INLIER_DISTANCE)
    np.testing.assert_allclose(hessian, weighted.T @ jacobian, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(gradient, -weighted.T @ residuals, rtol=1e-9, atol=1e-9)
    assert inliers == np.count_nonzero(np.abs(residuals) < INLIER_DISTANCE)


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**31), kind=st.sampled_from(["censi", "normals", "denoised"]),
    loss=st.sampled_from(LOSSES), with_prior=st.booleans(),
    min_information=st.sampled_from([0.0, 2.0, 1e6]), iterations=st.integers(1, 30),
    shift=st.floats(-0.2, 0.2), turn=st.floats(-0.2, 0.2),
)
def test_compiled_registration_matches_the_python_loop(
    seed: int, kind: str, loss: str, with_prior: bool, min_information: float,
    iterations: int, shift: float, turn: float,
) -> None:
    """``register`` in one numba call against its Python loop over the same steps."""
    rng = np.random.default_rng(seed)
    points, angles, reference = _room_reference(rng, kind)
    query_ranges, _ = _room_scan(rng)
    keep = query_ranges < 20.0
    query = np.column_stack([query_ranges[keep] * np.cos(angles[keep]),
                             query_ranges[keep] * np.sin(angles[keep])])
    params = ICPParams(max_iterations=iterations, loss=loss, min_information=min_information,
                       max_correspondence_distance=0.5)
    guess = np.array([shift, -shift, turn])
    prior = (guess + 0.01, np.array([0.4, 0.4, 0.04])) if with_prior else (None, None)
    found = register(reference, query, guess, params, *prior)
    expected = register(reference, query, guess, params, *prior, compiled=False)
    np.testing.assert_allclose(found.pose, expected.pose, rtol=0, atol=1e-9)
    assert (found.iterations, found.converged) == (expected.iterations, expected.converged)
    assert found.quality == expected.quality
    assert found.rmse == pytest.approx(expected.rmse, rel=1e-9)


def _same_match(found, expected) -> None:
    assert np.array_equal(found.pose, expected.pose)
    assert (found.iterations, found.converged) == (expected.iterations, expected.converged)
    assert (found.quality, found.rmse) == (expected.quality, expected.rmse)
    assert np.array_equal(found.information, expected.information)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31), kind=st.sampled_from(["censi", "normals", "denoised"]),
       shift=st.floats(-0.3, 0.3), turn=st.floats(-0.3, 0.3))
def test_registration_from_kept_neighbours_is_bit_identical(
    seed: int, kind: str, shift: float, turn: float,
) -> None:
    """ICP of a scan again from another start (its neighbours kept on the reference), of a
    subset of its points from their rows of those neighbours, and of another scan from the
    rows the last left, pairs and ends exactly as from no neighbours: the kept points only
    spare searches."""
    rng = np.random.default_rng(seed)
    points, angles, reference = _room_reference(rng, kind)
    query = points[rng.permutation(len(points))[: len(points) // 2]] + 0.01 * rng.standard_normal(
        (len(points) // 2, 2))
    params = ICPParams(max_correspondence_distance=0.5)
    register(reference, query, np.array([shift, -shift, turn]), params)
    kept, near = reference.neighbours_for(query)
    assert not np.isnan(kept[:, 0]).all()  # the first ICP left its neighbours
    start = np.array([-shift, 0.5 * shift, -turn])
    _same_match(register(reference, query, start, params),
                register(reference, query, start, params, neighbours=fresh_neighbours(len(query))))
    rows = np.flatnonzero(rng.random(len(query)) < 0.8)
    _same_match(register(reference, query[rows], start, params,
                         neighbours=(kept[rows], near[rows])),
                register(reference, query[rows], start, params,
                         neighbours=fresh_neighbours(len(rows))))
    # the next scan, another array, from the rows the last one left
    following = query[1:] + 0.02 * rng.standard_normal((len(query) - 1, 2))
    _same_match(register(reference, following, start, params),
                register(reference, following, start, params,
                         neighbours=fresh_neighbours(len(following))))
