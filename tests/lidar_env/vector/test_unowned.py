"""The batched kernels read and write their arguments through views that own nothing
(:mod:`lidar_env.vector.unowned`): a view must be the array itself (same data, shape and strides,
writes landing in it) and the grid's fields must come through unchanged."""

from __future__ import annotations

import numpy as np
from numba import njit

from lidar_env.vector.unowned import unowned, unowned_grid, unowned_scene
from lidar_env.world.primitive_grid import build_grid


@njit(cache=True)
def _doubled_through_view(array: np.ndarray) -> np.ndarray:
    view = unowned(array)
    for i in range(view.shape[0]):
        for j in range(view.shape[1]):
            view[i, j] *= 2.0
    return view.copy()  # a copy owns its memory: safe to return


def test_an_unowned_view_is_the_array_itself() -> None:
    base = np.arange(24.0).reshape(4, 6)
    strided = base[::2, 1::2]  # not contiguous: the strides must come through
    expected = 2.0 * strided
    got = _doubled_through_view(strided)
    assert np.array_equal(got, expected)
    assert np.array_equal(strided, expected)  # written in place
    assert np.array_equal(base[1::2], np.arange(24.0).reshape(4, 6)[1::2])  # nothing else


@njit(cache=True)
def _grid_fields(grid: tuple) -> tuple:
    fields = unowned_grid(grid)
    return (fields[0], fields[1], fields[2], fields[3], fields[4], fields[5].copy(),
            fields[6].copy(), fields[7].copy(), fields[8].copy())


def test_an_unowned_grid_holds_the_grids_fields() -> None:
    rng = np.random.default_rng(0)
    circles = np.column_stack([rng.uniform(0, 10, (20, 2)), np.full(20, 0.3)])
    segments = rng.uniform(0, 10, (15, 4))
    grid = build_grid(circles, segments)
    for got, expected in zip(_grid_fields(tuple(grid)), grid, strict=True):
        assert np.array_equal(got, expected)


@njit(cache=True)
def _scene_fields(item: tuple) -> tuple:
    circles, segments, grid, waypoints, trace_arc = unowned_scene(item)
    return circles.copy(), segments.copy(), grid[5].copy(), waypoints.copy(), trace_arc.copy()


def test_an_unowned_scene_item_is_its_world_and_trace() -> None:
    rng = np.random.default_rng(1)
    circles = np.column_stack([rng.uniform(0, 10, (5, 2)), np.full(5, 0.3)])
    segments = rng.uniform(0, 10, (4, 4))
    grid = build_grid(circles, segments)
    waypoints = rng.uniform(0, 10, (6, 2))
    trace_arc = np.cumsum(rng.uniform(0, 1, 6))
    item = (circles, segments, grid, waypoints, trace_arc, np.zeros(4, np.uint64))
    got = _scene_fields(item)
    for array, expected in zip(got, (circles, segments, grid[5], waypoints, trace_arc),
                               strict=True):
        assert np.array_equal(array, expected)
