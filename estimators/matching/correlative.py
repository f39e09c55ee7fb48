"""Exhaustive correlative search of a scan in a likelihood field (Olson, ICRA 2009).

Every heading of a window at a fixed step, every translation at the field's resolution; the
best mean score wins. The lookups (headings x translations x points, ~40,000 a heading for the
defaults) run in one compiled kernel; the means and the choice of the best stay numpy's, so the
search returns bit for bit what its array form (``compiled=False``) returns. Units: metres,
radians; the points in the car frame, the field and the poses in the world frame.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from estimators.matching.scan_matching import LikelihoodField
from lidar_env.core.se2 import wrap_angle


@njit(cache=True)
def _shifted_scores(grid: NDArray[np.float64], origin: NDArray[np.float64], resolution: float,
                    points: NDArray[np.float64],
                    shifts: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(S, M)`` field scores of ``points`` (M, 2) moved by each of ``shifts`` (S, 2); 0
    outside the grid (the arithmetic of :meth:`LikelihoodField.score`, point by point)."""
    out = np.zeros((shifts.shape[0], points.shape[0]))
    nx, ny = grid.shape
    for i in range(shifts.shape[0]):
        for j in range(points.shape[0]):
            cx = math.floor(((points[j, 0] + shifts[i, 0]) - origin[0]) / resolution)
            cy = math.floor(((points[j, 1] + shifts[i, 1]) - origin[1]) / resolution)
            if 0 <= cx < nx and 0 <= cy < ny:
                out[i, j] = grid[int(cx), int(cy)]
    return out


def correlative_search(
    field: LikelihoodField,
    points: NDArray[np.float64],
    center: ArrayLike,
    linear_window: float = 0.5,
    angular_window: float = np.radians(20.0),
    angular_step: float = np.radians(1.0),
    max_points: int = 90,
    compiled: bool = True,
) -> tuple[NDArray[np.float64], float]:
    """Exhaustive search for the pose of ``points`` (M, 2, car frame) in ``field`` (world).

    Tries every heading within ``center[2] ± angular_window`` [rad] at ``angular_step`` and
    every translation within ``center[:2] ± linear_window`` [m] at the field's resolution.
    Returns the best pose (3,) and its mean score in [0, 1]. At most ``max_points`` evenly
    spread points are scored: the search only has to find the basin ICP then refines.
    ``compiled=False`` scores with :meth:`LikelihoodField.score` on arrays (the reference).
    """
    center = np.asarray(center, dtype=np.float64)
    points = points[:: max(1, int(np.ceil(len(points) / max_points)))]
    step = field.resolution
    n_lin = int(np.ceil(linear_window / step))
    offsets = step * np.arange(-n_lin, n_lin + 1)
    n_ang = int(np.ceil(angular_window / angular_step))
    headings = center[2] + angular_step * np.arange(-n_ang, n_ang + 1)
    best_pose, best_score = center.copy(), -1.0
    grid_x, grid_y = np.meshgrid(offsets, offsets, indexing="ij")
    shifts = np.column_stack([grid_x.ravel(), grid_y.ravel()])
    origin = np.asarray(field.origin, dtype=np.float64)
    for heading in headings:
        c, s = np.cos(heading), np.sin(heading)
        rotated = points @ np.array([[c, s], [-s, c]]) + center[:2]
        if compiled:
            lookups = _shifted_scores(field.grid, origin, float(step),
                                      np.ascontiguousarray(rotated), shifts)
        else:  # (n_shifts, M, 2): every translation of the rotated scan at once
            lookups = field.score(rotated[None, :, :] + shifts[:, None, :])
        scores = lookups.mean(axis=1)
        k = int(np.argmax(scores))
        if scores[k] > best_score:
            best_score = float(scores[k])
            best_pose = np.array(
                [center[0] + shifts[k, 0], center[1] + shifts[k, 1], float(wrap_angle(heading))]
            )
    return best_pose, best_score
