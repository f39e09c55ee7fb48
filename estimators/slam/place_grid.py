"""The grids a loop-closure search reads: an old place's likelihood field by a compiled exact
distance transform (:class:`PlaceField`), and the part of its max-pooled pyramid one search
can reach (:func:`search_pyramid`).

Both give exactly what the general tools give: :class:`PlaceField`'s grid is
:class:`~estimators.matching.scan_matching.LikelihoodField`'s, bit for bit (the squared
distances are integers in cells, and each distinct one is turned into a score by the same
numpy expression); a search on :func:`search_pyramid`'s window reads the same values as on
the whole pyramid. They are cheaper: ``scipy.ndimage.distance_transform_edt`` spent 40 ns
per cell on a place's 400,000 cells (feature transform, then float arrays of the distances),
and the whole pyramid of a large place (6 levels of 900 x 1,000 cells, 44 MB) is fresh memory
each time, whose page faults cost more than the pooling: a search reads a third to a half of
it on ACES.

Frames and units: points [m] in the place's (reference keyframe's) frame; cells of
``resolution`` [m], cell ``(0, 0)`` at the field's ``origin``.
"""

from __future__ import annotations

from functools import cache

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from estimators.matching.branch_and_bound import GridPyramid, search_headings
from estimators.matching.scan_matching import LikelihoodField

FloatArray = NDArray[np.float64]

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
        for j in range(n_cols):
            height[j] = column[i, j] ** 2 if column[i, j] < far else -1
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
        m = 0
        for j in range(n_cols):
            while bound[m + 1] < j:
                m += 1
            out[i, j] = scores[min((j - apex[m]) ** 2 + height[apex[m]], top)]
    return out


@cache
def _score_table(resolution: float, sigma: float) -> FloatArray:
    """``exp(-d^2 / 2 sigma^2)`` for every squared distance ``0, 1, 2, ...`` [cells^2] up to
    the first that underflows to 0, by LikelihoodField's own expression (so bit for bit)."""
    count = int(np.ceil(1500.0 * (sigma / resolution) ** 2)) + 2  # exp(-750) is 0
    distance = np.sqrt(np.arange(count, dtype=np.float64)) * resolution
    scores = np.exp(-0.5 * (distance / sigma) ** 2)
    last = int(np.flatnonzero(scores)[-1]) + 2
    scores = scores[:last]
    scores.flags.writeable = False
    return scores


class PlaceField(LikelihoodField):
    """:class:`~estimators.matching.scan_matching.LikelihoodField` of ``points`` (M >= 1, 2)
    [m] (same origin, shape and grid), its distances by :func:`distance_scores`."""

    @staticmethod
    def _scores(occupied: NDArray[np.bool_], resolution: float,
                sigma: float) -> NDArray[np.float64]:
        return distance_scores(occupied, _score_table(float(resolution), float(sigma)))


def search_pyramid(field: LikelihoodField, levels: int, points: ArrayLike, center: ArrayLike,
                   linear_window: float, angular_window: float, angular_step: float,
                   ) -> GridPyramid:
    """The ``levels``-level pyramid of ``field``, kept only where
    :func:`~estimators.matching.branch_and_bound.match` with these arguments reads it: the
    cells of ``points`` (M, 2) turned to every heading and moved to ``center`` (3,), ``±
    linear_window`` [m] in whole cells, and the coarsest node's width beyond (plus a cell
    either way, so that rounding cannot put a read outside)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    center = np.asarray(center, dtype=np.float64)
    resolution = field.resolution
    pad = 2 ** (levels - 1) - 1
    reach = int(np.ceil(linear_window / resolution - 1e-9)) + 1
    headings = search_headings(float(center[2]), angular_window, angular_step)[:, None]
    c, s = np.cos(headings), np.sin(headings)
    x = c * points[:, 0] - s * points[:, 1] + center[0] - field.origin[0]
    y = s * points[:, 0] + c * points[:, 1] + center[1] - field.origin[1]
    low = np.floor(np.array([x.min(), y.min()]) / resolution).astype(np.int64) + pad - reach
    high = np.floor(np.array([x.max(), y.max()]) / resolution).astype(np.int64) + pad + reach
    sizes = np.array(field.grid.shape) + pad
    start = np.clip(low, 0, sizes - 1)
    stop = np.clip(high + pad + 1, start + 1, sizes)
    window = ((int(start[0]), int(stop[0])), (int(start[1]), int(stop[1])))
    return GridPyramid(field.grid, field.origin, resolution, levels, window)
