"""Obstacles from single scans, and a tracker that keeps one id per static obstacle.

Detection (:func:`detect_obstacles`): the returns of a scan are cut into clusters where two
angular neighbours are farther apart than the adaptive breakpoint distance of Borges & Aldon
("Line extraction in 2D range images for mobile robotics", J. Intell. Robot. Syst. 2004)::

    D_max = r_prev * sin(dphi) / sin(lambda - dphi) + 3 sigma_r

i.e. the gap a surface seen at the grazing angle ``lambda`` would leave between two beams
``dphi`` apart, plus three range-noise sigmas. Each cluster is reported in the world frame at
the (estimated) sensor pose with its centroid and extent (along and across its principal axis);
a cluster that an algebraic circle fit (Kåsa, "A circle fitting procedure and its error
analysis", IEEE Trans. Instrum. Meas. 1976) explains to within the range noise, better than two
line segments would (a corner), convex towards the sensor and no larger than ``max_radius``, is
a round obstacle with a centre and a radius. A cluster that is not round as a whole may hold
one: a cylinder touching a wall joins the wall's cluster, as the wall meets its arc without a
range jump. The detector cuts out of it the longest run of returns that a circle of at most
``max_radius`` explains to within two range sigmas while a line does not (found in one pass with
prefix sums of the moments), less the end returns that lie within noise of the line of the rest
of the cluster on that side (a wall is tangent to the cylinder it touches), and keeps the cut if
the run passes the roundness test above; the rest is searched again. The per-cluster fits are
compiled (numba): detection and tracking together cost ~0.9 ms per step of two 360-beam scans
in ``open_cylinders`` (CPU time, ``benchmarks/bench_mapping.py``).

Tracking (:class:`ObstacleTracker`): nearest-neighbour association with a gate. A detection
joins the track whose position (circle centre for round obstacles, else centroid) is nearest,
if it lies within ``gate`` [m], or, if it is extended, the track whose latest returns come
within ``surface_gate`` [m] of its own (a wall's centroid moves with the car, its surface does
not); several detections may join one track in one step, which is how the same obstacle seen
by both Lidars gets one id. The gate must exceed how far a static obstacle's reported position
moves between steps (pose-estimate drift per step, and for a round obstacle the jump from arc
centroid to fitted centre, at most its radius) and stay below the distance between distinct
obstacles. A round track's circle is the joint Kåsa fit of every point it was given, so its
centre sharpens as the arc is seen from more sides.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimators.base import SensorSetup
from estimators.mapping.occupancy import sensor_poses
from lidar_env.se2 import transform_points

# columns of the per-cluster statistics of _cluster_statistics
_CX, _CY, _AXIS, _LENGTH, _WIDTH, _SPREAD, _FIT_X, _FIT_Y, _FIT_R, _FIT_RMS, _CORNER_RMS = range(11)


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
def _kasa_moments(
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
def _solve_kasa(
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
def _kasa_circle(
    normal: NDArray[np.float64], rhs: NDArray[np.float64], points: NDArray[np.float64],
    origin: NDArray[np.float64],
) -> tuple[float, float, float, float]:
    """``cx, cy, r, rms`` [m] (world frame) of Kåsa's normal equations about ``origin``, the rms
    measured on ``points`` (N, 2); all NaN when degenerate."""
    cx, cy, radius_squared = _solve_kasa(normal, rhs)
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
        raise ValueError(f"points: expected shape (N >= 3, 2), got {points.shape}")
    origin = points.mean(axis=0)
    cx, cy, radius, rms = _kasa_circle(*_kasa_moments(points, origin), points, origin)
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
def _cluster_statistics(
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
        out[c, _CX], out[c, _CY], out[c, _AXIS] = mx, my, angle
        out[c, _LENGTH], out[c, _WIDTH], out[c, _SPREAD] = high_a - low_a, high_b - low_b, spread
        if n < 3:
            continue
        origin = np.array([mx, my])
        normal, rhs = _kasa_moments(cluster, origin)
        fit = _kasa_circle(normal, rhs, cluster, origin)
        out[c, _FIT_X], out[c, _FIT_Y], out[c, _FIT_R], out[c, _FIT_RMS] = fit
        chord_x = cluster[n - 1, 0] - cluster[0, 0]
        chord_y = cluster[n - 1, 1] - cluster[0, 1]
        split, farthest = 1, -1.0
        for i in range(1, n - 1):
            distance = abs((cluster[i, 0] - cluster[0, 0]) * chord_y
                           - (cluster[i, 1] - cluster[0, 1]) * chord_x)
            if distance > farthest:
                split, farthest = i, distance
        squares = _line_squares(cluster, 0, split + 1) + _line_squares(cluster, split, n)
        out[c, _CORNER_RMS] = math.sqrt(squares / (n + 1))
    return out


@numba.njit(cache=True)
def _scatter_squares(s: NDArray[np.float64], n: int) -> float:
    """:func:`_line_squares` from the sums ``s`` = (x, y, xx, xy, yy, ...) of ``n`` points."""
    sxx = s[2] - s[0] * s[0] / n
    sxy = s[3] - s[0] * s[1] / n
    syy = s[4] - s[1] * s[1] / n
    return max(0.5 * (sxx + syy) - math.sqrt(0.25 * (sxx - syy) ** 2 + sxy * sxy), 0.0)


@numba.njit(cache=True)
def _longest_arc(
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
            cx, cy, radius_squared = _solve_kasa(normal, rhs)
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


@dataclass(frozen=True)
class Obstacle:
    """One cluster of returns, in the world frame.

    Attributes:
        points: ``(m, 2)`` world positions [m] of the returns, in scan order.
        beams: ``(m,)`` indices of the beams (into the scan) that produced them.
        centroid: ``(2,)`` [m] mean of ``points``.
        extent: ``(length, width)`` [m] spread of the points along and across their principal
            axis.
        axis_angle: [rad] world direction of the principal axis.
        circle: the fitted circle if the cluster is round, else ``None``.
        circle_tested: whether the cluster had enough returns to be tested for roundness.
        spread: [m] largest distance of a point from the centroid.
    """

    points: NDArray[np.float64]
    beams: NDArray[np.int64]
    centroid: NDArray[np.float64]
    extent: NDArray[np.float64]
    axis_angle: float
    circle: CircleFit | None
    circle_tested: bool
    spread: float

    @property
    def position(self) -> NDArray[np.float64]:
        """``(2,)`` [m]: the circle centre of a round obstacle, else the centroid."""
        return self.circle.centre if self.circle is not None else self.centroid


@dataclass(frozen=True)
class DetectorParams:
    """Parameters of :func:`detect_obstacles`, with the reasons for their defaults.

    Attributes:
        range_sigma: [m] 1-sigma range noise of the Lidar (0.01: a typical time-of-flight
            planar Lidar, and the env's default noise); set it to your sensor's.
        grazing_angle: [rad] ``lambda`` of the breakpoint detector: a surface seen at a shallower
            angle than this is split (10 degrees, Borges & Aldon's value).
        min_points: returns a cluster needs to be reported (3: fewer cannot show an extent).
        min_circle_points: returns a circle fit needs to be trusted (5: two more than the three
            that always fit a circle exactly, so the fit residual means something).
        max_radius: [m] largest round obstacle (1.0: posts, pillars, trees, people, barrels;
            larger curved things are mapped as extended obstacles).
        max_circle_rms: [m] largest rms residual of a round cluster, in units of
            ``range_sigma`` (3: generous for noise, far below the misfit of a corner).
    """

    range_sigma: float = 0.01
    grazing_angle: float = math.radians(10.0)
    min_points: int = 3
    min_circle_points: int = 5
    max_radius: float = 1.0
    max_circle_rms: float = 3.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.range_sigma) and self.range_sigma >= 0):
            raise ValueError(f"range_sigma: expected a number >= 0 [m], got {self.range_sigma!r}")
        if not 0.0 < self.grazing_angle < math.pi / 2:
            raise ValueError(f"grazing_angle: expected an angle in (0, pi/2) [rad], "
                             f"got {self.grazing_angle!r}")
        if self.min_points < 1 or self.min_circle_points < 4:
            raise ValueError(f"expected min_points >= 1 and min_circle_points >= 4, got "
                             f"{self.min_points} and {self.min_circle_points}")
        if not (self.max_radius > 0 and self.max_circle_rms > 0):
            raise ValueError(f"expected max_radius > 0 and max_circle_rms > 0, got "
                             f"{self.max_radius} and {self.max_circle_rms}")


def split_scan(
    ranges: ArrayLike, beam_angles: ArrayLike, max_range: float, params: DetectorParams
) -> list[NDArray[np.int64]]:
    """Clusters of one scan as arrays of beam indices, each ordered by angle.

    Beams reading ``>= max_range`` (no return) separate clusters; so does a gap between two
    angular neighbours wider than the adaptive breakpoint distance ``D_max`` (module doc). When
    the beams cover the full circle, the clusters at both ends of the angle order are joined if
    they touch across 0 rad."""
    ranges = np.asarray(ranges, dtype=np.float64)
    angles = np.asarray(beam_angles, dtype=np.float64)
    if angles.ndim != 1 or ranges.shape != angles.shape:
        raise ValueError(f"ranges: expected shape {angles.shape} like beam_angles, "
                         f"got {ranges.shape}")
    order = np.argsort(np.mod(angles, 2 * np.pi), kind="stable")
    r = ranges[order]
    phi = np.mod(angles[order], 2 * np.pi)
    valid = r < max_range
    n = len(r)
    # gap between each beam and its predecessor (circularly): beam 0's predecessor is beam n-1
    step = np.mod(phi - np.roll(phi, 1), 2 * np.pi)
    x, y = r * np.cos(phi), r * np.sin(phi)
    gap = np.hypot(x - np.roll(x, 1), y - np.roll(y, 1))
    lam = params.grazing_angle
    limit = np.roll(r, 1) * np.sin(step) / np.sin(np.maximum(lam - step, 1e-12))
    limit = np.where(step < lam, limit, 0.0) + 3.0 * params.range_sigma
    joined = valid & np.roll(valid, 1) & (gap <= limit)  # beam i continues beam i-1's cluster
    starts = np.flatnonzero(valid & ~joined)
    if len(starts) == 0:
        # no start: either nothing returned, or one closed ring of returns around the sensor
        return [order[valid]] if np.all(valid) and n > 0 else []
    clusters = []
    for begin, end in zip(starts, np.append(starts[1:], starts[0] + n), strict=True):
        members = np.arange(begin, end) % n
        members = members[valid[members]]
        clusters.append(members)
    return [order[c] for c in clusters]


def _round_clusters(
    statistics: NDArray[np.float64], sizes: NDArray[np.int64],
    sensor_position: NDArray[np.float64], params: DetectorParams,
) -> NDArray[np.bool_]:
    """Which clusters (rows of :func:`_cluster_statistics`, ``sizes`` points each) are round
    obstacles seen from ``sensor_position`` (2,) [m] (module doc)."""
    fit_rms = statistics[:, _FIT_RMS]
    centre_range = np.hypot(statistics[:, _FIT_X] - sensor_position[0],
                            statistics[:, _FIT_Y] - sensor_position[1])
    centroid_range = np.hypot(statistics[:, _CX] - sensor_position[0],
                              statistics[:, _CY] - sensor_position[1])
    return (
        (sizes >= params.min_circle_points)
        & (statistics[:, _FIT_R] <= params.max_radius)  # NaN (no circle) compares False
        & (fit_rms <= params.max_circle_rms * max(params.range_sigma, 1e-6))
        # convex towards the sensor: the centre lies beyond the arc, not in front of it
        & (centre_range > centroid_range)
        # a circle with fewer degrees of freedom (3) than two lines (4) must still fit better:
        # the convex corner of a box or of two walls is not a cylinder
        & (fit_rms < statistics[:, _CORNER_RMS])
    )


def _trim_against_lines(
    points: NDArray[np.float64], begin: int, arc_begin: int, arc_end: int, end: int,
    min_points: int, tolerance: float,
) -> tuple[int, int]:
    """Shrink the arc ``points[arc_begin:arc_end]`` cut out of the cluster
    ``points[begin:end]``: drop from each of its ends the points that lie within ``tolerance``
    [m] of the line fitted to the rest of the cluster on that side (if it has ``min_points``).
    Where a wall touches a cylinder it is tangent to it, so the wall's first returns past the
    contact are within noise of the circle too, and would pull its centre towards the wall."""
    for side_begin, side_end, step in ((begin, arc_begin, 1), (arc_end, end, -1)):
        if side_end - side_begin < max(min_points, 2):
            continue
        side = points[side_begin:side_end]
        centre = side.mean(axis=0)
        normal = np.linalg.svd(side - centre, full_matrices=False)[2][1]
        while arc_end - arc_begin > 0:
            index = arc_begin if step == 1 else arc_end - 1
            if abs(float((points[index] - centre) @ normal)) > tolerance:
                break
            if step == 1:
                arc_begin += 1
            else:
                arc_end -= 1
    return arc_begin, arc_end


def _cut_out_arcs(
    points: NDArray[np.float64], begins: NDArray[np.int64], ends: NDArray[np.int64],
    sensor_position: NDArray[np.float64], params: DetectorParams,
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64], NDArray[np.bool_]]:
    """The clusters ``points[begins[c]:ends[c]]`` after cutting a round arc out of each one
    that is not round as a whole (a cylinder touching a wall is one cluster with the wall),
    until none is left to cut; pieces of fewer than ``params.min_points`` are dropped. Returns
    the new ``begins, ends``, their statistics and roundness."""
    # the arc is searched for within 2 sigma rms (pure noise exceeds it with a chance < 1e-4 at
    # 5 points), not the acceptance limit, so the wall points next to the contact, which the
    # circle misses by a little more than the noise, are left out of it
    tolerance = 2.0 * max(params.range_sigma, 1e-6)
    searched = np.zeros(len(begins), dtype=bool)
    while True:
        statistics = _cluster_statistics(points, begins, ends)
        round_ = _round_clusters(statistics, ends - begins, sensor_position, params)
        todo = np.flatnonzero(~round_ & ~searched & (ends - begins > params.min_circle_points))
        searched[todo] = True
        cuts = {}
        for k in todo:
            begin, end = _longest_arc(points[begins[k]:ends[k]], params.min_circle_points,
                                      params.max_radius, tolerance)
            if begin < 0:
                continue
            arc = _trim_against_lines(points, begins[k], begins[k] + begin, begins[k] + end,
                                      ends[k], params.min_points, tolerance)
            if arc[1] - arc[0] >= params.min_circle_points:
                cuts[k] = arc
        if cuts:  # keep only the arcs that pass the full roundness test
            arcs = np.array(list(cuts.values()), dtype=np.int64).reshape(-1, 2)
            arc_round = _round_clusters(_cluster_statistics(points, arcs[:, 0], arcs[:, 1]),
                                        arcs[:, 1] - arcs[:, 0], sensor_position, params)
            cuts = {k: cut for (k, cut), keep in zip(cuts.items(), arc_round, strict=True)
                    if keep}
        if not cuts:
            return begins, ends, statistics, round_
        pieces = []  # (begin, end, searched)
        for k, (begin, end) in enumerate(zip(begins, ends, strict=True)):
            if k not in cuts:
                pieces.append((begin, end, searched[k]))
                continue
            arc_begin, arc_end = cuts[k]
            pieces += [(begin, arc_begin, False), (arc_begin, arc_end, True),
                       (arc_end, end, False)]
        pieces = [p for p in pieces if p[1] - p[0] >= params.min_points]
        begins = np.array([p[0] for p in pieces], dtype=np.int64)
        ends = np.array([p[1] for p in pieces], dtype=np.int64)
        searched = np.array([p[2] for p in pieces], dtype=bool)


def detect_obstacles(
    ranges: ArrayLike,
    beam_angles: ArrayLike,
    sensor_pose: ArrayLike,
    max_range: float,
    params: DetectorParams | None = None,
) -> list[Obstacle]:
    """The obstacles in one scan ``ranges`` (n,) [m] taken at world ``sensor_pose`` (3,), beam
    ``i`` at ``beam_angles[i]`` [rad] CCW from the sensor's forward axis, in the world frame."""
    params = DetectorParams() if params is None else params
    pose = np.asarray(sensor_pose, dtype=np.float64)
    if pose.shape != (3,) or not np.all(np.isfinite(pose)):
        raise ValueError(f"sensor_pose: expected 3 finite numbers (x, y, heading), got {pose}")
    ranges = np.asarray(ranges, dtype=np.float64)
    angles = np.asarray(beam_angles, dtype=np.float64)
    clusters = [c for c in split_scan(ranges, angles, max_range, params)
                if len(c) >= params.min_points]
    if not clusters:
        return []
    beams = np.concatenate(clusters)
    local = np.column_stack([ranges[beams] * np.cos(angles[beams]),
                             ranges[beams] * np.sin(angles[beams])])
    points = transform_points(pose, local)
    ends = np.cumsum([len(c) for c in clusters]).astype(np.int64)
    begins = ends - np.array([len(c) for c in clusters], dtype=np.int64)
    begins, ends, statistics, round_ = _cut_out_arcs(points, begins, ends, pose[:2], params)
    obstacles = []
    for begin, end, row, is_round in zip(begins, ends, statistics, round_, strict=True):
        circle = CircleFit(*(float(v) for v in row[_FIT_X:_FIT_RMS + 1])) if is_round else None
        obstacles.append(Obstacle(
            points[begin:end], beams[begin:end], row[_CX:_CY + 1].copy(),
            row[_LENGTH:_WIDTH + 1].copy(), float(row[_AXIS]), circle,
            circle_tested=bool(end - begin >= params.min_circle_points),
            spread=float(row[_SPREAD]),
        ))
    return obstacles


def detect_in_observation(
    observation: Mapping[str, ArrayLike],
    car_pose: ArrayLike,
    setup: SensorSetup,
    params: DetectorParams | None = None,
) -> list[Obstacle]:
    """The obstacles in every scan of one env observation (keyed by ``setup.keys``) taken at
    the (estimated) car pose ``car_pose`` (3,), each Lidar at car pose ⊕ its mount."""
    scans = setup.check_observation(observation)
    obstacles = []
    for key, pose in zip(setup.keys, sensor_poses(car_pose, setup)[0], strict=True):
        obstacles += detect_obstacles(scans[key], setup.beam_angles, pose, setup.max_range,
                                      params)
    return obstacles


@numba.njit(cache=True)
def _nearest_distance(a: NDArray[np.float64], b: NDArray[np.float64]) -> float:
    """Smallest distance [m] between a point of ``a`` (m, 2) and a point of ``b`` (k, 2);
    brute force, as both are one obstacle's returns (tens of points)."""
    best = np.inf
    for i in range(len(a)):
        for j in range(len(b)):
            best = min(best, (a[i, 0] - b[j, 0]) ** 2 + (a[i, 1] - b[j, 1]) ** 2)
    return math.sqrt(best)


@dataclass
class Track:
    """One obstacle followed across steps.

    Attributes:
        id: stable identifier, unique within its tracker.
        position: ``(2,)`` world position [m]: the circle centre of a round track, else the
            latest centroid.
        circle: joint circle fit of all round detections, or ``None`` (updated every step, for
            association; :meth:`consensus_circle` is the one to report).
        points: ``(m, 2)`` world returns [m] of the latest step it was detected in.
        hits: detections joined so far.
        round_hits, circle_tests: detections found round, and tested for roundness.
        first_step, last_step: steps of the first and the latest detection.
    """

    id: int
    position: NDArray[np.float64]
    circle: CircleFit | None
    points: NDArray[np.float64]
    hits: int
    first_step: int
    last_step: int
    _origin: NDArray[np.float64] = field(repr=False)
    round_hits: int = 0
    circle_tests: int = 0
    _normal: NDArray[np.float64] = field(default_factory=lambda: np.zeros((3, 3)), repr=False)
    _rhs: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3), repr=False)
    # per round detection: its Kåsa normal equations about _origin, its own centre and rms
    _round: list[tuple[NDArray[np.float64], NDArray[np.float64], float, float, float]] = field(
        default_factory=list, repr=False)

    def reach(self) -> tuple[NDArray[np.float64], float]:
        """Centre (2,) [m] and radius [m] of a circle holding :attr:`points`: their mean and
        the largest distance from it."""
        centre = self.points.mean(axis=0)
        return centre, float(np.sqrt(np.max(np.sum((self.points - centre) ** 2, axis=1))))

    def surface_distance(self, points: NDArray[np.float64]) -> float:
        """Smallest distance [m] from ``points`` (m, 2) to this track's latest returns."""
        return _nearest_distance(np.ascontiguousarray(points, dtype=np.float64), self.points)

    def add(self, obstacle: Obstacle, step: int) -> None:
        """Join ``obstacle`` (detected at ``step``) to this track."""
        same_step = self.hits > 0 and step == self.last_step  # e.g. seen by both Lidars
        self.points = np.vstack([self.points, obstacle.points]) if same_step else obstacle.points
        self.hits += 1
        self.last_step = step
        self.circle_tests += obstacle.circle_tested
        if obstacle.circle is None:
            if self.circle is None:
                self.position = obstacle.centroid.copy()
            return
        self.round_hits += 1
        normal, rhs = _kasa_moments(obstacle.points, self._origin)
        self._round.append((normal, rhs, obstacle.circle.cx, obstacle.circle.cy,
                            obstacle.circle.rms))
        self._normal += normal
        self._rhs += rhs
        cx, cy, radius, rms = _kasa_circle(self._normal, self._rhs, obstacle.points,
                                           self._origin)
        if not math.isnan(radius):
            self.circle = CircleFit(cx, cy, radius, rms)
            self.position = self.circle.centre

    def consensus_circle(self) -> CircleFit | None:
        """The joint Kåsa fit of the round detections whose own centre lies within three
        median distances of the median centre (about 3.5 sigma of a Gaussian scatter, whose
        median distance is 1.18 sigma), or ``None`` if none was round. A few short arcs that
        a circle fitted by chance (5 returns of a cylinder and of the wall behind it) would
        otherwise pull the centre by decimetres. ``rms`` is the median of the kept detections'."""
        if not self._round:
            return None
        centres = np.array([(cx, cy) for _, _, cx, cy, _ in self._round])
        distances = np.hypot(*(centres - np.median(centres, axis=0)).T)
        keep = distances <= 3.0 * np.median(distances)
        kept = [d for d, k in zip(self._round, keep, strict=True) if k]
        cx, cy, radius_squared = _solve_kasa(sum(d[0] for d in kept), sum(d[1] for d in kept))
        if not radius_squared > 0.0:
            return None
        return CircleFit(cx + self._origin[0], cy + self._origin[1], math.sqrt(radius_squared),
                         float(np.median([d[4] for d in kept])))


@dataclass
class ObstacleTracker:
    """Gives each static obstacle one id across steps (nearest neighbour within a gate).

    A detection joins the nearest track by position (circle centre or centroid) within
    ``gate`` [m]; an extended (not round) detection may instead join the track whose latest
    returns come within ``surface_gate`` [m] of its own, so a wall whose centroid wanders as
    the car drives along it keeps its id.

    ``gate`` defaults to 0.5 m: several times the per-step drift of a usable pose estimate and
    larger than the radius of the round obstacles we fit (so an arc's centroid and its fitted
    centre fall in one gate), yet below the spacing of obstacles a car can pass between
    (its width, 0.5 m here, plus margins). ``surface_gate`` defaults to 0.2 m: the returns of
    one surface in consecutive scans lie within one beam spacing of each other (0.17 m at 10 m
    for 1-degree beams), while distinct obstacles this close are one obstacle to a car.

    The tracks' positions and bounding circles are kept in arrays, so that associating a
    detection costs a few vector operations over all tracks and an exact surface distance only
    to the tracks whose bounding circles come within ``surface_gate``."""

    gate: float = 0.5
    surface_gate: float = 0.2
    tracks: list[Track] = field(default_factory=list)
    _step: int = field(default=-1, repr=False)
    _positions: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 2)),
                                            repr=False)
    _reach: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3)), repr=False)

    def __post_init__(self) -> None:
        for name in ("gate", "surface_gate"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name}: expected a positive distance [m], got {value!r}")

    def update(self, obstacles: list[Obstacle]) -> list[int]:
        """Associate one step's detections (from any number of Lidars); return their track ids."""
        self._step += 1
        ids = []
        for obstacle in obstacles:
            track = self.nearest(obstacle)
            if track is None:
                track = Track(
                    id=len(self.tracks), position=obstacle.position.copy(), circle=None,
                    points=obstacle.points, hits=0, first_step=self._step,
                    last_step=self._step, _origin=obstacle.centroid.copy(),
                )
                self.tracks.append(track)
                self._positions = np.vstack([self._positions, np.zeros((1, 2))])
                self._reach = np.vstack([self._reach, np.zeros((1, 3))])
            track.add(obstacle, self._step)
            self._positions[track.id] = track.position
            if track.points is obstacle.points:  # its first detection this step
                self._reach[track.id] = (*obstacle.centroid, obstacle.spread)
            else:
                centre, radius = track.reach()
                self._reach[track.id] = (*centre, radius)
            ids.append(track.id)
        return ids

    def nearest(self, obstacle: Obstacle) -> Track | None:
        """The track ``obstacle`` belongs to (see the class doc), or ``None``."""
        if not self.tracks:
            return None
        distances = np.hypot(self._positions[:, 0] - obstacle.position[0],
                             self._positions[:, 1] - obstacle.position[1])
        distances[distances > self.gate] = np.inf
        if obstacle.circle is None:
            # only tracks whose returns could be within surface_gate: bounding circles first
            near = (np.hypot(self._reach[:, 0] - obstacle.centroid[0],
                             self._reach[:, 1] - obstacle.centroid[1])
                    <= obstacle.spread + self._reach[:, 2] + self.surface_gate)
            for i in np.flatnonzero(near):
                surface = self.tracks[i].surface_distance(obstacle.points)
                if surface <= self.surface_gate:
                    distances[i] = min(distances[i], surface)
        best = int(np.argmin(distances))
        return self.tracks[best] if np.isfinite(distances[best]) else None

    def cylinders(self, min_hits: int = 3, min_round_share: float = 0.5) -> NDArray[np.float64]:
        """``(M, 3)`` rows ``cx, cy, r`` [m] (:meth:`Track.consensus_circle`) of the round
        tracks detected at least ``min_hits``
        times (one detection may be a coincidence of noise) and found round in at least
        ``min_round_share`` of their roundness tests (the majority of the views that could tell).
        A cylinder is round in most of them, also one touching a wall, whose arc the detector
        cuts out of the wall's cluster (85-100 % in the built-in worlds and the tests); the
        convex corner of a box or of two walls in a few percent (a short arc of returns around
        it fits a circle), at most 11 % in the built-in worlds."""
        if not 0.0 <= min_round_share <= 1.0:
            raise ValueError(
                f"min_round_share: expected a share in [0, 1], got {min_round_share!r}"
            )
        circles = [
            t.consensus_circle() for t in self.tracks
            if t.circle is not None and t.hits >= min_hits
            and t.round_hits >= min_round_share * t.circle_tests
        ]
        rows = [(c.cx, c.cy, c.radius) for c in circles if c is not None]
        return np.array(rows, dtype=np.float64).reshape(-1, 3)
