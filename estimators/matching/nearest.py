"""Exact nearest-neighbour search in the plane, compiled: a k-d tree built and searched in numba.

:class:`PointIndex` answers the queries scan matching makes many times per scan -- the one or
two nearest reference points of every query point within a pairing distance -- with the same
answer as ``scipy.spatial.cKDTree.query(points, k, distance_upper_bound=...)`` (distances
``inf`` and index ``n`` where there is none; equally distant points ranked by index), but
callable from compiled code (:func:`search`): ICP asks for the nearest points of a few hundred
queries 10-30 times per scan, and from inside one numba loop each query costs no Python call.

The tree splits the longer side of each node's bounding box at the median until at most
``LEAF_SIZE`` points remain; a query descends nearest child first and skips every node whose
box lies further than its k-th best candidate or the pairing distance. (A hashed uniform grid
was tried first: on sparse scans, where the second-nearest point of a 1-degree scan of a
wall 5 m away is 10-20 cm off, its many empty-cell look-ups cost more than scipy's tree.)
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

#: Points per leaf of the tree: about what a few cache lines hold.
LEAF_SIZE = 8
STACK = 128  # depth bound of a search: a median-split tree of n points is log2(n) deep


@njit(cache=True)
def _build(points: NDArray[np.float64]) -> tuple[
    NDArray[np.int64], NDArray[np.float64], NDArray[np.int64], NDArray[np.int64],
    NDArray[np.int64], NDArray[np.float64],
]:
    """The tree: original index of each stored point, the points in tree order, each node's
    range of them ``[start, end)``, its first child (-1 for a leaf; the second is next to
    it) and its bounding box (min x, min y, max x, max y)."""
    n = points.shape[0]
    order = np.arange(n)
    capacity = 2 * n + 1
    start = np.empty(capacity, np.int64)
    end = np.empty(capacity, np.int64)
    child = np.full(capacity, -1, np.int64)
    box = np.empty((capacity, 4))
    pending = np.empty((STACK, 3), np.int64)
    pending[0] = (0, 0, n)
    top, nodes = 1, 1
    while top > 0:
        top -= 1
        node, lo, hi = pending[top]
        start[node], end[node] = lo, hi
        box[node] = (np.inf, np.inf, -np.inf, -np.inf)
        for i in range(lo, hi):
            x, y = points[order[i], 0], points[order[i], 1]
            box[node, 0], box[node, 1] = min(box[node, 0], x), min(box[node, 1], y)
            box[node, 2], box[node, 3] = max(box[node, 2], x), max(box[node, 3], y)
        if hi - lo <= LEAF_SIZE:
            continue
        axis = 0 if box[node, 2] - box[node, 0] >= box[node, 3] - box[node, 1] else 1
        members = order[lo:hi].copy()
        order[lo:hi] = members[np.argsort(points[members, axis], kind="mergesort")]
        middle = (lo + hi) // 2
        child[node] = nodes
        pending[top] = (nodes, lo, middle)
        pending[top + 1] = (nodes + 1, middle, hi)
        top += 2
        nodes += 2
    tree_points = np.empty((n, 2))
    for i in range(n):
        tree_points[i, 0], tree_points[i, 1] = points[order[i], 0], points[order[i], 1]
    return order, tree_points, start[:nodes], end[:nodes], child[:nodes], box[:nodes]


@njit(cache=True)
def _box_gap(box: NDArray[np.float64], node: int, qx: float, qy: float) -> float:
    """Squared distance from (qx, qy) to the node's bounding box (0 inside it)."""
    dx = max(box[node, 0] - qx, qx - box[node, 2], 0.0)
    dy = max(box[node, 1] - qy, qy - box[node, 3], 0.0)
    return dx * dx + dy * dy


@njit(cache=True)
def search(
    order: NDArray[np.int64], tree_points: NDArray[np.float64], start: NDArray[np.int64],
    end: NDArray[np.int64], child: NDArray[np.int64], box: NDArray[np.float64],
    qx: float, qy: float, k: int, bound: float, pending: NDArray[np.int64],
) -> tuple[float, int, float, int]:
    """The squared distances and indices of the ``k`` (1 or 2) points nearest (qx, qy) with
    squared distance below ``bound``: ``(d0, i0, d1, i1)``, ``inf`` and ``n`` where there is
    none (``d1, i1`` stay so for ``k=1``). Equally distant points rank by index. The tree is
    the tuple a :class:`PointIndex` holds (``PointIndex.arrays``), for compiled callers;
    ``pending`` is scratch space for the nodes still to visit, ``(STACK,)``, allocated once by
    the caller for all its queries (a fresh array per query cost a fifth of ICP's time)."""
    n = tree_points.shape[0]
    best0, best1 = np.inf, np.inf
    at0, at1 = n, n
    pending[0] = 0
    top = 1
    while top > 0:
        top -= 1
        node = pending[top]
        worst = best0 if k == 1 else best1
        # ties with the k-th best still count (ranked by index), points at the bound do not
        gap = _box_gap(box, node, qx, qy)
        if gap > worst or gap >= bound:
            continue
        first = child[node]
        if first < 0:
            for p in range(start[node], end[node]):
                dx = tree_points[p, 0] - qx
                dy = tree_points[p, 1] - qy
                d2 = dx * dx + dy * dy
                original = order[p]
                if d2 < best0 or (d2 == best0 and original < at0):
                    best1, at1 = best0, at0
                    best0, at0 = d2, original
                elif k == 2 and (d2 < best1 or (d2 == best1 and original < at1)):
                    best1, at1 = d2, original
            continue
        # nearer child on top of the stack: searched first, it tightens the bound soonest
        if _box_gap(box, first, qx, qy) <= _box_gap(box, first + 1, qx, qy):
            pending[top], pending[top + 1] = first + 1, first
        else:
            pending[top], pending[top + 1] = first, first + 1
        top += 2
    if not best0 < bound:
        best0, at0 = np.inf, n
    if not best1 < bound:
        best1, at1 = np.inf, n
    return best0, at0, best1, at1


@njit(cache=True)
def _nearest(
    order: NDArray[np.int64], tree_points: NDArray[np.float64], start: NDArray[np.int64],
    end: NDArray[np.int64], child: NDArray[np.int64], box: NDArray[np.float64],
    queries: NDArray[np.float64], k: int, max_distance: float,
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """``(M, k)`` distances and indices of each query's ``k`` (1 or 2) nearest points closer
    than ``max_distance``; ``inf`` and ``n`` where fewer exist (``cKDTree.query``'s answer)."""
    m = queries.shape[0]
    distances = np.empty((m, k))
    index = np.empty((m, k), np.int64)
    bound = max_distance * max_distance
    pending = np.empty(STACK, np.int64)
    for q in range(m):
        d0, i0, d1, i1 = search(order, tree_points, start, end, child, box,
                                queries[q, 0], queries[q, 1], k, bound, pending)
        distances[q, 0], index[q, 0] = np.sqrt(d0), i0
        if k == 2:
            distances[q, 1], index[q, 1] = np.sqrt(d1), i1
    return distances, index


class PointIndex:
    """Points ``(N, 2)`` [m] indexed for exact nearest-neighbour queries (see the module)."""

    def __init__(self, points: ArrayLike) -> None:
        self.points = np.ascontiguousarray(points, dtype=np.float64)
        if self.points.ndim != 2 or self.points.shape[1] != 2 or len(self.points) == 0:
            raise ValueError(f"points: expected shape (N >= 1, 2), got {self.points.shape}")
        self.n = len(self.points)
        self.arrays = _build(self.points)

    def query(
        self, queries: ArrayLike, k: int = 1, distance_upper_bound: float = np.inf
    ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """Distances and indices of the ``k`` (1 or 2) nearest points closer than
        ``distance_upper_bound`` [m] to each query ``(M, 2)``: shapes ``(M,)`` for ``k=1``,
        ``(M, 2)`` for ``k=2``; ``inf`` and ``N`` where there is none, as ``cKDTree.query``.
        Equally distant points are ranked by index."""
        if k not in (1, 2):
            raise ValueError(f"k: expected 1 or 2 neighbours, got {k}")
        if not distance_upper_bound > 0:
            raise ValueError("distance_upper_bound: expected a positive pairing distance "
                             f"[m], got {distance_upper_bound}")
        queries = np.ascontiguousarray(queries, dtype=np.float64).reshape(-1, 2)
        distances, index = _nearest(*self.arrays, queries, k, float(distance_upper_bound))
        return (distances[:, 0], index[:, 0]) if k == 1 else (distances, index)
