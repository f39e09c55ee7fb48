"""The part of an old place's max-pooled pyramid one loop-closure search can reach
(:func:`search_pyramid`): a search on that window reads the same values as on the whole
pyramid, and is cheaper: the whole pyramid of a large place (6 levels of 900 x 1,000 cells,
44 MB) costs more to pool than a search reads (a third to a half of it on ACES).

Frames and units: points [m] in the place's (reference keyframe's) frame; cells of
``resolution`` [m], cell ``(0, 0)`` at the field's ``origin``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from estimators.matching.branch_and_bound import GridPyramid, PyramidBuffer, search_headings
from estimators.matching.scan_matching import LikelihoodField


def search_pyramid(field: LikelihoodField, levels: int, points: ArrayLike, center: ArrayLike,
                   linear_window: float, angular_window: float, angular_step: float,
                   buffer: PyramidBuffer | None = None) -> GridPyramid:
    """The ``levels``-level pyramid of ``field``, kept only where
    :func:`~estimators.matching.branch_and_bound.match` with these arguments reads it: the
    cells of ``points`` (M, 2) turned to every heading and moved to ``center`` (3,), ``±
    linear_window`` [m] in whole cells, and the coarsest node's width beyond (plus a cell
    either way, so that rounding cannot put a read outside). Its levels go into ``buffer``
    when given (:class:`~estimators.matching.branch_and_bound.PyramidBuffer`)."""
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
    return GridPyramid(field.grid, field.origin, resolution, levels, window, buffer)
