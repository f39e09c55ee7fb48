"""The Lidar's compiled ray caster: exact beam ranges against circles and segments (numba).

Instead of testing every beam against every primitive, :func:`cast_sensor` sweeps the
primitives: each one within ``max_range`` updates only the beams inside the angular interval it
subtends from the sensor, found by index arithmetic for uniformly spaced beams and by binary
search otherwise. Every candidate beam then gets the exact ray-circle or ray-segment
intersection (computed whole and kept or not without a branch), so the interval only has to
be conservative (it is widened by :data:`lidar_env.sensors.beam_wedge.ANGLE_MARGIN`). Three
culls keep the primitives a sensor touches few, none of which can change a range (each skips
only primitives no beam can hit closer than it already reads):

- the grid cells (:class:`~lidar_env.world.primitive_grid.PrimitiveGrid`) visited are those over the
  bounding box of the sensor's sector (its beams' angular range out to ``max_range``), so a
  90-degree Lidar visits about a quarter of a 360-degree one's (row by row: the ranges are the
  nearest hits whatever the order; no cell is skipped for lying behind the beams' current
  ends, a test that costs about what the primitives it would skip cost);
- a cell or primitive wholly outside a narrow sensor's beam wedge
  (:mod:`lidar_env.sensors.beam_wedge`) is skipped before bearings;
- a polygon edge whose filled side faces the sensor is skipped (back-face culling, with the
  free sides from :func:`lidar_env.sensors.edge_facing.edge_facing`): about half of a traced map's.

Units and frames: positions and ranges in metres, angles in radians, world frame; a sensor pose
is ``(x, y, heading)``, beam ``j`` points at world angle ``heading + beam_angles[j]``. Beam
sets come as ``(sorted_angles, order, step)`` from :func:`.lidar_config.beam_geometry`. The
callers' entry points are :func:`.lidar.cast_rays` and :meth:`.lidar_layout.LidarLayout.scan`,
through :func:`.layout_kernels.cast_packed`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from lidar_env.core.errors import ConfigError
from lidar_env.sensors.beam_wedge import ANGLE_MARGIN, beam_wedge, box_outside_wedge, outside_wedge
from lidar_env.sensors.edge_facing import BACK_FACE_TOLERANCE
from lidar_env.world.primitive_grid import cell_block, odd_crossings, point_segment_distance2

#: Relative tolerance on the segment parameter so a beam through an end point still hits it.
_ENDPOINT_TOLERANCE = 1e-12
#: [rad] a beam wedge leaving less of the circle than this out is not worth culling against.
_MIN_CULLED_ANGLE = 0.2
#: [m] a segment's bounding box farther than this from the sensor cannot touch it, and one whose
#: nearest end is within ``max_range * sqrt(_IN_RANGE)`` is in range: no exact distance needed.
_NEAR, _IN_RANGE = 1e-9, 1.0 - 1e-9
_TWO_PI = 2.0 * math.pi


def scan_loop(kernel: Callable[..., Any]) -> Callable[..., Any]:
    """Marks ``kernel`` (a Python function, before ``njit``) as one that scans many times per
    call, such as the batched env's: :func:`cast_sensor`, :func:`beam_directions` and the
    layout's ``cast_packed`` and ``readings`` are compiled inline into it (numba's own
    inlining), where its arrays are handed on with no reference counting and no call; other
    callers call them."""
    kernel.inlines_scans = True  # type: ignore[attr-defined]
    return kernel


def inline_into_scan_loops(call: Any, caller: Any, callee: Any) -> bool:
    """numba's inline cost model for the scan's kernels: inline into :func:`scan_loop`
    kernels only."""
    return getattr(caller.func_id.func, "inlines_scans", False)


@njit(cache=True, fastmath=False, error_model="numpy")  # no zero test: loops of it vectorise
def _bearing(y: float, x: float) -> float:
    """``atan2(y, x)`` [rad] to within 1.7e-6 rad, several times cheaper than libm's.

    Octant reduction and a degree-11 odd polynomial for atan on [0, 1]. Only used to bound the
    beams a primitive can hit, never for a range.
    """
    ax, ay = abs(x), abs(y)
    a = min(ax, ay) / max(ax, ay)
    s = a * a
    poly = 0.19354346 + s * (-0.11643287 + s * (0.05265332 - s * 0.0117212))
    r = a * (0.99997726 + s * (-0.33262347 + s * poly))
    if ay > ax:
        r = 0.5 * math.pi - r
    if x < 0.0:
        r = math.pi - r
    return -r if y < 0.0 else r


@njit(cache=True, fastmath=False)
def _wrap_positive(angle: float) -> float:
    """``angle`` in ``[-4 pi, 4 pi)`` wrapped to ``[0, 2 pi)`` without a float modulo or a
    branch: at most two turns added, then at most two taken off."""
    angle = angle + _TWO_PI if angle < 0.0 else angle
    angle = angle + _TWO_PI if angle < 0.0 else angle
    angle = angle - _TWO_PI if angle >= _TWO_PI else angle
    return angle - _TWO_PI if angle >= _TWO_PI else angle


@njit(cache=True, fastmath=False)
def _sorted_range(
    lo: float, hi: float, sorted_angles: NDArray[np.float64], step: float
) -> tuple[int, int]:
    """Positions ``[first, last)`` in ``sorted_angles`` of the angles within ``[lo, hi]``."""
    n = sorted_angles.shape[0]
    if step > 0.0:
        # times the reciprocal (hoisted out of a sensor's loops once inlined), not divided:
        # it moves a bound by one beam at most, and only for a beam at the edge of the
        # margin-widened interval, which cannot hit
        per_step = 1.0 / step
        first = max(0, int(math.ceil((lo - sorted_angles[0]) * per_step)))
        last = min(n, int(math.floor((hi - sorted_angles[0]) * per_step)) + 1)
        return first, last
    return np.searchsorted(sorted_angles, lo, "left"), np.searchsorted(sorted_angles, hi, "right")


@njit(cache=True, fastmath=False, inline="always")
def _beam_span(
    lo: float, width: float, sorted_angles: NDArray[np.float64], step: float
) -> tuple[int, int, int, int]:
    """Sorted-beam positions ``[f0, l0)`` and ``[f1, l1)`` of the beams within the interval
    ``[lo, lo + width]`` (``lo`` in [0, 2 pi), ``width`` <= pi) widened by the margin.

    The second range is the part that wraps past 0 or 2 pi (empty when none does).
    """
    a = lo - ANGLE_MARGIN
    b = lo + width + ANGLE_MARGIN
    f0, l0 = _sorted_range(a, b, sorted_angles, step)
    if a < 0.0:
        f1, l1 = _sorted_range(a + _TWO_PI, _TWO_PI, sorted_angles, step)
    elif b >= _TWO_PI:
        f1, l1 = _sorted_range(0.0, b - _TWO_PI, sorted_angles, step)
    else:
        f1, l1 = 0, 0
    return f0, max(l0, f0), f1, max(l1, f1)


@njit(cache=True, fastmath=False)
def _subtended(v1x: float, v1y: float, v2x: float, v2y: float, heading: float):
    """``(lo, width)``: the angles [rad] from ``heading`` (lo wrapped to [0, 2 pi)) of the
    interval a segment from ``v1`` to ``v2`` (relative to the sensor, not through it) spans."""
    a1 = _bearing(v1y, v1x)
    a2 = _bearing(v2y, v2x)
    # The sign of the cross product, not the rounded bearings, says which end is clockwise
    # of the other; this stays right for a sensor next to a long wall (sweep near pi).
    if v1x * v2y - v1y * v2x >= 0.0:
        lo, width = a1, _wrap_positive(a2 - a1)
    else:
        lo, width = a2, _wrap_positive(a1 - a2)
    if width > math.pi:  # rounding: the true sweep is ~pi (or ~0 when nearly collinear)
        width = math.pi if width < 1.5 * math.pi else 0.0
    return _wrap_positive(lo - heading), width


@njit(cache=True, fastmath=False)
def segment_hit(ox: float, oy: float, dx: float, dy: float, x1: float, y1: float, x2: float,
                y2: float, nearer_than: float) -> float:
    """Distance along the unit ray ``o + t d`` to the segment if below ``nearer_than``, else
    inf (parallel rays miss). The segment parameter is only worked out for such a ``t``."""
    ex, ey = x2 - x1, y2 - y1
    denom = dx * ey - dy * ex
    if denom == 0.0:
        return math.inf
    wx, wy = x1 - ox, y1 - oy
    t = (wx * ey - wy * ex) / denom
    if t < 0.0 or t >= nearer_than:
        return math.inf
    u = (wx * dy - wy * dx) / denom
    if u < -_ENDPOINT_TOLERANCE or u > 1.0 + _ENDPOINT_TOLERANCE:
        return math.inf
    return t


@njit(cache=True, fastmath=False, inline="always")
def _circle_window(fx: float, fy: float, d: float, r: float, heading: float):
    """``(lo in [0, 2 pi), width)`` [rad] from ``heading`` of a circle at ``(fx, fy)``, d > r."""
    half = _bearing(r, math.sqrt((d - r) * (d + r)))  # asin(r / d)
    return _wrap_positive(_bearing(fy, fx) - half - heading), 2.0 * half


@njit(cache=True, fastmath=False)
def _circle_lower(ox: float, oy: float, dx: float, dy: float, cx: float, cy: float, r: float,
                  current: float) -> float:
    """A beam's range ``current`` lowered to its exact hit on the circle ``(cx, cy, r)``: the
    distance along the unit ray ``o + t d`` (sensor outside the circle) to where it enters
    the circle, if the ray meets it ahead and nearer than ``current``.

    Both outcomes are computed and one is picked, without a branch: whether a beam of a
    circle's window hits follows no pattern a branch predictor learns, and a mispredicted
    branch costs more than the square root."""
    fx, fy = cx - ox, cy - oy
    b = fx * dx + fy * dy  # distance along the ray to the foot of the centre
    off_ray = fx * dy - fy * dx  # distance of the centre from the ray's line
    # (r - p)(r + p) rather than b^2 - |f|^2 + r^2: no cancellation near tangency.
    disc = (r - off_ray) * (r + off_ray)
    t = b - math.sqrt(max(disc, 0.0))
    return t if (disc >= 0.0) & (b >= 0.0) & (t < current) else current


@njit(cache=True, fastmath=False, inline="always")
def _segment_lower(dx: float, dy: float, v1x: float, v1y: float, ex: float, ey: float,
                   along: float, current: float) -> float:
    """A beam's range ``current`` lowered to its exact hit on a segment from ``v1`` (relative
    to the sensor) along ``(ex, ey)``, for the unit beam direction ``(dx, dy)``; ``along`` is
    ``v1x * ey - v1y * ex``. Both divisions always, the hit picked without a branch (see
    :func:`_circle_lower`); a parallel beam (zero denominator) misses."""
    denom = dx * ey - dy * ex
    divisor = denom if denom != 0.0 else 1.0
    t = along / divisor
    u = (v1x * dy - v1y * dx) / divisor
    hit = (denom != 0.0) & (t >= 0.0) & (t < current) & (
        u >= -_ENDPOINT_TOLERANCE) & (u <= 1.0 + _ENDPOINT_TOLERANCE)
    return t if hit else current


@njit(cache=True, fastmath=False, inline=inline_into_scan_loops)
def beam_directions(
    heading: float, sorted_angles: NDArray[np.float64], order: NDArray[np.int64], step: float,
    cos_beam: NDArray[np.float64], sin_beam: NDArray[np.float64], dir_x: NDArray[np.float64],
    dir_y: NDArray[np.float64],
) -> tuple:
    """``(sorted_angles, order, step, dir_x, dir_y)`` as :func:`cast_sensor` and the sweeps
    take a sensor's beams (see :func:`lidar_env.sensors.lidar_config.beam_geometry`), ``dir_x`` and
    ``dir_y`` filled with their world-frame unit directions for a sensor ``heading`` [rad]."""
    ch, sh = math.cos(heading), math.sin(heading)
    for j in range(cos_beam.shape[0]):
        dir_x[j] = ch * cos_beam[j] - sh * sin_beam[j]
        dir_y[j] = sh * cos_beam[j] + ch * sin_beam[j]
    return sorted_angles, order, step, dir_x, dir_y


@njit(cache=True, fastmath=False, inline=inline_into_scan_loops)
def cast_sensor(
    ranges: NDArray[np.float64],
    pose: tuple[float, float, float],
    circles: NDArray[np.float64],
    segments: NDArray[np.float64],
    first_polygon_edge: int,
    grid: tuple,
    seen: tuple,
    stamp: int,
    own: tuple,
    max_range: float,
    facing: NDArray[np.int64],
    in_order: bool,
) -> None:
    """Fill ``ranges`` (n,) with the exact ranges of one sensor at world ``pose``.

    ``grid`` is a :class:`~lidar_env.world.primitive_grid.PrimitiveGrid` or a plain tuple of its
    fields; ``own`` the sensor's beams from :func:`beam_directions` for ``pose``; ``seen``
    ``(circle_seen, segment_seen)``, int64 arrays as long as ``circles`` and ``segments``
    holding no value >= ``stamp`` (>= 1) and none <= ``-stamp``, so each sensor meets every
    primitive once without clearing them; ``facing``
    :func:`lidar_env.sensors.edge_facing.edge_facing`'s codes for the segments, or empty (then no
    edge is skipped as facing away); ``in_order`` True when the beams' ``order`` is 0, 1, 2, ...
    (the loops over a primitive's beams then index the beams directly: contiguous, vectorised;
    their bounds are unsigned, so numba adds no wrap of negative indices and LLVM vectorises the
    loops, square roots and divisions included).
    """
    ox, oy, heading = pose
    if not (math.isfinite(ox) and math.isfinite(oy) and math.isfinite(heading)):
        raise ConfigError("sensor_poses: expected finite (K, 3) poses, got NaN or inf")
    circle_seen, segment_seen = seen
    if first_polygon_edge < segments.shape[0] and odd_crossings(
            ox, oy, segments, first_polygon_edge, grid, segment_seen, -stamp):
        ranges.fill(0.0)
        return
    ranges.fill(max_range)
    heading = heading % _TWO_PI
    sorted_angles, order, step, dir_x, dir_y = own
    wedge = beam_wedge(sorted_angles, order, dir_x, dir_y)
    cull = wedge[0] < _TWO_PI - _MIN_CULLED_ANGLE
    culls_faces = facing.shape[0] > 0
    x0, y0, size, nx, ny, circle_start, circle_ids, segment_start, segment_ids = grid
    c0, c1, r0, r1, sx, sy = cell_block(ox, oy, max_range, wedge if cull else (_TWO_PI, 1.0,
                                        0.0, 1.0, 0.0), grid[:5])
    pad = 1e-9 * size
    near, n_near = np.empty((6, circles.shape[0])), 0  # the circles the walk keeps
    for iy in range(r0, r1 + 1):
        for column in range(c0, c1 + 1):
            c = iy * nx + column
            listed = (circle_start[c + 1] - circle_start[c]
                      + segment_start[c + 1] - segment_start[c])
            if listed == 0:
                continue
            if cull and (column != sx or iy != sy) and listed > 2:  # costs about two primitives
                bx0, by0 = x0 + column * size - pad - ox, y0 + iy * size - pad - oy
                bx1, by1 = bx0 + size + 2.0 * pad, by0 + size + 2.0 * pad
                if box_outside_wedge(wedge, bx0, by0, bx1, by1):
                    continue
            for p in range(circle_start[c], circle_start[c + 1]):
                i = circle_ids[p]
                if circle_seen[i] == stamp:
                    continue
                circle_seen[i] = stamp
                cx, cy, r = circles[i, 0], circles[i, 1], circles[i, 2]
                if max(abs(cx - ox), abs(cy - oy)) - r >= max_range or (
                        cull and outside_wedge(wedge, cx - ox, cy - oy, cx - ox, cy - oy, r)):
                    continue
                near[0, n_near], near[1, n_near], near[2, n_near] = cx, cy, r
                n_near += 1
            for p in range(segment_start[c], segment_start[c + 1]):
                i = segment_ids[p]
                if segment_seen[i] == stamp:
                    continue
                segment_seen[i] = stamp
                # the segment's sweep (see sweep_circles), on scalars: a row view costs
                x1, y1, x2, y2 = segments[i, 0], segments[i, 1], segments[i, 2], segments[i, 3]
                v1x, v1y, v2x, v2y = x1 - ox, y1 - oy, x2 - ox, y2 - oy
                ex, ey = x2 - x1, y2 - y1
                if culls_faces and facing[i] != 0 and facing[i] * (ex * -v1y + ey * v1x) < (
                        -BACK_FACE_TOLERANCE * (abs(ex) + abs(ey))):
                    continue  # the sensor is on its filled side: it faces away
                if cull and outside_wedge(wedge, v1x, v1y, v2x, v2y, 0.0):
                    continue
                gap = max(min(v1x, v2x), -max(v1x, v2x), min(v1y, v2y), -max(v1y, v2y))
                if gap >= max_range:
                    continue
                # Its distance only matters when the sensor may touch it or it may lie out
                # of range: both are ruled out cheaply for most segments.
                if gap <= _NEAR or min(v1x * v1x + v1y * v1y, v2x * v2x + v2y * v2y) >= (
                        max_range * max_range * _IN_RANGE):
                    d2 = point_segment_distance2(ox, oy, x1, y1, x2, y2)
                    if d2 >= max_range * max_range:
                        continue
                    if d2 == 0.0:
                        ranges.fill(0.0)
                        return
                lo, width = _subtended(v1x, v1y, v2x, v2y, heading)
                f0, l0, f1, l1 = _beam_span(lo, width, sorted_angles, step)
                along = v1x * ey - v1y * ex  # t * denom
                if in_order:
                    for j in range(np.uint64(f0), np.uint64(l0)):
                        ranges[j] = _segment_lower(dir_x[j], dir_y[j], v1x, v1y, ex, ey, along,
                                                   ranges[j])
                    for j in range(np.uint64(f1), np.uint64(l1)):
                        ranges[j] = _segment_lower(dir_x[j], dir_y[j], v1x, v1y, ex, ey, along,
                                                   ranges[j])
                    continue
                for q in range(l0 - f0 + l1 - f1):
                    j = order[f0 + q] if q < l0 - f0 else order[f1 + q - (l0 - f0)]
                    ranges[j] = _segment_lower(dir_x[j], dir_y[j], v1x, v1y, ex, ey, along,
                                               ranges[j])
    if not sweep_circles(ranges, near, n_near, ox, oy, heading, own, max_range, in_order):
        ranges.fill(0.0)


@njit(cache=True, fastmath=False, error_model="numpy")
def _circle_windows(near: NDArray[np.float64], count: int, ox: float, oy: float,
                    heading: float) -> None:
    """Rows 3 to 5 of ``near`` set to the distance [m] and :func:`_circle_window` of each of
    its first ``count`` circles (rows 0 to 2) from the sensor at ``(ox, oy)``: a loop with no
    branch and no zero test, which LLVM vectorises (a circle holding the sensor gets NaN)."""
    for k in range(count):
        fx, fy, r = near[0, k] - ox, near[1, k] - oy, near[2, k]
        d = math.sqrt(fx * fx + fy * fy)
        near[3, k] = d
        near[4, k], near[5, k] = _circle_window(fx, fy, d, r, heading)


@njit(cache=True, fastmath=False, inline=inline_into_scan_loops)
def sweep_circles(ranges: NDArray[np.float64], near: NDArray[np.float64], count: int, ox: float,
                  oy: float, heading: float, own: tuple, max_range: float, in_order: bool) -> bool:
    """Lower ``ranges`` (n,) of a sensor at ``(ox, oy)`` (heading [rad] in [0, 2 pi)) to the
    exact hits on the first ``count`` circles of ``near`` (6, count or more: x, y, radius [m],
    then scratch rows), each for the beams within the angle it subtends only (``own`` and
    ``in_order`` as :func:`cast_sensor` takes them). Returns False (ranges left for the caller
    to zero) when the sensor is inside one. Distances and windows come first, all circles'
    at once (:func:`_circle_windows`): no branch waits on their square roots and divisions."""
    sorted_angles, order, step, dir_x, dir_y = own
    _circle_windows(near, count, ox, oy, heading)
    for k in range(count):
        cx, cy, r, d = near[0, k], near[1, k], near[2, k], near[3, k]
        if d - r >= max_range:
            continue
        if d <= r:
            return False
        f0, l0, f1, l1 = _beam_span(near[4, k], near[5, k], sorted_angles, step)
        if in_order:
            for j in range(np.uint64(f0), np.uint64(l0)):
                ranges[j] = _circle_lower(ox, oy, dir_x[j], dir_y[j], cx, cy, r, ranges[j])
            for j in range(np.uint64(f1), np.uint64(l1)):
                ranges[j] = _circle_lower(ox, oy, dir_x[j], dir_y[j], cx, cy, r, ranges[j])
            continue
        for q in range(l0 - f0 + l1 - f1):
            j = order[f0 + q] if q < l0 - f0 else order[f1 + q - (l0 - f0)]
            ranges[j] = _circle_lower(ox, oy, dir_x[j], dir_y[j], cx, cy, r, ranges[j])
    return True
