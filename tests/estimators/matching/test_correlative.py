"""The compiled correlative search against its array form, and that it finds a known pose."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from estimators.matching.correlative import correlative_search
from estimators.matching.scan_matching import LikelihoodField
from lidar_env.core.se2 import transform_points


def _room(rng: np.random.Generator) -> np.ndarray:
    """Points on the walls of a 6 x 4 m room with a post, 2 cm noise."""
    t = rng.uniform(0, 1, 400)
    walls = np.concatenate([np.column_stack([6 * t[:100], np.zeros(100)]),
                            np.column_stack([6 * t[100:200], np.full(100, 4.0)]),
                            np.column_stack([np.zeros(100), 4 * t[200:300]]),
                            np.column_stack([np.full(100, 6.0), 4 * t[300:]])])
    angles = rng.uniform(0, 2 * np.pi, 40)
    post = np.column_stack([4 + 0.2 * np.cos(angles), 1.5 + 0.2 * np.sin(angles)])
    return np.concatenate([walls, post]) + 0.02 * rng.standard_normal((440, 2))


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), max_points=st.sampled_from([30, 90, 500]))
def test_the_compiled_search_returns_its_array_form_bit_for_bit(seed: int,
                                                                max_points: int) -> None:
    rng = np.random.default_rng(seed)
    world = _room(rng)
    field = LikelihoodField(world, resolution=rng.choice([0.03, 0.05, 0.1]))
    pose = np.array([rng.uniform(1, 5), rng.uniform(1, 3), rng.uniform(-np.pi, np.pi)])
    points = transform_points(np.array([-pose[0], -pose[1], 0.0]), world)  # arbitrary frame
    points = rng.permutation(points)[:200]
    center = pose + rng.normal(0, [0.2, 0.2, 0.2])
    fast = correlative_search(field, points, center, 0.4, np.radians(15), max_points=max_points)
    slow = correlative_search(field, points, center, 0.4, np.radians(15), max_points=max_points,
                              compiled=False)
    np.testing.assert_array_equal(fast[0], slow[0])
    assert fast[1] == slow[1]


def test_it_finds_the_pose_a_scan_was_taken_at() -> None:
    rng = np.random.default_rng(3)
    world = _room(rng)
    true = np.array([2.5, 1.8, 0.3])
    c, s = np.cos(true[2]), np.sin(true[2])
    car = (world - true[:2]) @ np.array([[c, -s], [s, c]])  # world -> car frame
    field = LikelihoodField(world, resolution=0.05)
    found, score = correlative_search(field, car, true + [0.25, -0.2, np.radians(8)], 0.5,
                                      np.radians(20))
    assert np.abs(found[:2] - true[:2]).max() <= 0.05
    assert abs(found[2] - true[2]) <= np.radians(1.0)
    assert score > 0.8
