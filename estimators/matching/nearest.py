"""Exact nearest-neighbour search in the plane, compiled: a hashed uniform grid.

:class:`GridIndex` answers the queries scan matching makes many times per scan -- the one or
two nearest reference points of every query point within a pairing distance -- with the same
answer as ``scipy.spatial.cKDTree.query(points, k, distance_upper_bound=...)`` (distances
``inf`` and index ``n`` where there is none), but in one compiled call without Python per
query: ICP asks for the nearest points of a few hundred queries 10-30 times per scan, and a
k-d tree's per-call set-up was most of that cost.

Points are sorted by their grid cell (side ``cell_size`` [m]); an open-addressing hash table
maps each occupied cell to its run of points, so memory and build time grow with the number
of points, not with the extent of the scan (a 100 m x 100 m real log's scan costs no more
than a 10 m one). A query visits rings of cells around its own, nearest first, and stops
when the next ring lies further than its k-th best candidate or the pairing distance: in
ICP, where the nearest point is usually a few centimetres away, that is one or two rings.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

#: Grid cell side [m] of a :class:`GridIndex` unless given: a few map voxels (0.05 m), so a
#: query's own ring of 3 x 3 cells usually holds its nearest points.
DEFAULT_CELL_SIZE = 0.1

_EMPTY = np.iinfo(np.int64).min
_OFFSET = np.int64(1) << 30


@njit(cache=True)
def _cell_key(ix: np.int64, iy: np.int64) -> np.int64:
    return ((ix + _OFFSET) << 32) | ((iy + _OFFSET) & 0xFFFFFFFF)


@njit(cache=True)
def _slot(key: np.int64, mask: np.int64) -> np.int64:
    mixed = np.uint64(key) * np.uint64(0x9E3779B97F4A7C15)
    return np.int64(mixed >> np.uint64(20)) & mask


@njit(cache=True)
def _build(points: NDArray[np.float64], cell: float) -> tuple[
    NDArray[np.int64], NDArray[np.float64], NDArray[np.int64], NDArray[np.int64],
    NDArray[np.int64],
]:
    """Points sorted by cell, their original indices, and the hash table of cell runs."""
    n = points.shape[0]
    keys = np.empty(n, np.int64)
    for i in range(n):
        keys[i] = _cell_key(np.int64(np.floor(points[i, 0] / cell)),
                            np.int64(np.floor(points[i, 1] / cell)))
    order = np.argsort(keys)
    sorted_points = np.empty((n, 2))
    for i in range(n):
        sorted_points[i, 0] = points[order[i], 0]
        sorted_points[i, 1] = points[order[i], 1]
    runs = 0
    for i in range(n):
        if i == 0 or keys[order[i]] != keys[order[i - 1]]:
            runs += 1
    size = 16
    while size < 2 * runs:
        size *= 2
    mask = np.int64(size - 1)
    table_keys = np.full(size, _EMPTY, np.int64)
    table_start = np.zeros(size, np.int64)
    table_end = np.zeros(size, np.int64)
    i = 0
    while i < n:
        key = keys[order[i]]
        j = i + 1
        while j < n and keys[order[j]] == key:
            j += 1
        slot = _slot(key, mask)
        while table_keys[slot] != _EMPTY:
            slot = (slot + 1) & mask
        table_keys[slot], table_start[slot], table_end[slot] = key, i, j
        i = j
    return order.astype(np.int64), sorted_points, table_keys, table_start, table_end


@njit(cache=True)
def _run(table_keys: NDArray[np.int64], table_start: NDArray[np.int64],
         table_end: NDArray[np.int64], ix: np.int64, iy: np.int64) -> tuple[int, int]:
    """The run ``[start, end)`` of sorted points in cell (ix, iy); empty when none."""
    key = _cell_key(ix, iy)
    mask = np.int64(len(table_keys) - 1)
    slot = _slot(key, mask)
    while table_keys[slot] != _EMPTY:
        if table_keys[slot] == key:
            return table_start[slot], table_end[slot]
        slot = (slot + 1) & mask
    return 0, 0


@njit(cache=True)
def search(
    order: NDArray[np.int64], sorted_points: NDArray[np.float64],
    table_keys: NDArray[np.int64], table_start: NDArray[np.int64],
    table_end: NDArray[np.int64], cell: float, qx: float, qy: float, k: int, bound: float,
) -> tuple[float, int, float, int]:
    """The squared distances and indices of the ``k`` (1 or 2) points nearest (qx, qy) with
    squared distance below ``bound``: ``(d0, i0, d1, i1)``, ``inf`` and ``n`` where there is
    none (``d1, i1`` stay so for ``k=1``). Equally distant points rank by index. The grid is
    the tuple a :class:`GridIndex` holds (``GridIndex.arrays``), for compiled callers."""
    n = sorted_points.shape[0]
    cx, cy = np.int64(np.floor(qx / cell)), np.int64(np.floor(qy / cell))
    best0, best1 = np.inf, np.inf
    at0, at1 = n, n
    rings = np.int64(np.ceil(np.sqrt(bound) / cell)) + 1
    for ring in range(rings + 1):
        # Every point of ring r lies more than (r - 1) cells from the query.
        reach = (ring - 1) * cell
        worst = min(best0 if k == 1 else best1, bound)
        if ring > 0 and reach * reach >= worst:
            break
        for ix in range(cx - ring, cx + ring + 1):
            gap_x = max(ix * cell - qx, qx - (ix + 1) * cell, 0.0)
            edge = ix == cx - ring or ix == cx + ring
            step = 1 if edge or ring == 0 else 2 * ring
            for iy in range(cy - ring, cy + ring + 1, step):
                gap_y = max(iy * cell - qy, qy - (iy + 1) * cell, 0.0)
                # A cell whose box lies further than the k-th best so far holds nothing.
                worst = min(best0 if k == 1 else best1, bound)
                if gap_x * gap_x + gap_y * gap_y >= worst:
                    continue
                start, end = _run(table_keys, table_start, table_end, ix, iy)
                for p in range(start, end):
                    dx = sorted_points[p, 0] - qx
                    dy = sorted_points[p, 1] - qy
                    d2 = dx * dx + dy * dy
                    original = order[p]
                    if d2 < best0 or (d2 == best0 and original < at0):
                        best1, at1 = best0, at0
                        best0, at0 = d2, original
                    elif k == 2 and (d2 < best1 or (d2 == best1 and original < at1)):
                        best1, at1 = d2, original
    if not best0 < bound:
        best0, at0 = np.inf, n
    if not best1 < bound:
        best1, at1 = np.inf, n
    return best0, at0, best1, at1


@njit(cache=True)
def _nearest(
    order: NDArray[np.int64], sorted_points: NDArray[np.float64],
    table_keys: NDArray[np.int64], table_start: NDArray[np.int64],
    table_end: NDArray[np.int64], cell: float, queries: NDArray[np.float64], k: int,
    max_distance: float,
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """``(M, k)`` distances and indices of each query's ``k`` (1 or 2) nearest points closer
    than ``max_distance``; ``inf`` and ``n`` where fewer exist (``cKDTree.query``'s answer)."""
    m = queries.shape[0]
    distances = np.empty((m, k))
    index = np.empty((m, k), np.int64)
    bound = max_distance * max_distance
    for q in range(m):
        d0, i0, d1, i1 = search(order, sorted_points, table_keys, table_start, table_end, cell,
                                queries[q, 0], queries[q, 1], k, bound)
        distances[q, 0], index[q, 0] = np.sqrt(d0), i0
        if k == 2:
            distances[q, 1], index[q, 1] = np.sqrt(d1), i1
    return distances, index


class GridIndex:
    """Points ``(N, 2)`` [m] indexed for exact nearest-neighbour queries (see the module)."""

    def __init__(self, points: ArrayLike, cell_size: float = DEFAULT_CELL_SIZE) -> None:
        self.points = np.ascontiguousarray(points, dtype=np.float64)
        if self.points.ndim != 2 or self.points.shape[1] != 2:
            raise ValueError(f"points: expected shape (N, 2), got {self.points.shape}")
        if not cell_size > 0:
            raise ValueError(f"cell_size: expected a positive size [m], got {cell_size}")
        self.cell_size = float(cell_size)
        self.n = len(self.points)
        self.arrays = (*_build(self.points, self.cell_size), self.cell_size)

    def query(
        self, queries: ArrayLike, k: int = 1, distance_upper_bound: float = np.inf
    ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """Distances and indices of the ``k`` (1 or 2) nearest points closer than
        ``distance_upper_bound`` [m] to each query ``(M, 2)``: shapes ``(M,)`` for ``k=1``,
        ``(M, 2)`` for ``k=2``; ``inf`` and ``N`` where there is none, as ``cKDTree.query``.
        Equally distant points are ranked by index."""
        if k not in (1, 2):
            raise ValueError(f"k: expected 1 or 2 neighbours, got {k}")
        if not distance_upper_bound < np.inf:
            raise ValueError("distance_upper_bound: expected a finite pairing distance [m], "
                             f"got {distance_upper_bound}")
        queries = np.ascontiguousarray(queries, dtype=np.float64).reshape(-1, 2)
        distances, index = _nearest(*self.arrays, queries, k,
                                    float(distance_upper_bound))
        return (distances[:, 0], index[:, 0]) if k == 1 else (distances, index)
