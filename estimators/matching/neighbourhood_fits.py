"""Compiled per-point fits of a map's neighbourhoods: the line through each point's nearest
neighbours and the parabola in that line's frame, one numba loop over the points.

The math is :func:`estimators.matching.scan_matching.fit_rows_pure` and
:func:`estimators.matching.scan_matching.curve_points_pure` (the principal axis of the
neighbours' covariance, the line test, the least-squares parabola ``t = a + b s + c s^2``),
which ``tests/estimators/matching/test_scan_matching.py`` checks these kernels against. The
local map is refitted at every keyframe (thousands of points, up to 72 neighbours each), where
the array form's (n, k, 2) temporaries and batched 3 x 3 solves cost most of the keyframe.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray


@njit(cache=True)
def line_fits(
    points: NDArray[np.float64], rows: NDArray[np.int64], index: NDArray[np.int64],
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
           NDArray[np.float64], NDArray[np.bool_]]:
    """Lines through the neighbours ``index`` (n, k) of ``points[rows]`` (``len(points)``
    where missing): neighbour count, centroid (n, 2), unit normal (n, 2), RMS spread across
    the line [m] and whether it is a line (>= 3 neighbours, elongated, the point in its band)."""
    n, k = index.shape
    missing = points.shape[0]
    count = np.zeros(n)
    mean = np.zeros((n, 2))
    normals = np.empty((n, 2))
    across = np.empty(n)
    valid = np.empty(n, np.bool_)
    for r in range(n):
        sx = sy = 0.0
        for j in range(k):
            if index[r, j] != missing:
                count[r] += 1.0
                sx += points[index[r, j], 0]
                sy += points[index[r, j], 1]
        mx, my = sx / count[r], sy / count[r]
        mean[r, 0], mean[r, 1] = mx, my
        sxx = syy = sxy = 0.0
        for j in range(k):
            if index[r, j] != missing:
                dx, dy = points[index[r, j], 0] - mx, points[index[r, j], 1] - my
                sxx += dx * dx
                syy += dy * dy
                sxy += dx * dy
        direction = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)
        nx, ny = -np.sin(direction), np.cos(direction)
        normals[r, 0], normals[r, 1] = nx, ny
        spread = np.sqrt((sxx - syy) ** 2 + 4.0 * sxy**2)
        small = 0.5 * (sxx + syy - spread)
        large = 0.5 * (sxx + syy + spread)
        across[r] = np.sqrt(max(small, 0.0) / count[r])
        own = abs((points[rows[r], 0] - mx) * nx + (points[rows[r], 1] - my) * ny)
        valid[r] = count[r] >= 3 and small < 0.1 * large and own <= 3.0 * across[r] + 1e-9
    return count, mean, normals, across, valid


@njit(cache=True)
def _solve3(m: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
    """``m^-1 v`` for a 3 x 3 system by Gaussian elimination with partial pivoting."""
    a = m.copy()
    x = v.copy()
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
    return x


@njit(cache=True)
def curve_points(
    points: NDArray[np.float64], rows: NDArray[np.int64], index: NDArray[np.int64],
    mean: NDArray[np.float64], normals: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Normals and anchors (n, 2): ``points[rows]`` moved onto the parabola through their
    neighbours ``index`` (n, k) in the frame of their line (centroid ``mean``, ``normals``)."""
    n, k = index.shape
    missing = points.shape[0]
    curve_normals = np.empty((n, 2))
    on_curve = np.empty((n, 2))
    gram = np.empty((3, 3))
    moment = np.empty(3)
    for r in range(n):
        nx, ny = normals[r, 0], normals[r, 1]
        tx, ty = ny, -nx
        gram[:] = 0.0
        moment[:] = 0.0
        for j in range(k):
            if index[r, j] == missing:
                continue
            ox = points[index[r, j], 0] - mean[r, 0]
            oy = points[index[r, j], 1] - mean[r, 1]
            s, t = ox * tx + oy * ty, ox * nx + oy * ny
            basis = (1.0, s, s * s)
            for a in range(3):
                moment[a] += basis[a] * t
                for b in range(3):
                    gram[a, b] += basis[a] * basis[b]
        c0, c1, c2 = _solve3(gram, moment)
        px, py = points[rows[r], 0] - mean[r, 0], points[rows[r], 1] - mean[r, 1]
        s = px * tx + py * ty
        height = c0 + c1 * s + c2 * s * s
        on_curve[r, 0] = mean[r, 0] + s * tx + height * nx
        on_curve[r, 1] = mean[r, 1] + s * ty + height * ny
        slope = c1 + 2.0 * c2 * s
        cx, cy = nx - slope * tx, ny - slope * ty
        length = np.sqrt(cx * cx + cy * cy)
        curve_normals[r, 0], curve_normals[r, 1] = cx / length, cy / length
    return curve_normals, on_curve
