"""Multi-resolution branch-and-bound correlative scan matching: the exact best pose of a scan
on a likelihood grid over a window of translations and headings, at a fraction of the cost of
scoring every pose.

Olson, "Real-time correlative scan matching", ICRA 2009 (the multi-resolution
search); Hess et al., "Real-time loop closure in 2D LIDAR SLAM", ICRA 2016 (branch-and-bound
over precomputed grids, Cartographer's ``FastCorrelativeScanMatcher2D``).

A candidate is a heading and a translation in whole cells; its score is the mean grid value
under the scan's points (0 outside the grid). Level ``l`` of a :class:`GridPyramid` holds, in
every cell, the maximum of the ``2^l x 2^l`` cells of level 0 starting there, so the score of a
translation on level ``l`` bounds from above the score of every one of the ``4^l``
translations it stands for (Hess et al. 2016). The search scores the coarsest level for
every heading, then descends depth first, best child first, and drops every node whose bound
does not beat the best leaf found so far: the result is the grid optimum the exhaustive search
(the tests' oracle) finds. An ``allowed`` mask of translations
(e.g. "at least 0.5 m from the best", for an ambiguity test) is pooled the same way, so a node
with no allowed translation is never expanded.

Frames: the scan's points ``(M, 2)`` are in the car frame; the grid, the centre of the window
and the returned pose are in the grid's (world) frame. Distances [m], angles [rad].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from estimators.matching.likelihood_grids import (
    MAX_LEVELS,
    PyramidBuffer,
    likelihood_grid,
    max_pool_levels,
    pool_window,
)
from lidar_env.core import ConfigError, EstimatorInputError
from lidar_env.core.se2 import wrap_angle

FloatArray = NDArray[np.float64]

__all__ = ["MAX_LEVELS", "GridPyramid", "Match", "PyramidBuffer", "levels_for_window",
           "likelihood_grid", "match", "max_pool_levels", "search_headings"]



@njit(cache=True)
def _rotated_cells(points: NDArray[np.float64], cos: NDArray[np.float64],
                   sin: NDArray[np.float64], center: NDArray[np.float64],
                   origin: NDArray[np.float64], resolution: float, row_offset: int,
                   col_offset: int) -> NDArray[np.int64]:  # pragma: no cover (numba)
    """``(H, M, 2)`` cells of ``points`` turned by each heading (its ``cos``, ``sin``) and
    moved to ``center`` (2,), on a grid whose cell ``(0, 0)`` starts at ``origin``, plus the
    offsets (padding, and the start of a kept window)."""
    out = np.empty((len(cos), len(points), 2), np.int64)
    for h in range(len(cos)):
        c, s = cos[h], sin[h]
        for m in range(len(points)):
            x = (c * points[m, 0] - s * points[m, 1] + center[0]) - origin[0]
            y = (s * points[m, 0] + c * points[m, 1] + center[1]) - origin[1]
            out[h, m, 0] = int(np.floor(x / resolution)) + row_offset
            out[h, m, 1] = int(np.floor(y / resolution)) + col_offset
    return out


class GridPyramid:
    """A likelihood grid and its max-pooled levels, ready for :func:`match`.

    Args:
        grid: ``(NX, NY)`` scores >= 0; cell ``(i, j)`` covers ``origin + resolution * (i, j)``
            up to the next cell.
        origin: ``(2,)`` [m] corner of cell ``(0, 0)``.
        resolution: cell size [m], also the translation step of the search.
        levels: 1 (only the grid: exhaustive) to ``MAX_LEVELS``; a window ``2n + 1`` cells
            wide is searched fastest with ``2^(levels - 1)`` about a quarter of it.

        window: ``((row_start, row_stop), (col_start, col_stop))``: the padded grid's cells
            to keep (default all); a search reading only those finds what it finds on all.
            Only those are checked for scores >= 0.
        buffer: where the levels go (default fresh memory); the pyramid is then valid until
            the buffer's next pyramid.

    The levels are padded with ``2^(levels - 1) - 1`` empty cells on the low side, so that a
    coarse cell reaching into the grid from outside still bounds the cells it covers.
    """

    def __init__(self, grid: ArrayLike, origin: ArrayLike, resolution: float, levels: int,
                 window: tuple[tuple[int, int], tuple[int, int]] | None = None,
                 buffer: PyramidBuffer | None = None) -> None:
        grid = np.ascontiguousarray(grid, dtype=np.float64)
        if grid.ndim != 2 or grid.size == 0:
            raise EstimatorInputError(f"grid: expected a non-empty 2-D array, got {grid.shape}")
        if not resolution > 0:
            raise ConfigError(f"resolution: expected a cell size > 0 [m], got {resolution}")
        if not (isinstance(levels, int | np.integer) and 1 <= levels <= MAX_LEVELS):
            raise ConfigError(f"levels: expected an integer in [1, {MAX_LEVELS}], got {levels}")
        self.origin = np.asarray(origin, dtype=np.float64).reshape(2)
        self.resolution = float(resolution)
        self.padding = pad = 2 ** (levels - 1) - 1
        (r0, r1), (c0, c1) = window or ((0, grid.shape[0] + pad), (0, grid.shape[1] + pad))
        if not (0 <= r0 < r1 <= grid.shape[0] + pad and 0 <= c0 < c1 <= grid.shape[1] + pad):
            raise ConfigError(f"window: expected a non-empty part of the padded grid, got {window}")
        self.start = (r0, c0)
        shape = (int(levels), r1 - r0, c1 - c0)
        self.levels = np.empty(shape) if buffer is None else buffer.take(shape)
        # only the kept cells are read, so only they are checked
        if pool_window(grid, pad, r0, r1, c0, c1, int(levels), self.levels):
            raise EstimatorInputError("grid: expected finite scores >= 0")

    @classmethod
    def from_field(cls, field: object, levels: int) -> GridPyramid:
        """The pyramid of a :class:`~estimators.matching.scan_matching.LikelihoodField`."""
        return cls(field.grid, field.origin, field.resolution, levels)  # type: ignore[attr-defined]

    @property
    def n_levels(self) -> int:
        """Levels, the grid itself included."""
        return len(self.levels)

    def cells(self, points: FloatArray, center: FloatArray,
              headings: FloatArray) -> NDArray[np.int64]:
        """``(H, M, 2)`` level-0 cells (of the kept window) of ``points`` (M, 2) turned to
        each of ``headings`` (H,) and moved to ``center[:2]`` (no translation offset yet)."""
        headings = np.asarray(headings, dtype=np.float64)
        return _rotated_cells(np.ascontiguousarray(points, dtype=np.float64), np.cos(headings),
                              np.sin(headings), np.asarray(center[:2], dtype=np.float64),
                              self.origin, self.resolution, self.padding - self.start[0],
                              self.padding - self.start[1])


@dataclass(frozen=True)
class Match:
    """Outcome of :func:`match`: the best ``pose`` (3,) and its mean ``score`` in [0, 1];
    ``found`` is False when no candidate beat ``min_score`` (``pose`` is then the window's
    centre and ``score`` 0); ``nodes`` counts the candidates scored at any level (the
    exhaustive search scores ``headings * (2n + 1)^2``)."""

    pose: FloatArray
    score: float
    found: bool
    nodes: int


def search_headings(center_heading: float, angular_window: float,
                    angular_step: float) -> FloatArray:
    """Headings [rad] of the search: ``center_heading + k * angular_step`` within
    ``± angular_window``; a window of pi or more covers the circle once."""
    if not angular_step > 0:
        raise ConfigError(f"angular_step: expected a step > 0 [rad], got {angular_step}")
    if not angular_window >= 0:
        raise ConfigError(f"angular_window: expected a window >= 0 [rad], got {angular_window}")
    if angular_window >= np.pi:
        n = int(np.ceil(2 * np.pi / angular_step))
        return center_heading + (2 * np.pi / n) * (np.arange(n) - n // 2)
    n = int(np.ceil(angular_window / angular_step - 1e-9))
    return center_heading + angular_step * np.arange(-n, n + 1)


def angular_step_for(points: FloatArray, resolution: float, max_step: float = np.radians(1.0),
                     min_step: float = np.radians(0.1)) -> float:
    """Heading step [rad] at which the scan's far points (90th percentile of their ranges)
    move by one grid cell (Hess et al. 2016 take the farthest point), within
    [``min_step``, ``max_step``]."""
    ranges = np.hypot(points[:, 0], points[:, 1])
    far = float(np.percentile(ranges, 90)) if len(ranges) else 0.0
    if far <= resolution:
        return max_step
    return float(np.clip(resolution / far, min_step, max_step))


@njit(cache=True)
def _cell_bounds(cells: NDArray[np.int64]) -> NDArray[np.int64]:  # pragma: no cover (numba)
    """``(H, 4)``: the smallest and largest row, then column, of each heading's ``cells``
    (H, M, 2)."""
    out = np.empty((cells.shape[0], 4), np.int64)
    for h in range(cells.shape[0]):
        out[h, 0] = out[h, 2] = 2**62
        out[h, 1] = out[h, 3] = -(2**62)
        for m in range(cells.shape[1]):
            out[h, 0] = min(out[h, 0], cells[h, m, 0])
            out[h, 1] = max(out[h, 1], cells[h, m, 0])
            out[h, 2] = min(out[h, 2], cells[h, m, 1])
            out[h, 3] = max(out[h, 3], cells[h, m, 1])
    return out


@njit(cache=True)
def _square_scores(grid: NDArray[np.float64], cells: NDArray[np.int64],
                   bounds: NDArray[np.int64], h: int, di: int, dj: int, width: int,
                   out: NDArray[np.float64]) -> None:  # pragma: no cover (numba)
    """``out[2 a + b]``: mean of ``grid`` under the points of heading ``h`` moved by ``(di + a
    width, dj + b width)`` cells, ``a, b`` in 0, 1: four sums in one pass, each in point order
    (each sum's additions wait for one another; four of them interleave). ``bounds`` are
    :func:`_cell_bounds` of ``cells``: when all four shifted scans lie on the grid, no point
    is checked (the same sums, in the same order)."""
    n_rows, n_cols = grid.shape
    n_points = cells.shape[1]
    t00 = t01 = t10 = t11 = 0.0
    if (bounds[h, 0] + di >= 0 and bounds[h, 1] + di + width < n_rows
            and bounds[h, 2] + dj >= 0 and bounds[h, 3] + dj + width < n_cols):
        for m in range(n_points):
            i, j = cells[h, m, 0] + di, cells[h, m, 1] + dj
            t00 += grid[i, j]
            t01 += grid[i, j + width]
            t10 += grid[i + width, j]
            t11 += grid[i + width, j + width]
        count = max(n_points, 1)
        out[0], out[1], out[2], out[3] = t00 / count, t01 / count, t10 / count, t11 / count
        return
    for m in range(n_points):
        i, j = cells[h, m, 0] + di, cells[h, m, 1] + dj
        low_i, high_i = 0 <= i < n_rows, 0 <= i + width < n_rows
        low_j, high_j = 0 <= j < n_cols, 0 <= j + width < n_cols
        if low_i and low_j:
            t00 += grid[i, j]
        if low_i and high_j:
            t01 += grid[i, j + width]
        if high_i and low_j:
            t10 += grid[i + width, j]
        if high_i and high_j:
            t11 += grid[i + width, j + width]
    count = max(n_points, 1)
    out[0], out[1], out[2], out[3] = t00 / count, t01 / count, t10 / count, t11 / count


@njit(cache=True)
def _branch_and_bound(
    levels: NDArray[np.float64], cells: NDArray[np.int64], n: int,
    allowed: NDArray[np.bool_], min_score: float,
) -> tuple[float, int, int, int, int]:  # pragma: no cover (numba)
    """Best (score, heading, di, dj) over the translations ``[-n, n]^2`` cells that
    ``allowed[0]`` admits, scoring ``levels[l]`` for nodes of ``2^l x 2^l`` translations;
    also the number of nodes scored. ``allowed[l]`` is the mask pooled like the grid."""
    top = levels.shape[0] - 1
    width = 2**top
    n_headings = cells.shape[0]
    starts = np.arange(-n, n + 1, width)
    n_starts = len(starts)
    roots = np.empty(n_headings * n_starts * n_starts)
    square = np.empty(4)
    bounds = _cell_bounds(cells)
    for h in range(n_headings):
        for a0 in range(0, n_starts, 2):
            for b0 in range(0, n_starts, 2):
                _square_scores(levels[top], cells, bounds, h, starts[a0], starts[b0], width,
                               square)
                for a in range(a0, min(a0 + 2, n_starts)):
                    for b in range(b0, min(b0 + 2, n_starts)):
                        k = (h * n_starts + a) * n_starts + b
                        allow = allowed[top, starts[a] + n, starts[b] + n]
                        roots[k] = square[2 * (a - a0) + b - b0] if allow else -1.0
    nodes = len(roots)
    order = np.argsort(-roots, kind="mergesort")
    best, best_h, best_i, best_j = min_score, -1, 0, 0
    capacity = 4 * (top + 1) + 1
    stack_level = np.empty(capacity, np.int64)
    stack_h = np.empty(capacity, np.int64)
    stack_i = np.empty(capacity, np.int64)
    stack_j = np.empty(capacity, np.int64)
    stack_score = np.empty(capacity)
    child_i = np.empty(4, np.int64)
    child_j = np.empty(4, np.int64)
    child_score = np.empty(4)
    for k in order:
        if roots[k] <= best:
            break
        h = k // (n_starts * n_starts)
        stack_level[0], stack_h[0] = top, h
        stack_i[0], stack_j[0] = starts[(k // n_starts) % n_starts], starts[k % n_starts]
        stack_score[0] = roots[k]
        size = 1
        while size > 0:
            size -= 1
            level, score = stack_level[size], stack_score[size]
            di, dj = stack_i[size], stack_j[size]
            if score <= best:
                continue
            if level == 0:
                best, best_h, best_i, best_j = score, stack_h[size], di, dj
                continue
            half = 2 ** (level - 1)
            _square_scores(levels[level - 1], cells, bounds, h, di, dj, half, square)
            count = 0
            for a in range(2):
                for b in range(2):
                    ci, cj = di + a * half, dj + b * half
                    if ci > n or cj > n or not allowed[level - 1, ci + n, cj + n]:
                        continue
                    child_i[count], child_j[count] = ci, cj
                    child_score[count] = square[2 * a + b]
                    count += 1
            nodes += count
            # Push the best child last, so that it is expanded first.
            for c in np.argsort(child_score[:count], kind="mergesort"):
                if child_score[c] > best:
                    stack_level[size], stack_h[size] = level - 1, h
                    stack_i[size], stack_j[size] = child_i[c], child_j[c]
                    stack_score[size] = child_score[c]
                    size += 1
    return best, best_h, best_i, best_j, nodes


def _window_cells(linear_window: float, resolution: float) -> int:
    if not linear_window >= 0:
        raise ConfigError(f"linear_window: expected a window >= 0 [m], got {linear_window}")
    return int(np.ceil(linear_window / resolution - 1e-9))


def _check_inputs(points: ArrayLike, center: ArrayLike) -> tuple[FloatArray, FloatArray]:
    points = np.asarray(points, dtype=np.float64)
    center = np.asarray(center, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 2 or len(points) == 0:
        raise EstimatorInputError(f"points: expected shape (M >= 1, 2), got {points.shape}")
    if center.shape != (3,) or not np.all(np.isfinite(center)):
        raise EstimatorInputError(f"center: expected a finite pose (x, y, heading), got {center}")
    return points, center


def match(
    pyramid: GridPyramid, points: ArrayLike, center: ArrayLike, linear_window: float,
    angular_window: float, angular_step: float, min_score: float = 0.0,
    allowed: NDArray[np.bool_] | None = None,
) -> Match:
    """Best pose of ``points`` (M, 2, car frame) on ``pyramid`` within ``center[:2] ±
    linear_window`` [m] (whole cells: ``n = ceil(linear_window / resolution)`` each way) and
    ``center[2] ± angular_window`` at ``angular_step`` (:func:`search_headings`), exact on the
    grid. Only translations where ``allowed`` ``(2n + 1, 2n + 1)`` holds count (index
    ``(di + n, dj + n)`` for a shift of ``(di, dj)`` cells; all when None). A best score
    that does not exceed ``min_score`` gives ``found=False``."""
    points, center = _check_inputs(points, center)
    n = _window_cells(linear_window, pyramid.resolution)
    headings = search_headings(center[2], angular_window, angular_step)
    if allowed is None:
        allowed = np.ones((2 * n + 1, 2 * n + 1), dtype=bool)
    elif allowed.shape != (2 * n + 1, 2 * n + 1):
        raise EstimatorInputError(f"allowed: expected shape {(2 * n + 1, 2 * n + 1)}, "
                                  f"got {allowed.shape}")
    mask = max_pool_levels(np.asarray(allowed, dtype=bool), pyramid.n_levels) > 0
    cells = pyramid.cells(points, center, headings)
    best, h, di, dj, nodes = _branch_and_bound(pyramid.levels, cells, n, mask, float(min_score))
    if h < 0:
        return Match(center.copy(), 0.0, False, int(nodes))
    pose = np.array([center[0] + di * pyramid.resolution, center[1] + dj * pyramid.resolution,
                     float(wrap_angle(headings[h]))])
    return Match(pose, float(best), True, int(nodes))


def levels_for_window(linear_window: float, resolution: float,
                      max_levels: int = MAX_LEVELS) -> int:
    """Levels for a window of ``± linear_window`` [m]: the coarsest node spans at least half
    of it, so a heading starts from 4 nodes (fewer when the window is one cell), but at most
    ``max_levels``. Where a scan has a few hundred points, fewer levels can be cheaper: each
    level costs a pass over the pyramid's window, while more first nodes cost passes over
    the points only (loop closure takes 5, see
    :class:`~estimators.slam.loop_closure.LoopClosureParams`)."""
    if not 1 <= max_levels <= MAX_LEVELS:
        raise ConfigError(f"max_levels: expected an integer in [1, {MAX_LEVELS}], got {max_levels}")
    cells = 2 * _window_cells(linear_window, resolution) + 1
    return int(np.clip(np.ceil(np.log2(cells)), 1, max_levels))
