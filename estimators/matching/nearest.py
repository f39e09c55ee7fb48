"""Exact nearest-neighbour search in the plane, compiled: a k-d tree built and searched in numba.

:class:`PointIndex` answers the queries scan matching makes many times per scan -- the one or
two nearest reference points of every query point within a pairing distance, and the 9 to 72
nearest neighbours of every map point the local map's line fits need -- with the same answer
as ``scipy.spatial.cKDTree.query(points, k, distance_upper_bound=...)`` (distances ``inf`` and
index ``n`` where there is none) up to the order of equally distant points, which it ranks by
index (cKDTree's order among them is its heap's), and callable from compiled code
(:func:`search`): ICP asks for the nearest points of a few hundred queries 10-30 times per
scan, and from inside one numba loop each query costs no Python call.

The tree splits the longer side of each node's bounding box at the median until at most
``LEAF_SIZE`` points remain; a query descends nearest child first and skips every node whose
box lies further than its k-th best candidate or the pairing distance. ICP asks again for the
same query points after each small step: :func:`search_near` keeps each query's three nearest
points and answers from them while the triangle inequality says no other point can have come
nearer, and seeds the search with them where it cannot (the same answer, bit for bit; hallway
scans: half the queries after the first iteration need no search). A k-d tree rather than a
hashed uniform grid: on sparse scans, where the second-nearest point of a 1-degree scan of a
wall 5 m away is 10-20 cm off, a grid's many empty-cell look-ups cost more than the tree.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from lidar_env.core import ConfigError, EstimatorInputError

#: Points per leaf of the tree: about what a few cache lines hold.
LEAF_SIZE = 8
STACK = 128  # depth bound of a search: a median-split tree of n points is log2(n) deep
#: Nearest points :func:`search_near` keeps per query: one more than the two a pair needs, so
#: that a query that moved less than the gap to the third keeps its pair without a search.
KEPT = 3
#: [m] slack of :func:`search_near`'s reuse test for the rounding of its distances.
REUSE_MARGIN = 1e-9


@njit(cache=True)
def _select(order: NDArray[np.int64], tree_points: NDArray[np.float64], axis: int, lo: int,
            hi: int, kth: int) -> None:
    """Reorder ``order[lo:hi]`` and the rows of ``tree_points`` (the points in that order)
    in place so that no point before ``kth`` has a larger coordinate ``axis`` than any point
    from ``kth`` on (Hoare's selection with a median-of-three pivot: linear time, equal
    coordinates split evenly, no allocation; the points moved with their indices, where
    reading them through ``order`` cost a sixth of the build)."""
    left, right = lo, hi - 1
    while left < right:
        a = tree_points[left, axis]
        b = tree_points[(left + right) // 2, axis]
        c = tree_points[right, axis]
        pivot = max(min(a, b), min(max(a, b), c))
        i, j = left, right
        while i <= j:
            while i < hi and tree_points[i, axis] < pivot:
                i += 1
            while j >= lo and tree_points[j, axis] > pivot:
                j -= 1
            if i <= j:
                order[i], order[j] = order[j], order[i]
                tree_points[i, 0], tree_points[j, 0] = tree_points[j, 0], tree_points[i, 0]
                tree_points[i, 1], tree_points[j, 1] = tree_points[j, 1], tree_points[i, 1]
                i += 1
                j -= 1
        if kth <= j:
            right = j
        elif kth > i:
            left = i
        else:  # [lo, j] <= pivot, (j, i) == pivot, [i, hi) >= pivot: split anywhere in (j, i]
            return


@njit(cache=True)
def _build(points: NDArray[np.float64]) -> tuple[
    NDArray[np.int64], NDArray[np.float64], NDArray[np.int64], NDArray[np.int64],
    NDArray[np.int64], NDArray[np.float64],
]:
    """The tree: original index of each stored point, the points in tree order, each node's
    range of them ``[start, end)``, its first child (-1 for a leaf; the second is next to
    it) and its bounding box (min x, min y, max x, max y). Which of equally placed points goes
    to which side of a split changes no answer: every search ranks by distance, then index."""
    n = points.shape[0]
    order = np.arange(n)
    tree_points = points.copy()
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
        x0 = y0 = np.inf
        x1 = y1 = -np.inf
        for i in range(lo, hi):
            x, y = tree_points[i, 0], tree_points[i, 1]
            x0, y0, x1, y1 = min(x0, x), min(y0, y), max(x1, x), max(y1, y)
        box[node, 0], box[node, 1], box[node, 2], box[node, 3] = x0, y0, x1, y1
        if hi - lo <= LEAF_SIZE:
            continue
        axis = 0 if x1 - x0 >= y1 - y0 else 1
        middle = (lo + hi) // 2
        _select(order, tree_points, axis, lo, hi, middle)
        child[node] = nodes
        pending[top] = (nodes, lo, middle)
        pending[top + 1] = (nodes + 1, middle, hi)
        top += 2
        nodes += 2
    return order, tree_points, start[:nodes], end[:nodes], child[:nodes], box[:nodes]


@njit(cache=True)
def _box_gap(box: NDArray[np.float64], node: int, qx: float, qy: float) -> float:
    """Squared distance from (qx, qy) to the node's bounding box (0 inside it)."""
    dx = max(box[node, 0] - qx, qx - box[node, 2], 0.0)
    dy = max(box[node, 1] - qy, qy - box[node, 3], 0.0)
    return dx * dx + dy * dy


@njit(cache=True, inline="always")
def _push_children(box: NDArray[np.float64], first: int, qx: float, qy: float,
                   pending: NDArray[np.int64], top: int) -> int:
    """Push the children ``first`` and ``first + 1`` of a node onto ``pending`` above ``top``,
    the nearer one to (qx, qy) on top (searched first, it tightens the bound soonest); the
    new top."""
    if _box_gap(box, first, qx, qy) <= _box_gap(box, first + 1, qx, qy):
        pending[top], pending[top + 1] = first + 1, first
    else:
        pending[top], pending[top + 1] = first, first + 1
    return top + 2


@njit(cache=True, inline="always")
def _ranked(d2: float, original: int, best0: float, at0: int, best1: float, at1: int,
            best2: float, at2: int) -> tuple[float, int, float, int, float, int]:
    """The three best (squared distance, index) pairs with one more candidate ranked in:
    nearer first, equally distant ones by index."""
    if d2 < best0 or (d2 == best0 and original < at0):
        return d2, original, best0, at0, best1, at1
    if d2 < best1 or (d2 == best1 and original < at1):
        return best0, at0, d2, original, best1, at1
    if d2 < best2 or (d2 == best2 and original < at2):
        return best0, at0, best1, at1, d2, original
    return best0, at0, best1, at1, best2, at2


@njit(cache=True, inline="always")
def search_from(
    order: NDArray[np.int64], tree_points: NDArray[np.float64], start: NDArray[np.int64],
    end: NDArray[np.int64], child: NDArray[np.int64], box: NDArray[np.float64],
    qx: float, qy: float, k: int, bound: float, pending: NDArray[np.int64],
    best0: float, at0: int, best1: float, at1: int, best2: float, at2: int,
) -> tuple[float, int, float, int, float, int]:
    """The squared distances and indices of the ``k`` (1 to 3) points nearest (qx, qy) with
    squared distance below ``bound``: ``(d0, i0, d1, i1, d2, i2)``, ``inf`` and ``n`` where
    there is none (entries past the ``k``-th are not meaningful). Equally distant points rank
    by index. The tree is the tuple a :class:`PointIndex` holds (``PointIndex.arrays``), for
    compiled callers; ``pending`` is scratch space for the nodes still to visit, ``(STACK,)``,
    allocated once by the caller for all its queries (a fresh array per query cost a fifth of
    ICP's time).

    ``best0, at0, ...`` seed the search: distinct points ranked as :func:`_ranked` ranks them,
    with their squared distances to (qx, qy) (``inf`` and ``n`` for none), e.g. the nearest
    points of a query that has moved a little. The answer is the same; the closer the seeds,
    the more of the tree is skipped (a node whose box lies further than the ``k``-th best so
    far)."""
    n = tree_points.shape[0]
    pending[0] = 0
    top = 1
    while top > 0:
        top -= 1
        node = pending[top]
        worst = best0 if k == 1 else best1 if k == 2 else best2
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
                if d2 <= worst and original != at0 and original != at1 and original != at2:
                    best0, at0, best1, at1, best2, at2 = _ranked(
                        d2, original, best0, at0, best1, at1, best2, at2)
                    worst = best0 if k == 1 else best1 if k == 2 else best2
            continue
        top = _push_children(box, first, qx, qy, pending, top)
    if not best0 < bound:
        best0, at0 = np.inf, n
    if not best1 < bound:
        best1, at1 = np.inf, n
    if not best2 < bound:
        best2, at2 = np.inf, n
    return best0, at0, best1, at1, best2, at2


@njit(cache=True, inline="always")
def search(
    order: NDArray[np.int64], tree_points: NDArray[np.float64], start: NDArray[np.int64],
    end: NDArray[np.int64], child: NDArray[np.int64], box: NDArray[np.float64],
    qx: float, qy: float, k: int, bound: float, pending: NDArray[np.int64],
) -> tuple[float, int, float, int, float, int]:
    """:func:`search_from` without seeds: the ``k`` (1 to 3) nearest points of (qx, qy)."""
    n = tree_points.shape[0]
    return search_from(order, tree_points, start, end, child, box, qx, qy, k, bound, pending,
                       np.inf, n, np.inf, n, np.inf, n)


@njit(cache=True, inline="always")
def kept_answer(kept: NDArray[np.float64], near: NDArray[np.int64], row: int, qx: float,
                qy: float, k: int, bound: float, n: int,
                ) -> tuple[float, int, float, int, float, int, bool]:
    """The kept points of query ``row`` (:func:`search_near`'s ``kept`` and ``near``) ranked
    by their squared distance to where it stands now, (qx, qy): ``(d0, i0, d1, i1, d2, i2,
    holds)``, ``holds`` whether they answer :func:`search` (``k`` 1 or 2, ``bound``, ``n``
    points in the tree) by the triangle inequality, the answer then cut at the bound as
    :func:`search` cuts it. ICP asks it inline before it calls :func:`search_near`: a query
    the kept points answer then costs a few nanoseconds, where passing through
    :func:`search_near` with the tree's arrays cost about ten times that (half the time of
    an iteration)."""
    best0 = best1 = best2 = np.inf
    at0 = at1 = at2 = n
    for j in range(KEPT):  # a missing one's (or a never searched row's) NaN ranks nowhere
        dx = kept[row, 3 + 2 * j] - qx
        dy = kept[row, 4 + 2 * j] - qy
        best0, at0, best1, at1, best2, at2 = _ranked(
            dx * dx + dy * dy, near[row, j], best0, at0, best1, at1, best2, at2)
    ox, oy = qx - kept[row, 0], qy - kept[row, 1]
    last = best0 if k == 1 else best1
    # false for a never searched row (NaN)
    if np.sqrt(min(last, bound)) + np.sqrt(ox * ox + oy * oy) + REUSE_MARGIN <= kept[row, 2]:
        if not best0 < bound:
            best0, at0 = np.inf, n
        if not best1 < bound:
            best1, at1 = np.inf, n
        return best0, at0, best1, at1, np.inf, n, True
    return best0, at0, best1, at1, best2, at2, False


@njit(cache=True, inline="always")
def search_near(
    order: NDArray[np.int64], tree_points: NDArray[np.float64], start: NDArray[np.int64],
    end: NDArray[np.int64], child: NDArray[np.int64], box: NDArray[np.float64],
    points: NDArray[np.float64], qx: float, qy: float, k: int, bound: float,
    pending: NDArray[np.int64], row: int, kept: NDArray[np.float64], near: NDArray[np.int64],
) -> tuple[float, int, float, int, float, int]:
    """:func:`search` (``k`` 1 or 2) for query ``row`` of a set of queries asked again as they
    move (ICP's iterations), with the same answer, from the points last found nearest where
    they suffice.

    Each search of a query keeps its ``KEPT`` nearest points: their indices in ``near``
    (M, 3), ``n`` for none, and in ``kept`` (M, 9) where the query stood [m] (NaN: never
    searched), ``reach`` [m], the distance within which those were all the points (the
    third's distance; inf with fewer than three points in the tree), and their coordinates
    (NaN for none). A query that has moved ``m`` since lies at least ``reach - m`` from every
    other point (triangle inequality), so when its ``k``-th nearest kept point, or the bound
    where there is none, lies closer than that (by ``REUSE_MARGIN`` for rounding), the kept
    points hold the answer (:func:`kept_answer`): their distances are computed as
    :func:`search` computes them, so it is bit-identical. Else the query is searched again,
    seeded with them. ``points`` (N, 2) are the tree's points in their original order."""
    n = tree_points.shape[0]
    best0, at0, best1, at1, best2, at2, holds = kept_answer(kept, near, row, qx, qy, k, bound,
                                                            n)
    if holds:
        return best0, at0, best1, at1, best2, at2
    # seeded by the kept points (none before the first search): most of the tree is skipped;
    # not cut at the bound, so that a query with fewer than three points within it keeps a
    # reach past it (a reach capped at the bound fails the test after any move, and a tenth
    # of ICP's queries, those near no wall, would be searched again at every iteration)
    best0, at0, best1, at1, best2, at2 = search_from(
        order, tree_points, start, end, child, box, qx, qy, KEPT, np.inf, pending,
        best0, at0, best1, at1, best2, at2)
    kept[row, 0], kept[row, 1], kept[row, 2] = qx, qy, np.sqrt(best2)
    near[row, 0], near[row, 1], near[row, 2] = at0, at1, at2
    for j in range(KEPT):
        at = near[row, j]
        kept[row, 3 + 2 * j] = points[at, 0] if at < n else np.nan
        kept[row, 4 + 2 * j] = points[at, 1] if at < n else np.nan
    if not best0 < bound:  # the k nearest within the bound lead the nearest overall
        best0, at0 = np.inf, n
    if not best1 < bound:
        best1, at1 = np.inf, n
    if not best2 < bound:
        best2, at2 = np.inf, n
    return best0, at0, best1, at1, best2, at2


@njit(cache=True, inline="always")
def k_nearest(
    order: NDArray[np.int64], tree_points: NDArray[np.float64], start: NDArray[np.int64],
    end: NDArray[np.int64], child: NDArray[np.int64], box: NDArray[np.float64],
    qx: float, qy: float, k: int, bound: float, pending: NDArray[np.int64],
    best: NDArray[np.float64], at: NDArray[np.int64],
) -> None:
    """The ``k`` points nearest (qx, qy) with squared distance below ``bound``, written to
    ``best[:k]`` (squared distances, ascending) and ``at[:k]`` (indices), ``inf`` and ``n``
    where fewer exist; equally distant points ranked by index. The best so far are kept
    sorted, a candidate inserted in place. For compiled callers, as :func:`search`; ``best``
    and ``at`` are scratch of at least ``k`` entries, like ``pending``."""
    n = tree_points.shape[0]
    best[:k] = np.inf
    at[:k] = n
    pending[0] = 0
    top = 1
    while top > 0:
        top -= 1
        node = pending[top]
        gap = _box_gap(box, node, qx, qy)
        if gap > best[k - 1] or gap >= bound:  # ties with the k-th best still count
            continue
        first = child[node]
        if first >= 0:
            top = _push_children(box, first, qx, qy, pending, top)
            continue
        for p in range(start[node], end[node]):
            dx = tree_points[p, 0] - qx
            dy = tree_points[p, 1] - qy
            d2 = dx * dx + dy * dy
            original = order[p]
            if d2 > best[k - 1] or (d2 == best[k - 1] and original > at[k - 1]):
                continue
            rank = k - 1  # shift the farther ones down, the last one out
            while rank > 0 and (d2 < best[rank - 1] or (
                    d2 == best[rank - 1] and original < at[rank - 1])):
                best[rank], at[rank] = best[rank - 1], at[rank - 1]
                rank -= 1
            best[rank], at[rank] = d2, original
    for j in range(k):
        if not best[j] < bound:
            best[j], at[j] = np.inf, n


@njit(cache=True)
def _nearest(
    order: NDArray[np.int64], tree_points: NDArray[np.float64], start: NDArray[np.int64],
    end: NDArray[np.int64], child: NDArray[np.int64], box: NDArray[np.float64],
    queries: NDArray[np.float64], k: int, max_distance: float,
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """``(M, k)`` distances and indices of each query's ``k`` nearest points closer than
    ``max_distance`` (:func:`k_nearest`): ``cKDTree.query``'s answer."""
    squared = np.empty((queries.shape[0], k))
    index = np.empty((queries.shape[0], k), np.int64)
    pending = np.empty(STACK, np.int64)
    for q in range(queries.shape[0]):
        k_nearest(order, tree_points, start, end, child, box, queries[q, 0], queries[q, 1], k,
                  max_distance * max_distance, pending, squared[q], index[q])
    return np.sqrt(squared), index


class PointIndex:
    """Points ``(N, 2)`` [m] indexed for exact nearest-neighbour queries (see the module)."""

    def __init__(self, points: ArrayLike) -> None:
        self.points = np.ascontiguousarray(points, dtype=np.float64)
        if self.points.ndim != 2 or self.points.shape[1] != 2 or len(self.points) == 0:
            raise EstimatorInputError(
                f"points: expected shape (N >= 1, 2), got {self.points.shape}")
        self.n = len(self.points)
        self.arrays = _build(self.points)

    def query(
        self, queries: ArrayLike, k: int = 1, distance_upper_bound: float = np.inf
    ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """Distances and indices of the ``k`` nearest points closer than
        ``distance_upper_bound`` [m] to each query ``(M, 2)``: shapes ``(M,)`` for ``k=1``,
        ``(M, k)`` otherwise; ``inf`` and ``N`` where there is none, as ``cKDTree.query``.
        Equally distant points are ranked by index."""
        if isinstance(k, bool) or not isinstance(k, int | np.integer) or k < 1:
            raise ConfigError(f"k: expected a positive number of neighbours, got {k!r}")
        if not distance_upper_bound > 0:
            raise ConfigError("distance_upper_bound: expected a positive pairing distance "
                             f"[m], got {distance_upper_bound}")
        queries = np.ascontiguousarray(queries, dtype=np.float64).reshape(-1, 2)
        distances, index = _nearest(*self.arrays, queries, k, float(distance_upper_bound))
        return (distances[:, 0], index[:, 0]) if k == 1 else (distances, index)
