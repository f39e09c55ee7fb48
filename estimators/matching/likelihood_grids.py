"""Likelihood grids for correlative scan matching, compiled: the exact Euclidean distance
transform turned into scores (:func:`distance_scores`, what
:class:`~estimators.matching.scan_matching.LikelihoodField` is built from) and a grid stamped
point by point, cut at 3 sigma (:func:`likelihood_grid`), and a grid's max-pooled levels
(:func:`max_pool_levels`, the bounds of the branch and bound in
:mod:`estimators.matching.branch_and_bound`).

:func:`distance_scores` with :func:`score_table` gives ``LikelihoodField``'s grid bit for bit
(the squared distances are integers in cells, and each distinct one is turned into a score by
the same numpy expression), at 2.5-4x less CPU than ``scipy.ndimage.distance_transform_edt``
(40 ns per cell on a place's 400,000 cells: a feature transform, then float arrays of the
distances); :func:`likelihood_scores` ``compiled=False`` is that scipy form, the tests'
reference.

Units: points [m]; cells of ``resolution`` [m], cell ``(0, 0)`` at ``origin``.
"""

from __future__ import annotations

from functools import cache

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from lidar_env.core import ConfigError

FloatArray = NDArray[np.float64]

#: Most levels a pyramid may have: level 9 pools 512 x 512 cells (25.6 m at 5 cm).
MAX_LEVELS = 10


@njit(cache=True)
def distance_scores(occupied: NDArray[np.bool_],
                    scores: FloatArray) -> FloatArray:  # pragma: no cover (numba)
    """``(NX, NY)``: ``scores[min(d2, len(scores) - 1)]`` per cell, ``d2`` the squared
    Euclidean distance [cells^2] from the cell to the nearest ``occupied`` one (exact; at
    least one cell must be occupied), found along the columns by two sweeps, then along the
    rows by the lower envelope of parabolas (Felzenszwalb & Huttenlocher, "Distance transforms
    of sampled functions", Theory of Computing 2012). ``scores = arange(K)`` gives ``d2``.

    Row by row throughout (memory order), into one int32 array and the output: fresh memory
    costs as much as the arithmetic here."""
    n_rows, n_cols = occupied.shape
    far = n_rows + n_cols  # beyond any distance along a column
    column = np.empty((n_rows, n_cols), np.int32)
    last = np.full(n_cols, -far)
    for i in range(n_rows):
        for j in range(n_cols):
            if occupied[i, j]:
                last[j] = i
            column[i, j] = i - last[j]
    last[:] = 2 * far
    for i in range(n_rows - 1, -1, -1):
        for j in range(n_cols):
            if occupied[i, j]:
                last[j] = i
            column[i, j] = min(column[i, j], last[j] - i)
    out = np.empty((n_rows, n_cols))
    apex = np.empty(n_cols, np.int64)  # columns of the envelope's parabolas
    bound = np.empty(n_cols + 1)  # where each of them starts to be the lowest
    height = np.empty(n_cols, np.int64)
    top = len(scores) - 1
    for i in range(n_rows):
        # A parabola at or above the table's end only gives cells its last score, which every
        # cell whose envelope lacks it gets anyway (min(d2, top)): left out, exactly.
        for j in range(n_cols):
            height[j] = column[i, j] ** 2 if column[i, j] < far else -1
            if height[j] >= top:
                height[j] = -1
        k = -1
        for q in range(n_cols):
            if height[q] < 0:
                continue
            s = -np.inf  # where parabola q starts to lie below the envelope's last one
            while k >= 0:
                v = apex[k]
                s = ((height[q] + q * q) - (height[v] + v * v)) / (2.0 * (q - v))
                if s > bound[k]:
                    break
                k -= 1
            k += 1
            apex[k], bound[k], bound[k + 1] = q, s if k > 0 else -np.inf, np.inf
        if k < 0:  # every cell of the row is at least the table's end away
            out[i] = scores[top]
            continue
        m = 0
        for j in range(n_cols):
            while bound[m + 1] < j:
                m += 1
            out[i, j] = scores[min((j - apex[m]) ** 2 + height[apex[m]], top)]
    return out


@cache
def score_table(resolution: float, sigma: float) -> FloatArray:
    """``exp(-d^2 / 2 sigma^2)`` for every squared distance ``0, 1, 2, ...`` [cells^2] up to
    the first that underflows to 0, by LikelihoodField's own expression (so bit for bit)."""
    count = int(np.ceil(1500.0 * (sigma / resolution) ** 2)) + 2  # exp(-750) is 0
    distance = np.sqrt(np.arange(count, dtype=np.float64)) * resolution
    scores = np.exp(-0.5 * (distance / sigma) ** 2)
    last = int(np.flatnonzero(scores)[-1]) + 2
    scores = scores[:last]
    scores.flags.writeable = False
    return scores


def likelihood_scores(occupied: NDArray[np.bool_], resolution: float, sigma: float,
                      compiled: bool = True) -> FloatArray:
    """``exp(-d^2 / 2 sigma^2)`` per cell of ``occupied`` (NX, NY), ``d`` [m] the Euclidean
    distance to the nearest occupied cell (at least one must be). ``compiled`` by
    :func:`distance_scores`, else by ``scipy.ndimage.distance_transform_edt`` (bit for bit
    the same grid)."""
    if compiled:
        return distance_scores(occupied, score_table(float(resolution), float(sigma)))
    distance = ndimage.distance_transform_edt(~occupied) * resolution
    return np.exp(-0.5 * (distance / sigma) ** 2)


@njit(cache=True)
def _stamp(cells: NDArray[np.int64], n_rows: int, n_cols: int,
           kernel: NDArray[np.float64]) -> NDArray[np.float64]:  # pragma: no cover (numba)
    """``(n_rows, n_cols)`` grid holding in each cell the largest ``kernel`` value any of
    ``cells`` (N, 2) puts there (``kernel`` centred on the cell)."""
    grid = np.zeros((n_rows, n_cols))
    reach = kernel.shape[0] // 2
    for k in range(len(cells)):
        ci, cj = cells[k, 0], cells[k, 1]
        for a in range(kernel.shape[0]):
            i = ci + a - reach
            if 0 <= i < n_rows:
                for b in range(kernel.shape[1]):
                    j = cj + b - reach
                    if 0 <= j < n_cols and kernel[a, b] > grid[i, j]:
                        grid[i, j] = kernel[a, b]
    return grid


def likelihood_grid(points: ArrayLike, origin: ArrayLike, shape: tuple[int, int],
                    resolution: float, sigma: float = 0.1) -> FloatArray:
    """``shape`` grid of ``exp(-d^2 / 2 sigma^2)``, ``d`` [m] from each cell to the nearest
    cell holding one of ``points`` (M, 2) [m] (cell ``(0, 0)`` at ``origin``), cut to 0 beyond
    ``3 sigma``: the values of :class:`~estimators.matching.scan_matching.LikelihoodField`
    (which spends a distance transform on the whole grid to give cells further out 0.01 or
    less), stamped point by point, so a grid costs its points, not its area."""
    if not (resolution > 0 and sigma > 0):
        raise ConfigError(f"resolution and sigma: expected > 0 [m], got {resolution}, {sigma}")
    reach = int(np.ceil(3.0 * sigma / resolution))
    offsets = np.arange(-reach, reach + 1) * resolution
    distance2 = offsets[:, None] ** 2 + offsets[None, :] ** 2
    kernel = np.where(distance2 <= (3.0 * sigma) ** 2, np.exp(-0.5 * distance2 / sigma**2), 0.0)
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    cells = np.floor((points - np.asarray(origin, dtype=np.float64)) / resolution)
    return _stamp(cells.astype(np.int64), int(shape[0]), int(shape[1]), kernel)


@njit(cache=True)
def pool_window(grid: NDArray[np.float64], pad: int, r0: int, r1: int, c0: int, c1: int,
                 levels: int, out: NDArray[np.float64]) -> bool:  # pragma: no cover (numba)
    """Fill ``out`` ``(levels, r1 - r0, c1 - c0)`` (every cell written): level 0 the cells
    ``r0 .. r1 - 1``, ``c0 .. c1 - 1`` of ``grid`` padded with ``pad`` empty (0) cells on the
    low side (0 beyond it too); level
    ``l`` holds in cell ``(i, j)`` the maximum of level 0's ``[i : i + 2^l, j : j + 2^l]``
    (clipped to the window), from level ``l - 1`` as the largest of its four cells ``(i, j)``,
    ``(i + w, j)``, ``(i, j + w)``, ``(i + w, j + w)``, ``w = 2^(l-1)``: one pass a level,
    the rows split where the clipping starts so that the inner loops have no branches (and
    vectorise). Returns whether a kept cell is negative or not finite."""
    n_rows, n_cols = r1 - r0, c1 - c0
    bad = False
    i_lo, i_hi = max(0, pad - r0), min(n_rows, grid.shape[0] + pad - r0)
    j_lo, j_hi = max(0, pad - c0), min(n_cols, grid.shape[1] + pad - c0)
    out[0] = 0.0
    for i in range(i_lo, i_hi):
        source = grid[r0 + i - pad]
        for j in range(j_lo, j_hi):
            value = source[c0 + j - pad]
            bad |= not (value >= 0.0 and value < np.inf)
            out[0, i, j] = value
    for level in range(1, levels):
        width = 2 ** (level - 1)
        below, here = out[level - 1], out[level]
        split_i, split_j = max(n_rows - width, 0), max(n_cols - width, 0)
        for i in range(split_i):
            top, low, row = below[i], below[i + width], here[i]
            for j in range(split_j):
                row[j] = max(max(top[j], top[j + width]), max(low[j], low[j + width]))
            for j in range(split_j, n_cols):
                row[j] = max(top[j], low[j])
        for i in range(split_i, n_rows):
            top, row = below[i], here[i]
            for j in range(split_j):
                row[j] = max(top[j], top[j + width])
            for j in range(split_j, n_cols):
                row[j] = top[j]
    return bad


class PyramidBuffer:
    """Memory that :class:`GridPyramid` s take their levels from, one after another: a
    pyramid built into it is valid until the next one is. Searches of places of every size
    otherwise get fresh memory each time (megabytes), whose page faults cost more than
    pooling into it."""

    def __init__(self) -> None:
        self._memory = np.empty(0)

    def take(self, shape: tuple[int, ...]) -> NDArray[np.float64]:
        """An uninitialised float array of ``shape``, over this buffer's memory (grown when
        too small)."""
        size = int(np.prod(shape))
        if size > len(self._memory):
            self._memory = np.empty(max(size, 3 * len(self._memory) // 2))
        return self._memory[:size].reshape(shape)


def max_pool_levels(grid: NDArray, levels: int) -> NDArray[np.float64]:
    """``(levels, NX, NY)`` copies of ``grid`` (2-D, values >= 0; booleans count as 0 / 1):
    level ``l`` holds in cell ``(i, j)`` the maximum of ``grid[i : i + 2^l, j : j + 2^l]``
    (clipped to the grid)."""
    if not 1 <= levels <= MAX_LEVELS:
        raise ConfigError(f"levels: expected an integer in [1, {MAX_LEVELS}], got {levels}")
    grid = np.ascontiguousarray(grid, dtype=np.float64)
    out = np.empty((levels, *grid.shape))
    pool_window(grid, 0, 0, grid.shape[0], 0, grid.shape[1], levels, out)
    return out
