"""Compiled per-point fits of a map's neighbourhoods: each point's nearest neighbours, the line
through them and the parabola in that line's frame, in one numba loop over the points.

The math is :func:`estimators.matching.scan_matching.fit_local_curves`'s array form (the
principal axis of the neighbours' covariance, the line test, the least-squares parabola
``t = a + b s + c s^2``), which ``tests/estimators/matching/test_scan_matching.py`` checks
these kernels against. The local map is refitted at every keyframe (thousands of points, up
to 72 neighbours each): fitting and growing each point's neighbourhood in one compiled pass
leaves no subsets or dispatches between the steps, and the points' neighbours are found a
batch of nearby points at a time (:func:`neighbours_of`: one tree search and one sort
of a few candidates per point, where a search per point ranks every point it meets; 0.55 ->
0.37 us per point for 9 neighbours on the hallway maps, the same answer bit for bit).

Arrays: ``tree`` is the tuple a :class:`estimators.matching.nearest.PointIndex` holds over
``points`` (N, 2) [m]; ``normals`` (N, 2), ``valid`` (N,) and ``anchors`` (N, 2) [m] are
written in place, row by row.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from estimators.matching.nearest import LEAF_SIZE, REUSE_MARGIN, STACK, PointIndex, k_nearest
from lidar_env.core import ConfigError

#: The tuple :attr:`estimators.matching.nearest.PointIndex.arrays`.
Tree = tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.int64], NDArray[np.int64],
             NDArray[np.int64], NDArray[np.float64]]


#: Most points of a node whose points are searched together by :func:`neighbours_of`.
BATCH_SIZE = 2 * LEAF_SIZE
#: A neighbourhood that is no line is fitted again through more points while it spreads across
#: no more than this many times the noise limit (twice the median spread of the first fits);
#: the grown line is kept only within the limit itself. In the band of a noisy wall, about 2 %
#: of the first fits spread just past the limit by chance (5 cm voxels, 1.5 cm range noise);
#: left as "no line", their two-nearest-point pairs lie across the band and pin the motion
#: along the wall with their noise (a TurtleBot down a depot's aisle drifted metres).
GROW_SPREAD = 1.5


@njit(cache=True, inline="always")
def _candidates(tree: Tree, x0: float, y0: float, x1: float, y1: float, reach: float,
                pending: NDArray[np.int64], xs: NDArray[np.float64], ys: NDArray[np.float64],
                index: NDArray[np.int64]) -> int:
    """Write the points within ``reach`` [m] of the box ``[x0, x1] x [y0, y1]`` [m] to ``xs``,
    ``ys`` (coordinates) and ``index`` (original indices); their number."""
    order, tree_points, start, end, child, box = tree
    reach2 = reach * reach
    count = 0
    pending[0] = 0
    top = 1
    while top > 0:
        top -= 1
        node = pending[top]
        dx = max(box[node, 0] - x1, x0 - box[node, 2], 0.0)
        dy = max(box[node, 1] - y1, y0 - box[node, 3], 0.0)
        if dx * dx + dy * dy > reach2:
            continue
        if child[node] >= 0:
            pending[top], pending[top + 1] = child[node], child[node] + 1
            top += 2
            continue
        for p in range(start[node], end[node]):
            x, y = tree_points[p, 0], tree_points[p, 1]
            dx, dy = max(x - x1, x0 - x, 0.0), max(y - y1, y0 - y, 0.0)
            xs[count], ys[count], index[count] = x, y, order[p]
            count += dx * dx + dy * dy <= reach2  # written anyway, kept or overwritten
    return count


@njit(cache=True)
def neighbours_of(tree: Tree, positions: NDArray[np.int64], k: int, max_distance: float,
                  ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """``(M, k)`` squared distances and indices of the ``k`` nearest points closer than
    ``max_distance`` [m] of the tree's own points at ``positions`` (M,) (in tree order,
    ascending): :func:`estimators.matching.nearest.k_nearest`'s answer for each (``inf`` and
    ``N`` where fewer exist, equally distant points ranked by index), bit for bit, with the
    tree searched about once per batch of them in one node of up to ``BATCH_SIZE`` points
    rather than once per point.

    The batch's first point is searched in the tree; its ``k``-th distance ``r`` bounds
    every other's by ``r`` plus its distance from it (triangle inequality), so the points
    within that reach of the batch's bounding box hold all their neighbours. Each further
    point keeps those no further than its own bound (the first point's, or the previous
    point's ``k``-th distance plus its distance from it, whichever is less) and sorts those
    few, where a search would rank every point it meets in the tree. Bounds carry a margin
    for rounding (:data:`estimators.matching.nearest.REUSE_MARGIN`, scaled by the
    coordinates)."""
    order, tree_points, start, end, child, box = tree
    n, m = tree_points.shape[0], positions.shape[0]
    bound = max_distance * max_distance
    squared = np.empty((m, k))
    index = np.empty((m, k), np.int64)
    pending = np.empty(STACK, np.int64)
    xs, ys, near = np.empty(n), np.empty(n), np.empty(n, np.int64)
    kept, kept_index = np.empty(max(n, k)), np.empty(max(n, k), np.int64)
    lo = 0  # the batch's first position in positions
    nodes = np.empty(STACK, np.int64)  # the largest nodes of at most BATCH_SIZE points
    nodes[0] = 0
    top = 1
    while top > 0 and lo < m:  # in tree order
        top -= 1
        node = nodes[top]
        if end[node] <= positions[lo]:
            continue
        if end[node] - start[node] > BATCH_SIZE:
            nodes[top], nodes[top + 1] = child[node] + 1, child[node]
            top += 2
            continue
        hi = lo
        x0 = y0 = np.inf
        x1 = y1 = -np.inf
        while hi < m and positions[hi] < end[node]:
            x, y = tree_points[positions[hi], 0], tree_points[positions[hi], 1]
            x0, y0, x1, y1 = min(x0, x), min(y0, y), max(x1, x), max(y1, y)
            hi += 1
        fx, fy = tree_points[positions[lo], 0], tree_points[positions[lo], 1]
        k_nearest(order, tree_points, start, end, child, box, fx, fy, k, bound, pending,
                  squared[lo], index[lo])
        if hi - lo > 1:
            margin = REUSE_MARGIN * (1.0 + max(abs(x0), abs(y0), abs(x1), abs(y1)))
            spread = 0.0
            for i in range(lo + 1, hi):
                x, y = tree_points[positions[i], 0], tree_points[positions[i], 1]
                spread = max(spread, np.sqrt((x - fx) ** 2 + (y - fy) ** 2))
            first_reach = np.sqrt(squared[lo, k - 1])  # inf where fewer than k
            reach = min(first_reach + spread, max_distance) + margin
            found = _candidates(tree, x0, y0, x1, y1, reach, pending, xs, ys, near)
            for i in range(lo + 1, hi):
                qx, qy = tree_points[positions[i], 0], tree_points[positions[i], 1]
                px, py = tree_points[positions[i - 1], 0], tree_points[positions[i - 1], 1]
                limit = min(first_reach + np.sqrt((qx - fx) ** 2 + (qy - fy) ** 2),
                            np.sqrt(squared[i - 1, k - 1])
                            + np.sqrt((qx - px) ** 2 + (qy - py) ** 2),
                            max_distance) + margin
                limit2 = limit * limit
                count = 0
                for c in range(found):
                    dx, dy = xs[c] - qx, ys[c] - qy
                    d2 = dx * dx + dy * dy  # as k_nearest computes it
                    kept[count], kept_index[count] = d2, near[c]
                    count += d2 <= limit2
                for c in range(1, count):  # nearer first, equally distant ones by index
                    d2, original = kept[c], kept_index[c]
                    j = c
                    while j > 0 and (d2 < kept[j - 1] or (
                            d2 == kept[j - 1] and original < kept_index[j - 1])):
                        kept[j], kept_index[j] = kept[j - 1], kept_index[j - 1]
                        j -= 1
                    kept[j], kept_index[j] = d2, original
                for j in range(k):
                    inside = j < count and kept[j] < bound
                    squared[i, j] = kept[j] if inside else np.inf
                    index[i, j] = kept_index[j] if inside else n
        lo = hi
    return squared, index


@njit(cache=True, inline="always")
def _line(points: NDArray[np.float64], row: int, at: NDArray[np.int64], k: int,
          ) -> tuple[float, float, float, float, float, float, bool]:
    """The line through the neighbours ``at[:k]`` of ``points[row]`` (``len(points)`` where
    missing): neighbour count, centroid, unit normal, RMS spread across the line [m] and
    whether it is a line (>= 3 neighbours, elongated, the point in its band)."""
    missing = points.shape[0]
    count = sx = sy = 0.0
    for j in range(k):
        if at[j] != missing:
            count += 1.0
            sx += points[at[j], 0]
            sy += points[at[j], 1]
    mx, my = sx / count, sy / count
    sxx = syy = sxy = 0.0
    for j in range(k):
        if at[j] != missing:
            dx, dy = points[at[j], 0] - mx, points[at[j], 1] - my
            sxx += dx * dx
            syy += dy * dy
            sxy += dx * dy
    direction = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)
    nx, ny = -np.sin(direction), np.cos(direction)
    spread = np.sqrt((sxx - syy) ** 2 + 4.0 * sxy**2)
    small = 0.5 * (sxx + syy - spread)
    large = 0.5 * (sxx + syy + spread)
    across = np.sqrt(max(small, 0.0) / count)
    own = abs((points[row, 0] - mx) * nx + (points[row, 1] - my) * ny)
    valid = count >= 3 and small < 0.1 * large and own <= 3.0 * across + 1e-9
    return count, mx, my, nx, ny, across, valid


@njit(cache=True, inline="always")
def _solve3(a: NDArray[np.float64], x: NDArray[np.float64]) -> None:
    """``x <- a^-1 x`` for a 3 x 3 system by Gaussian elimination with partial pivoting, in
    place (``a`` is overwritten)."""
    for col in range(3):
        pivot = col
        for row in range(col + 1, 3):
            if abs(a[row, col]) > abs(a[pivot, col]):
                pivot = row
        if pivot != col:
            for j in range(3):
                a[col, j], a[pivot, j] = a[pivot, j], a[col, j]
            x[col], x[pivot] = x[pivot], x[col]
        for row in range(col + 1, 3):
            factor = a[row, col] / a[col, col]
            for j in range(col, 3):
                a[row, j] -= factor * a[col, j]
            x[row] -= factor * x[col]
    for row in range(2, -1, -1):
        for j in range(row + 1, 3):
            x[row] -= a[row, j] * x[j]
        x[row] /= a[row, row]


@njit(cache=True, inline="always")
def _curve(points: NDArray[np.float64], row: int, at: NDArray[np.int64], k: int, mx: float,
           my: float, nx: float, ny: float, gram: NDArray[np.float64],
           moment: NDArray[np.float64]) -> tuple[float, float, float, float]:
    """The normal and anchor of ``points[row]`` moved onto the parabola through its
    neighbours ``at[:k]`` in the frame of their line (centroid ``mx, my``, normal ``nx,
    ny``); ``gram`` (3, 3) and ``moment`` (3,) are scratch."""
    missing = points.shape[0]
    tx, ty = ny, -nx
    g01 = g02 = g12 = g22 = m0 = m1 = m2 = 0.0
    count = 0.0
    for j in range(k):
        if at[j] == missing:
            continue
        ox, oy = points[at[j], 0] - mx, points[at[j], 1] - my
        s, t = ox * tx + oy * ty, ox * nx + oy * ny
        square = s * s  # the basis (1, s, s^2): products with 1 are exact
        count += 1.0
        g01 += s
        g02 += square
        g12 += s * square
        g22 += square * square
        m0 += t
        m1 += s * t
        m2 += square * t
    gram[0, 0], gram[0, 1], gram[0, 2] = count, g01, g02
    gram[1, 0], gram[1, 1], gram[1, 2] = g01, g02, g12
    gram[2, 0], gram[2, 1], gram[2, 2] = g02, g12, g22
    moment[0], moment[1], moment[2] = m0, m1, m2
    _solve3(gram, moment)
    c0, c1, c2 = moment[0], moment[1], moment[2]
    px, py = points[row, 0] - mx, points[row, 1] - my
    s = px * tx + py * ty
    height = c0 + c1 * s + c2 * s * s
    slope = c1 + 2.0 * c2 * s
    cx, cy = nx - slope * tx, ny - slope * ty
    length = np.sqrt(cx * cx + cy * cy)
    return cx / length, cy / length, mx + s * tx + height * nx, my + s * ty + height * ny


@njit(cache=True, inline="always")
def _fit(points: NDArray[np.float64], row: int, at: NDArray[np.int64], k: int, noise: float,
         curves: bool, normals: NDArray[np.float64], valid: NDArray[np.bool_],
         anchors: NDArray[np.float64], gram: NDArray[np.float64], moment: NDArray[np.float64],
         ) -> tuple[float, float, bool]:
    """Fit ``points[row]``'s neighbours ``at[:k]`` (``len(points)`` where missing): its
    line's normal and whether it is one with a spread across of at most ``noise`` [m]; with
    ``curves``, where it is and has at least 5 neighbours, the parabola's normal and anchor.
    Returns the neighbour count, the spread across [m] and the validity."""
    count, mx, my, nx, ny, across, line = _line(points, row, at, k)
    line = line and across <= noise
    normals[row, 0], normals[row, 1], valid[row] = nx, ny, line
    if curves and line and count >= 5:
        normals[row, 0], normals[row, 1], anchors[row, 0], anchors[row, 1] = _curve(
            points, row, at, k, mx, my, nx, ny, gram, moment)
    return count, across, line


@njit(cache=True)
def fit_neighbourhoods(
    tree: Tree, points: NDArray[np.float64], k: int, limit: int, max_radius: float,
    curves: bool, normals: NDArray[np.float64], valid: NDArray[np.bool_],
    anchors: NDArray[np.float64],
) -> None:
    """Every point's fit (:func:`_fit`) through its ``k`` nearest neighbours within
    ``max_radius`` [m] (found by :func:`neighbours_of`, in the tree's order); then, with
    twice the median spread across of those fits as the noise limit, the points whose
    neighbours are no line but spread across no more than ``GROW_SPREAD`` times that are
    fitted again through twice as many, and again those of them still so, up to ``limit``
    neighbours (a point with fewer neighbours than were asked for already has all within
    ``max_radius``)."""
    n = points.shape[0]
    order = tree[0]
    count, across = np.empty(n), np.empty(n)
    positions = np.arange(n)  # of the points to fit, in tree order
    fitting, width, noise = n, k, np.inf
    gram, moment = np.empty((3, 3)), np.empty(3)
    while fitting > 0:
        _, index = neighbours_of(tree, positions[:fitting], width, max_radius)
        for i in range(fitting):
            row = order[positions[i]]
            count[row], across[row], _ = _fit(points, row, index[i], width, noise, curves,
                                              normals, valid, anchors, gram, moment)
        if width >= limit:
            break
        if width == k:
            noise = 2.0 * np.median(across)  # the mean of the middle two, as np.median's
        still = 0
        for i in range(fitting):
            row = order[positions[i]]
            if not valid[row] and count[row] == width and across[row] <= GROW_SPREAD * noise:
                positions[still] = positions[i]
                still += 1
        fitting, width = still, min(2 * width, limit)


def local_fits(
    points: NDArray[np.float64], tree: PointIndex | cKDTree, k: int, max_radius: float,
    max_k: int | None, curves: bool,
) -> tuple[NDArray[np.float64], NDArray[np.bool_], NDArray[np.float64]]:
    """Normals (N, 2), validity (N,) and anchors (N, 2) [m] of ``points`` (N, 2) [m] through
    their ``k`` nearest neighbours within ``max_radius`` [m], grown up to ``max_k`` where they
    are no line (:func:`fit_neighbourhoods`); with ``curves`` the parabolas' normals and
    anchors, else the lines' normals and the raw points: the compiled form of
    :func:`estimators.matching.scan_matching.fit_local_curves` and
    :func:`~estimators.matching.scan_matching.estimate_normals`, bit for bit the same
    per-point arithmetic. ``tree`` is a :class:`PointIndex` over ``points``."""
    if not isinstance(tree, PointIndex):
        raise ConfigError(f"tree: the compiled fits search a PointIndex, got "
                          f"{type(tree).__name__} (compiled=False takes any tree with "
                          "cKDTree.query)")
    points = np.ascontiguousarray(points, dtype=np.float64)
    normals = np.empty((len(points), 2))
    valid = np.empty(len(points), dtype=bool)
    anchors = points.copy()
    fit_neighbourhoods(tree.arrays, points, min(k, len(points)),
                       min(max_k or k, len(points)), float(max_radius), curves, normals,
                       valid, anchors)
    return normals, valid, anchors


def check_neighbours(normal_neighbours: int, max_normal_neighbours: int) -> None:
    """Raise :class:`ConfigError` unless a line fit's neighbours are an integer >= 3 and its
    most an integer >= them."""
    for name, value, least in (("normal_neighbours", normal_neighbours, 3),
                               ("max_normal_neighbours", max_normal_neighbours,
                                normal_neighbours)):
        if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < least:
            said = f"{least} (normal_neighbours)" if name == "max_normal_neighbours" else least
            raise ConfigError(f"{name}: expected an integer >= {said}, got {value!r}")
