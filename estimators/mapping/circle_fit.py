"""The compiled per-cluster fits of obstacle detection (:mod:`estimators.mapping.obstacles`): the
algebraic circle fit (Kåsa, "A circle fitting procedure and its error analysis", IEEE Trans.
Instrum. Meas. 1976) from running moments, each cluster's centroid, principal-axis extent and
two-segment (corner) fit, and the longest run of returns a circle explains and a line does not
(a cylinder touching a wall), found in one pass with prefix sums of the moments.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from lidar_env.core import EstimatorInputError

# columns of the per-cluster statistics of cluster_statistics
CX, CY, AXIS, LENGTH, WIDTH, SPREAD, FIT_X, FIT_Y, FIT_R, FIT_RMS, CORNER_RMS = range(11)


@dataclass(frozen=True)
class CircleFit:
    """An algebraic circle fit: centre ``(cx, cy)`` [m], ``radius`` [m], and ``rms`` [m] of the
    geometric residuals ``|p - c| - r`` of the points it was fitted to."""

    cx: float
    cy: float
    radius: float
    rms: float

    @property
    def centre(self) -> NDArray[np.float64]:
        return np.array([self.cx, self.cy])


@numba.njit(cache=True)
def kasa_moments(
    points: NDArray[np.float64], origin: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The normal equations ``(A^T A (3, 3), A^T b (3,))`` of Kåsa's linear least squares
    ``x^2 + y^2 + D x + E y + F = 0`` over ``points`` (N, 2) taken relative to ``origin`` (2,)
    (centring keeps them well conditioned); sums of them fit several point sets jointly."""
    normal = np.zeros((3, 3))
    rhs = np.zeros(3)
    for i in range(len(points)):
        x, y = points[i, 0] - origin[0], points[i, 1] - origin[1]
        z = x * x + y * y
        row = (x, y, 1.0)
        for a in range(3):
            rhs[a] -= row[a] * z
            for b in range(3):
                normal[a, b] += row[a] * row[b]
    return normal, rhs


@numba.njit(cache=True)
def solve_kasa(
    normal: NDArray[np.float64], rhs: NDArray[np.float64]
) -> tuple[float, float, float]:
    """Centre ``(cx, cy)`` and squared radius solving Kåsa's normal equations (cofactors of the
    symmetric 3 x 3 matrix); NaN when they are singular (collinear or too few points) or give
    no real circle."""
    a, b, c = normal[0, 0], normal[0, 1], normal[0, 2]
    d, e, f = normal[1, 1], normal[1, 2], normal[2, 2]
    c00, c01, c02 = d * f - e * e, c * e - b * f, b * e - c * d
    c11, c12, c22 = a * f - c * c, b * c - a * e, a * d - b * b
    det = a * c00 + b * c01 + c * c02
    if not abs(det) > 1e-12 * abs(a * d * f):
        return np.nan, np.nan, np.nan
    p0 = (c00 * rhs[0] + c01 * rhs[1] + c02 * rhs[2]) / det
    p1 = (c01 * rhs[0] + c11 * rhs[1] + c12 * rhs[2]) / det
    p2 = (c02 * rhs[0] + c12 * rhs[1] + c22 * rhs[2]) / det
    cx, cy = -p0 / 2.0, -p1 / 2.0
    radius_squared = cx * cx + cy * cy - p2
    if not radius_squared > 0.0:
        return np.nan, np.nan, np.nan
    return cx, cy, radius_squared


@numba.njit(cache=True)
def kasa_circle(
    normal: NDArray[np.float64], rhs: NDArray[np.float64], points: NDArray[np.float64],
    origin: NDArray[np.float64],
) -> tuple[float, float, float, float]:
    """``cx, cy, r, rms`` [m] (world frame) of Kåsa's normal equations about ``origin``, the rms
    measured on ``points`` (N, 2); all NaN when degenerate."""
    cx, cy, radius_squared = solve_kasa(normal, rhs)
    if not radius_squared > 0.0:
        return np.nan, np.nan, np.nan, np.nan
    radius = math.sqrt(radius_squared)
    cx, cy = cx + origin[0], cy + origin[1]
    squares = 0.0
    for i in range(len(points)):
        residual = math.hypot(points[i, 0] - cx, points[i, 1] - cy) - radius
        squares += residual * residual
    return cx, cy, radius, math.sqrt(squares / max(len(points), 1))


def fit_circle(points: ArrayLike) -> CircleFit | None:
    """Kåsa's algebraic circle fit of ``points`` (N >= 3, 2) [m]; ``None`` if degenerate.

    Example:
        >>> angles = np.linspace(0, 2, 9)
        >>> fit = fit_circle(np.column_stack([1 + 2 * np.cos(angles), 2 * np.sin(angles)]))
        >>> round(fit.cx, 6), round(fit.cy, 6), round(fit.radius, 6)
        (1.0, 0.0, 2.0)
    """
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 2 or len(points) < 3:
        raise EstimatorInputError(f"points: expected shape (N >= 3, 2), got {points.shape}")
    origin = points.mean(axis=0)
    cx, cy, radius, rms = kasa_circle(*kasa_moments(points, origin), points, origin)
    return None if math.isnan(radius) else CircleFit(cx, cy, radius, rms)


@numba.njit(cache=True)
def _line_squares(points: NDArray[np.float64], begin: int, end: int) -> float:
    """Sum of squared perpendicular distances [m^2] of ``points[begin:end]`` to their total
    least squares line (the smaller eigenvalue of their scatter matrix)."""
    n = end - begin
    if n < 3:
        return 0.0
    mx = my = 0.0
    for i in range(begin, end):
        mx += points[i, 0]
        my += points[i, 1]
    mx, my = mx / n, my / n
    sxx = sxy = syy = 0.0
    for i in range(begin, end):
        dx, dy = points[i, 0] - mx, points[i, 1] - my
        sxx += dx * dx
        sxy += dx * dy
        syy += dy * dy
    return max(0.5 * (sxx + syy) - math.sqrt(0.25 * (sxx - syy) ** 2 + sxy * sxy), 0.0)


@numba.njit(cache=True)
def cluster_statistics(
    points: NDArray[np.float64], begins: NDArray[np.int64], ends: NDArray[np.int64]
) -> NDArray[np.float64]:
    """``(C, 11)`` statistics of the clusters ``points[begins[c]:ends[c]]`` (world frame, in
    scan order): centroid (2) [m], principal axis angle [rad], extent along and across it [m],
    spread (largest distance from the centroid) [m], Kåsa circle ``cx, cy, r, rms`` [m] (NaN if
    degenerate or under 3 points) and the rms [m] of the best two-segment (corner) fit: split at
    the point farthest from the chord of the ends (as in Douglas-Peucker), one total least
    squares line per side, the split point on both."""
    out = np.full((len(begins), 11), np.nan)
    for c in range(len(begins)):
        begin, end = begins[c], ends[c]
        n = end - begin
        cluster = points[begin:end]
        mx = np.sum(cluster[:, 0]) / n
        my = np.sum(cluster[:, 1]) / n
        sxx = sxy = syy = 0.0
        for i in range(n):
            dx, dy = cluster[i, 0] - mx, cluster[i, 1] - my
            sxx += dx * dx
            sxy += dx * dy
            syy += dy * dy
        angle = 0.5 * math.atan2(2.0 * sxy, sxx - syy)  # the larger eigenvector's direction
        ux, uy = math.cos(angle), math.sin(angle)
        low_a = low_b = np.inf
        high_a = high_b = spread = -np.inf
        for i in range(n):
            dx, dy = cluster[i, 0] - mx, cluster[i, 1] - my
            along, across = dx * ux + dy * uy, dy * ux - dx * uy
            low_a, high_a = min(low_a, along), max(high_a, along)
            low_b, high_b = min(low_b, across), max(high_b, across)
            spread = max(spread, math.hypot(dx, dy))
        out[c, CX], out[c, CY], out[c, AXIS] = mx, my, angle
        out[c, LENGTH], out[c, WIDTH], out[c, SPREAD] = high_a - low_a, high_b - low_b, spread
        if n < 3:
            continue
        origin = np.array([mx, my])
        normal, rhs = kasa_moments(cluster, origin)
        fit = kasa_circle(normal, rhs, cluster, origin)
        out[c, FIT_X], out[c, FIT_Y], out[c, FIT_R], out[c, FIT_RMS] = fit
        chord_x = cluster[n - 1, 0] - cluster[0, 0]
        chord_y = cluster[n - 1, 1] - cluster[0, 1]
        split, farthest = 1, -1.0
        for i in range(1, n - 1):
            distance = abs((cluster[i, 0] - cluster[0, 0]) * chord_y
                           - (cluster[i, 1] - cluster[0, 1]) * chord_x)
            if distance > farthest:
                split, farthest = i, distance
        squares = _line_squares(cluster, 0, split + 1) + _line_squares(cluster, split, n)
        out[c, CORNER_RMS] = math.sqrt(squares / (n + 1))
    return out


@numba.njit(cache=True)
def _scatter_squares(s: NDArray[np.float64], n: int) -> float:
    """:func:`_line_squares` from the sums ``s`` = (x, y, xx, xy, yy, ...) of ``n`` points."""
    sxx = s[2] - s[0] * s[0] / n
    sxy = s[3] - s[0] * s[1] / n
    syy = s[4] - s[1] * s[1] / n
    return max(0.5 * (sxx + syy) - math.sqrt(0.25 * (sxx - syy) ** 2 + sxy * sxy), 0.0)


@numba.njit(cache=True)
def longest_arc(
    points: NDArray[np.float64], min_points: int, max_radius: float, tolerance: float
) -> tuple[int, int]:
    """``(begin, end)`` of the longest run ``points[begin:end]`` (m, 2), ordered along the scan,
    of at least ``min_points`` that a circle of radius <= ``max_radius`` [m] explains to within
    ``tolerance`` [m] rms while no straight line does; ``(-1, -1)`` if there is none.

    Each run's Kåsa fit and algebraic residual come from prefix sums of the point moments in
    O(1); the algebraic residual ``|p - c|^2 - r^2 ~ 2 r (|p - c| - r)`` gives the rms. Runs
    end before their chord exceeds ``2 max_radius``, and start only where the points up to that
    chord do not all fit a line (so a straight wall is skipped in O(1) per point)."""
    m = len(points)
    mx, my = np.mean(points[:, 0]), np.mean(points[:, 1])
    # prefix sums of x, y, xx, xy, yy, z, xz, yz, zz with z = x^2 + y^2 (about the mean)
    sums = np.zeros((m + 1, 9))
    for i in range(m):
        x, y = points[i, 0] - mx, points[i, 1] - my
        z = x * x + y * y
        sums[i + 1] = sums[i] + np.array([x, y, x * x, x * y, y * y, z, x * z, y * z, z * z])
    normal, rhs = np.zeros((3, 3)), np.zeros(3)
    best_begin, best_end, best_count = -1, -1, 0
    squared_tolerance = tolerance * tolerance
    diameter = 2.0 * max_radius
    reach = 0  # one past the last point within the chord limit of points[begin]
    for begin in range(m - min_points + 1):
        reach = max(reach, begin + 1)
        while reach < m and math.hypot(points[reach, 0] - points[begin, 0],
                                       points[reach, 1] - points[begin, 1]) <= diameter:
            reach += 1
        if reach - begin <= best_count:
            continue
        stretch = sums[reach] - sums[begin]
        if _scatter_squares(stretch, reach - begin) <= squared_tolerance * (reach - begin):
            continue
        for end in range(begin + max(min_points, best_count + 1), reach + 1):
            n = end - begin
            s = sums[end] - sums[begin]
            normal[0, 0], normal[0, 1], normal[0, 2] = s[2], s[3], s[0]
            normal[1, 0], normal[1, 1], normal[1, 2] = s[3], s[4], s[1]
            normal[2, 0], normal[2, 1], normal[2, 2] = s[0], s[1], n
            rhs[0], rhs[1], rhs[2] = -s[6], -s[7], -s[5]
            cx, cy, radius_squared = solve_kasa(normal, rhs)
            if not radius_squared <= max_radius * max_radius:
                continue
            d, e, f = -2.0 * cx, -2.0 * cy, cx * cx + cy * cy - radius_squared
            # sum of (z + D x + E y + F)^2 expanded over the moments
            algebraic = (s[8] + 2.0 * (d * s[6] + e * s[7] + f * s[5])
                         + d * d * s[2] + e * e * s[4] + f * f * n
                         + 2.0 * (d * e * s[3] + d * f * s[0] + e * f * s[1]))
            if max(algebraic, 0.0) / n > 4.0 * radius_squared * squared_tolerance:
                continue
            if _scatter_squares(s, n) <= squared_tolerance * n:
                continue  # a line explains it as well: no evidence of a curve
            best_begin, best_end, best_count = begin, end, n
    return best_begin, best_end
