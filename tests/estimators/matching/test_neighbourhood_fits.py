"""The batched search of map points' neighbours against the tree's own query: the same
neighbours, in the same order, with the same squared distances, bit for bit."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from estimators.matching.nearest import PointIndex, _nearest
from estimators.matching.neighbourhood_fits import BATCH_SIZE, neighbours_of


def _walls(rng: np.random.Generator, n_walls: int, noise: float) -> np.ndarray:
    """Points 5 cm apart along random segments with ``noise`` [m]: what a local map holds."""
    points = []
    for x1, y1, x2, y2 in rng.uniform(-4.0, 4.0, (n_walls, 4)):
        s = np.linspace(0.0, 1.0, max(int(np.hypot(x2 - x1, y2 - y1) / 0.05), 2))
        points.append(np.column_stack([x1 + s * (x2 - x1), y1 + s * (y2 - y1)]))
    points = np.concatenate(points)
    return points + rng.normal(0.0, noise, points.shape)


def _assert_the_trees_answer(tree: PointIndex, positions: np.ndarray, k: int,
                             max_distance: float) -> None:
    squared, index = neighbours_of(tree.arrays, positions, k, max_distance)
    distances, expected = _nearest(*tree.arrays, tree.arrays[1][positions], k, max_distance)
    np.testing.assert_array_equal(index, expected)
    np.testing.assert_array_equal(np.sqrt(squared), distances)


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**31), n=st.integers(1, 400), walls=st.booleans(),
       duplicates=st.booleans(), spread=st.floats(0.01, 1e6), noise=st.floats(0.0, 0.05),
       k=st.sampled_from([1, 2, 5, 9, 18, 40]),
       max_distance=st.sampled_from([1e-3, 0.1, 0.5, 3.0, np.inf]),
       share=st.sampled_from([1.0, 0.5, 0.1]))
def test_the_points_neighbours_are_the_trees_answer_bit_for_bit(
    seed: int, n: int, walls: bool, duplicates: bool, spread: float, noise: float, k: int,
    max_distance: float, share: float,
) -> None:
    """Walls (dense, like a local map) and uniform points over any scale, exact repeats (ties
    ranked by index), fewer points than k, bounds that cut every neighbourhood short; all the
    points or a random share of them (the neighbourhoods that grow)."""
    rng = np.random.default_rng(seed)
    if walls:
        points = _walls(rng, 1 + n // 60, noise)
    else:
        points = rng.uniform(-spread, spread, (n, 2))
    if duplicates:
        points[len(points) // 2:] = points[: len(points) - len(points) // 2]
    positions = np.flatnonzero(rng.random(len(points)) < share)
    _assert_the_trees_answer(PointIndex(points), positions, k, max_distance)


def test_batches_cover_a_map_larger_than_one() -> None:
    points = _walls(np.random.default_rng(3), 20, 0.01)
    assert len(points) > 10 * BATCH_SIZE
    tree = PointIndex(points)
    _assert_the_trees_answer(tree, np.arange(len(points)), 9, 0.5)
    _assert_the_trees_answer(tree, np.arange(0, len(points), 7), 18, 0.5)
    _assert_the_trees_answer(tree, np.array([], np.int64), 9, 0.5)
