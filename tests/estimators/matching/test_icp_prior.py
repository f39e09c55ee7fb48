"""The motion prior of ``icp.register`` as a full (3, 3) information matrix, and
``leaves_a_direction_free`` on a corridor and a corner."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.matching.icp import ICPParams, leaves_a_direction_free, register
from estimators.matching.point_to_line import PointToLineReference
from lidar_env.core.errors import EstimatorInputError
from lidar_env.core.se2 import transform_points


def _walls(corner: bool) -> np.ndarray:
    """Points (N, 2) [m] on two parallel walls 4 m apart (and, with ``corner``, an end wall)."""
    x = np.arange(0.0, 8.0, 0.05)
    points = [np.column_stack([x, np.full_like(x, y)]) for y in (-2.0, 2.0)]
    if corner:
        y = np.arange(-2.0, 2.0, 0.05)
        points.append(np.column_stack([np.full_like(y, 8.0), y]))
    return np.concatenate(points)


def test_a_full_prior_runs_the_same_compiled_and_in_python_and_a_diagonal_one_as_its_vector():
    reference = PointToLineReference.with_estimated_normals(_walls(corner=True), 9)
    truth = np.array([0.05, -0.03, 0.01])
    query = transform_points(-truth, _walls(corner=True))[::3]
    rng = np.random.default_rng(0)
    query = query + rng.normal(0, 0.01, query.shape)
    root = rng.normal(size=(3, 3))
    full = root @ root.T + np.eye(3)
    prior = np.array([0.02, 0.0, 0.0])
    params = ICPParams(min_information=2.0)
    compiled = register(reference, query, prior, params, prior, full)
    python = register(reference, query, prior, params, prior, full, compiled=False)
    np.testing.assert_allclose(compiled.pose, python.pose, atol=1e-9)
    diagonal = np.array([3.0, 5.0, 7.0])
    np.testing.assert_allclose(register(reference, query, prior, params, prior, diagonal).pose,
                               register(reference, query, prior, params, prior,
                                        np.diag(diagonal)).pose, atol=1e-12)


def test_a_prior_of_the_wrong_shape_is_named():
    reference = PointToLineReference(_walls(corner=True))
    with pytest.raises(EstimatorInputError, match=r"prior_information: expected shape \(3,\)"):
        register(reference, _walls(corner=True), np.zeros(3), ICPParams(), np.zeros(3),
                 np.eye(2))


def test_a_corridor_leaves_its_axis_free_and_a_corner_does_not():
    params = ICPParams(min_information=2.0)
    for corner, free in ((False, True), (True, False)):
        points = _walls(corner)
        reference = PointToLineReference.with_estimated_normals(points, 9)
        assert leaves_a_direction_free(reference, points[::2], np.zeros(3), params) is free
    assert not leaves_a_direction_free(reference, points, np.zeros(3), ICPParams())
