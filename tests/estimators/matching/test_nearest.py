"""The compiled k-d tree against scipy's k-d tree and brute force: same neighbours, same
distances, the same "none within the bound" answer, on random and wall-like point sets."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from estimators.matching.nearest import (
    KEPT,
    STACK,
    PointIndex,
    kept_answer,
    search,
    search_from,
    search_near,
)


def _brute(points: np.ndarray, queries: np.ndarray, k: int, bound: float):
    """k nearest by exhaustive search, ties by index, ``inf``/``n`` beyond ``bound``."""
    d2 = ((queries[:, None, :] - points[None, :, :]) ** 2).sum(axis=2)
    d2 = np.hstack([d2, np.full((len(queries), k), np.inf)])  # fewer points than k
    order = np.lexsort((np.broadcast_to(np.arange(d2.shape[1]), d2.shape), d2), axis=1)[:, :k]
    best = np.take_along_axis(d2, order, axis=1)
    inside = best < bound**2
    return np.where(inside, np.sqrt(best), np.inf), np.where(inside, order, len(points))


def _walls(rng: np.random.Generator, n_walls: int = 12) -> np.ndarray:
    """Noisy points 5 cm apart along random segments: what a scan or a local map holds."""
    points = []
    for x1, y1, x2, y2 in rng.uniform(-8.0, 8.0, (n_walls, 4)):
        s = np.linspace(0.0, 1.0, max(int(np.hypot(x2 - x1, y2 - y1) / 0.05), 2))
        points.append(np.column_stack([x1 + s * (x2 - x1), y1 + s * (y2 - y1)]))
    points = np.concatenate(points)
    return points + rng.normal(0.0, 0.01, points.shape)


@pytest.mark.parametrize("bound", [0.05, 0.5, 1.0, 100.0])
def test_same_neighbours_and_distances_as_scipys_tree_on_walls(bound: float) -> None:
    rng = np.random.default_rng(1)
    points = _walls(rng)
    queries = points[rng.integers(0, len(points), 400)] + rng.normal(0.0, 0.1, (400, 2))
    tree, grid = cKDTree(points), PointIndex(points)
    for k in (1, 2, 9, 72):
        expected = tree.query(queries, k=k, distance_upper_bound=bound)
        found = grid.query(queries, k=k, distance_upper_bound=bound)
        np.testing.assert_array_equal(found[1], expected[1])
        np.testing.assert_allclose(found[0], expected[0], rtol=0, atol=1e-12)
        assert np.any(np.isinf(found[0])) or bound >= 0.5  # the bound is exercised


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(1, 300), m=st.integers(1, 30), seed=st.integers(0, 2**31),
    spread=st.floats(0.01, 200.0), bound=st.floats(1e-3, 50.0),
    k=st.sampled_from([1, 2, 3, 9, 40]), duplicates=st.booleans(),
)
def test_matches_brute_force_on_any_points(n: int, m: int, seed: int, spread: float,
                                           bound: float, k: int, duplicates: bool) -> None:
    rng = np.random.default_rng(seed)
    points = rng.uniform(-spread, spread, (n, 2))
    if duplicates:  # exact ties: ranked by index
        points[n // 2:] = points[: n - n // 2]
    queries = np.concatenate([rng.uniform(-spread, spread, (m, 2)), points[:m]])
    distances, index = PointIndex(points).query(queries, k=k, distance_upper_bound=bound)
    expected_distances, expected_index = _brute(points, queries, k, bound)
    np.testing.assert_array_equal(index.reshape(-1, k), expected_index)
    np.testing.assert_allclose(distances.reshape(-1, k), expected_distances, rtol=1e-12, atol=0)


@settings(max_examples=60, deadline=None)
@given(n=st.integers(1, 400), seed=st.integers(0, 2**31), levels=st.integers(1, 6),
       k=st.sampled_from([1, 2, 9, 40]))
def test_split_points_lie_on_their_side_even_when_coordinates_repeat(
        n: int, seed: int, levels: int, k: int) -> None:
    """Points on a coarse lattice (``levels`` values per axis: many equal coordinates, as a
    CARMEN log's centimetre ranges or an axis-aligned wall give): each split leaves no point
    of its first child beyond the second's on the split axis, the leaves hold every point once,
    and the answers are brute force's."""
    rng = np.random.default_rng(seed)
    points = rng.integers(0, levels, (n, 2)).astype(np.float64) * 0.05
    index = PointIndex(points)
    order, tree_points, start, end, child, box = index.arrays
    assert np.array_equal(np.sort(order), np.arange(n))
    np.testing.assert_array_equal(tree_points, points[order])
    for node in np.flatnonzero(child >= 0):
        first, second = child[node], child[node] + 1
        assert start[first] == start[node] and end[second] == end[node]
        assert end[first] == start[second] == (start[node] + end[node]) // 2
        left, right = tree_points[start[first]:end[first]], tree_points[start[second]:end[second]]
        assert np.any(left.max(axis=0) <= right.min(axis=0))
    queries = np.concatenate([points, rng.uniform(-0.05, 0.05 * levels, (20, 2))])
    distances, found = index.query(queries, k=k, distance_upper_bound=0.12)
    expected_distances, expected_index = _brute(points, queries, k, 0.12)
    np.testing.assert_array_equal(found.reshape(-1, k), expected_index)
    np.testing.assert_allclose(distances.reshape(-1, k), expected_distances, rtol=1e-12, atol=0)


def test_bad_arguments_are_named() -> None:
    grid = PointIndex(np.zeros((3, 2)))
    with pytest.raises(ValueError, match="k: expected a positive number"):
        grid.query(np.zeros((1, 2)), k=0, distance_upper_bound=1.0)
    with pytest.raises(ValueError, match="distance_upper_bound"):
        grid.query(np.zeros((1, 2)), distance_upper_bound=0.0)
    with pytest.raises(ValueError, match="points: expected shape"):
        PointIndex(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="points: expected shape"):
        PointIndex(np.zeros((0, 2)))


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(1, 200), seed=st.integers(0, 2**31), spread=st.floats(0.05, 20.0),
    step=st.floats(1e-4, 5.0), bound=st.floats(1e-3, 20.0), duplicates=st.booleans(),
)
def test_kept_neighbours_give_the_searchs_answer_as_queries_move(
    n: int, seed: int, spread: float, step: float, bound: float, duplicates: bool,
) -> None:
    """``search_near`` over queries that move as ICP's do (small steps, some large, some
    back onto a point) answers as a fresh ``search`` does, bit for bit, for one and two
    neighbours and any bound, and a seeded ``search_from`` too; so does ``kept_answer``
    wherever it says the kept points hold the answer."""
    rng = np.random.default_rng(seed)
    points = rng.uniform(-spread, spread, (n, 2))
    if duplicates:
        points[n // 2:] = points[: n - n // 2]
    index = PointIndex(points)
    m = 12
    queries = rng.uniform(-spread, spread, (m, 2))
    kept, near = np.full((m, 3 + 2 * KEPT), np.nan), np.empty((m, KEPT), np.int64)
    pending = np.empty(STACK, np.int64)
    for _ in range(15):
        queries = queries + rng.normal(0.0, step * rng.choice([0.01, 0.1, 1.0]), (m, 2))
        queries[rng.random(m) < 0.1] = points[rng.integers(0, n)]  # exactly on a point
        for row in range(m):
            qx, qy = queries[row]
            for k, b in ((1, bound**2), (2, bound**2), (2, (0.3 * bound) ** 2)):
                expected = search(*index.arrays, qx, qy, k, b, pending)
                *answer, holds = kept_answer(kept, near, row, qx, qy, k, b, n)
                if holds:
                    assert tuple(answer[: 2 * k]) == expected[: 2 * k]
                found = search_near(*index.arrays, points, qx, qy, k, b, pending, row, kept,
                                    near)
                assert found[: 2 * k] == expected[: 2 * k]
            fresh = search(*index.arrays, qx, qy, 3, bound**2, pending)
            seeds = search(*index.arrays, qx + step, qy, 3, np.inf, pending)
            moved = [(float(np.sum((points[i] - (qx, qy)) ** 2)) if i < n else np.inf, i)
                     for i in seeds[1::2]]
            ranked = [value for pair in sorted(moved, key=lambda pair: pair) for value in pair]
            assert search_from(*index.arrays, qx, qy, 3, bound**2, pending, *ranked) == fresh
