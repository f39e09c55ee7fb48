"""The exact best pose of a scan on the likelihood grid of a set of map points (a local map,
or the last scan) within a window around a guess: multi-resolution branch and bound
(:mod:`estimators.matching.branch_and_bound`; Olson 2009), on a scan thinned to what pins a
pose to a cell. It gives ICP its start where a scan comes far from its guess (scans far
apart, or after scans skipped or lost). Distances [m], angles [rad].
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from estimators.matching.branch_and_bound import (
    GridPyramid,
    Match,
    angular_step_for,
    levels_for_window,
    likelihood_grid,
    match,
)
from estimators.matching.scan_matching import voxel_downsample

FloatArray = NDArray[np.float64]

#: Thinning [m] of the scan the branch-and-bound scores: a few points per metre of wall is what
#: pins a pose to a 5 cm cell, and the cost is linear in the points.
SEARCH_VOXEL = 0.1
#: At most this many points are scored (evenly spread); ICP refines with all of them.
SEARCH_POINTS = 300
#: A best mean score at or below this (a scan landing on nothing of the map: 0.05 = one point
#: in 20 on a wall) is "not found".
MIN_SEARCH_SCORE = 0.05


def thinned_for_search(points: FloatArray) -> FloatArray:
    """``points`` (M, 2) thinned on :data:`SEARCH_VOXEL` cells, at most about
    :data:`SEARCH_POINTS` of them, evenly spread."""
    thinned = voxel_downsample(points, SEARCH_VOXEL)
    return thinned[:: max(1, int(np.ceil(len(thinned) / SEARCH_POINTS)))]


def box_pyramid(map_points: FloatArray, low: FloatArray, high: FloatArray, resolution: float,
                levels: int) -> GridPyramid:
    """The likelihood grid (``resolution`` [m] cells) of the ``map_points`` (N, 2) inside the
    box ``low``..``high`` (2,), and its ``levels`` max-pooled levels."""
    shape = tuple(np.maximum(np.ceil((high - low) / resolution).astype(int), 1))
    inside = np.all((map_points >= low) & (map_points <= high), axis=1)
    grid = likelihood_grid(map_points[inside], low, shape, resolution)
    return GridPyramid(grid, low, resolution, levels)


def search_in_box(map_points: FloatArray, low: FloatArray, high: FloatArray,
                  thinned: FloatArray, guess: FloatArray, linear: float, angular: float,
                  resolution: float, pyramid: GridPyramid | None = None) -> Match:
    """Exact best pose of the ``thinned`` scan (:func:`thinned_for_search`, car frame) within
    ``linear`` [m] and ``angular`` [rad] of ``guess`` (3,), on the likelihood grid
    (``resolution`` [m] cells) of the ``map_points`` (N, 2) inside the box ``low``..``high``
    (2,); "not found" at or below :data:`MIN_SEARCH_SCORE`. ``pyramid``: that box's
    :func:`box_pyramid` with ``levels_for_window(linear, resolution)`` levels, if built."""
    if pyramid is None:
        pyramid = box_pyramid(map_points, low, high, resolution,
                              levels_for_window(linear, resolution))
    return match(pyramid, thinned, guess, linear, angular,
                 angular_step_for(thinned, resolution), MIN_SEARCH_SCORE)
