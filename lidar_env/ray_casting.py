"""The Lidar's compiled ray caster: exact beam ranges against circles and segments (numba).

Instead of testing every beam against every primitive, :func:`cast_rays_kernel` sweeps the
primitives: each one within ``max_range`` updates only the beams inside the angular interval it
subtends from the sensor, found by index arithmetic for uniformly spaced beams and by binary
search otherwise. Every candidate beam then gets the exact ray-circle or ray-segment
intersection, so the interval only has to be conservative (it is widened by
:data:`_ANGLE_MARGIN`). The candidate primitives come from the cells of the world's
:class:`~lidar_env.primitive_grid.PrimitiveGrid` that overlap the sensor's range box.
:func:`scan_kernel` turns the exact ranges into noisy float32 readings in the same pass.

Units and frames: positions and ranges in metres, angles in radians, world frame; a sensor pose
is ``(x, y, heading)``, beam ``j`` points at world angle ``heading + beam_angles[j]``. The
callers' validated entry points are :func:`lidar_env.lidar.cast_rays` and
:meth:`lidar_env.lidar.Lidar.scan`.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from numba import njit
from numpy.typing import NDArray

from lidar_env.errors import ConfigError
from lidar_env.primitive_grid import PrimitiveGrid, grid_cell, odd_crossings, segment_distance2

#: Extra angle [rad] each subtended interval is widened by. It covers the error of
#: :func:`_bearing` (< 1.7e-6 rad) so no beam that grazes a primitive is dropped; the exact
#: intersection test then decides the hit, so the margin costs only rare extra tests.
_ANGLE_MARGIN = 1e-5
#: Relative tolerance on the segment parameter so a beam through an end point still hits it.
_ENDPOINT_TOLERANCE = 1e-12
_TWO_PI = 2.0 * math.pi


@njit(cache=True, fastmath=False)
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
    """``angle`` in ``[-3 pi, 3 pi)`` wrapped to ``[0, 2 pi)`` without a float modulo."""
    while angle < 0.0:
        angle += _TWO_PI
    while angle >= _TWO_PI:
        angle -= _TWO_PI
    return angle


@njit(cache=True, fastmath=False)
def _beam_order(beam_angles: NDArray[np.float64]) -> tuple:
    """Beam angles wrapped to [0, 2 pi), sorted; their order; and the uniform step (0 if not)."""
    n = beam_angles.shape[0]
    wrapped = np.empty(n)
    for j in range(n):
        wrapped[j] = beam_angles[j] % _TWO_PI
    order = np.argsort(wrapped, kind="mergesort")
    sorted_angles = wrapped[order]
    step = (sorted_angles[n - 1] - sorted_angles[0]) / (n - 1) if n > 1 else 0.0
    uniform = step > 0.0
    for j in range(n):
        if abs(sorted_angles[j] - (sorted_angles[0] + j * step)) > 1e-12 * _TWO_PI:
            uniform = False
            break
    return sorted_angles, order, step if uniform else 0.0


@njit(cache=True, fastmath=False)
def _sorted_range(
    lo: float, hi: float, sorted_angles: NDArray[np.float64], step: float
) -> tuple[int, int]:
    """Positions ``[first, last)`` in ``sorted_angles`` of the angles within ``[lo, hi]``."""
    n = sorted_angles.shape[0]
    if step > 0.0:
        first = max(0, int(math.ceil((lo - sorted_angles[0]) / step)))
        last = min(n, int(math.floor((hi - sorted_angles[0]) / step)) + 1)
        return first, last
    return np.searchsorted(sorted_angles, lo, "left"), np.searchsorted(sorted_angles, hi, "right")


@njit(cache=True, fastmath=False)
def _beam_span(
    lo: float, width: float, sorted_angles: NDArray[np.float64], step: float
) -> tuple[int, int, int, int]:
    """Sorted-beam positions ``[f0, l0)`` and ``[f1, l1)`` of the beams within the interval
    ``[lo, lo + width]`` (``lo`` in [0, 2 pi), ``width`` <= pi) widened by the margin.

    The second range is the part that wraps past 0 or 2 pi (empty when none does).
    """
    a = lo - _ANGLE_MARGIN
    b = lo + width + _ANGLE_MARGIN
    f0, l0 = _sorted_range(a, b, sorted_angles, step)
    if a < 0.0:
        f1, l1 = _sorted_range(a + _TWO_PI, _TWO_PI, sorted_angles, step)
    elif b >= _TWO_PI:
        f1, l1 = _sorted_range(0.0, b - _TWO_PI, sorted_angles, step)
    else:
        f1, l1 = 0, 0
    return f0, l0, f1, max(l1, f1)


@njit(cache=True, fastmath=False)
def _circle_hit(ox: float, oy: float, dx: float, dy: float, cx: float, cy: float, r: float):
    """Distance along the unit ray ``o + t d`` to the circle (sensor outside), or inf."""
    fx, fy = cx - ox, cy - oy
    b = fx * dx + fy * dy  # distance along the ray to the foot of the centre
    off_ray = fx * dy - fy * dx  # distance of the centre from the ray's line
    # (r - p)(r + p) rather than b^2 - |f|^2 + r^2: no cancellation near tangency.
    disc = (r - off_ray) * (r + off_ray)
    if disc < 0.0 or b < 0.0:
        return math.inf
    return b - math.sqrt(disc)


@njit(cache=True, fastmath=False)
def _segment_hit(ox: float, oy: float, dx: float, dy: float, seg: NDArray[np.float64]):
    """Distance along the unit ray ``o + t d`` to the segment, or inf (parallel rays miss)."""
    ex, ey = seg[2] - seg[0], seg[3] - seg[1]
    denom = dx * ey - dy * ex
    if denom == 0.0:
        return math.inf
    wx, wy = seg[0] - ox, seg[1] - oy
    t = (wx * ey - wy * ex) / denom
    u = (wx * dy - wy * dx) / denom
    if t < 0.0 or u < -_ENDPOINT_TOLERANCE or u > 1.0 + _ENDPOINT_TOLERANCE:
        return math.inf
    return t


@njit(cache=True, fastmath=False)
def _gather(
    start: NDArray[np.int64],
    ids: NDArray[np.int64],
    columns: tuple[int, int],
    rows: tuple[int, int],
    nx: int,
    seen: NDArray[np.int64],
    stamp: int,
    out: NDArray[np.int64],
) -> int:
    """Write the distinct ids listed in a block of grid cells to ``out``; return how many."""
    count = 0
    for row in range(rows[0], rows[1] + 1):
        for c in range(row * nx + columns[0], row * nx + columns[1] + 1):
            for p in range(start[c], start[c + 1]):
                i = ids[p]
                if seen[i] != stamp:
                    seen[i] = stamp
                    out[count] = i
                    count += 1
    return count


@njit(cache=True, fastmath=False)
def sweep_circle(
    ranges: NDArray[np.float64],
    ox: float, oy: float, ch: float, sh: float, heading: float,
    cx: float, cy: float, r: float,
    sorted_angles: NDArray[np.float64],
    order: NDArray[np.int64],
    step: float,
    cos_beam: NDArray[np.float64],
    sin_beam: NDArray[np.float64],
    max_range: float,
) -> bool:
    """Lower ``ranges`` (n,) of a sensor at ``(ox, oy)`` (heading [rad] in [0, 2 pi), its
    cosine ``ch`` and sine ``sh``) to the exact hits on the circle ``(cx, cy, r)`` [m], for the
    beams within the angle it subtends only. Returns False (all ranges 0) when the sensor is
    inside the circle."""
    fx, fy = cx - ox, cy - oy
    d = math.sqrt(fx * fx + fy * fy)
    if d - r >= max_range:
        return True
    if d <= r:
        ranges[:] = 0.0
        return False
    half = _bearing(r, math.sqrt((d - r) * (d + r)))  # asin(r / d)
    lo = _wrap_positive(_bearing(fy, fx) - half - heading)
    f0, l0, f1, l1 = _beam_span(lo, 2.0 * half, sorted_angles, step)
    n0 = max(l0 - f0, 0)
    for q in range(n0 + l1 - f1):
        j = order[f0 + q] if q < n0 else order[f1 + q - n0]
        dx = ch * cos_beam[j] - sh * sin_beam[j]
        dy = sh * cos_beam[j] + ch * sin_beam[j]
        t = _circle_hit(ox, oy, dx, dy, cx, cy, r)
        if t < ranges[j]:
            ranges[j] = t
    return True


@njit(cache=True, fastmath=False)
def _scan_one(
    ranges: NDArray[np.float64],
    ox: float,
    oy: float,
    heading: float,
    circles: NDArray[np.float64],
    segments: NDArray[np.float64],
    circle_ids: NDArray[np.int64],
    segment_ids: NDArray[np.int64],
    sorted_angles: NDArray[np.float64],
    order: NDArray[np.int64],
    step: float,
    cos_beam: NDArray[np.float64],
    sin_beam: NDArray[np.float64],
    max_range: float,
) -> None:
    """Fill ``ranges`` (n,) for one sensor at ``(ox, oy, heading)`` from the candidate
    primitives ``circle_ids`` and ``segment_ids``; see :func:`cast_rays`."""
    ranges[:] = max_range
    ch, sh = math.cos(heading), math.sin(heading)
    heading = heading % _TWO_PI
    for i in circle_ids:
        cx, cy, r = circles[i, 0], circles[i, 1], circles[i, 2]
        if max(abs(cx - ox), abs(cy - oy)) - r >= max_range:  # a cheap bounding-box test first
            continue
        if not sweep_circle(ranges, ox, oy, ch, sh, heading, cx, cy, r, sorted_angles, order,
                            step, cos_beam, sin_beam, max_range):
            return
    for i in segment_ids:
        seg = segments[i]
        # A cheap bounding-box test first (few branches), then the exact distance.
        gap_x = max(min(seg[0], seg[2]) - ox, ox - max(seg[0], seg[2]))
        gap_y = max(min(seg[1], seg[3]) - oy, oy - max(seg[1], seg[3]))
        if max(gap_x, gap_y) >= max_range:
            continue
        d2 = segment_distance2(ox, oy, seg)
        if d2 >= max_range * max_range:
            continue
        if d2 == 0.0:
            ranges[:] = 0.0
            return
        v1x, v1y, v2x, v2y = seg[0] - ox, seg[1] - oy, seg[2] - ox, seg[3] - oy
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
        lo = _wrap_positive(lo - heading)
        f0, l0, f1, l1 = _beam_span(lo, width, sorted_angles, step)
        n0 = max(l0 - f0, 0)
        for q in range(n0 + l1 - f1):
            j = order[f0 + q] if q < n0 else order[f1 + q - n0]
            dx = ch * cos_beam[j] - sh * sin_beam[j]
            dy = sh * cos_beam[j] + ch * sin_beam[j]
            t = _segment_hit(ox, oy, dx, dy, seg)
            if t < ranges[j]:
                ranges[j] = t


@njit(cache=True, fastmath=False)
def cast_sensor(
    ranges: NDArray[np.float64],
    pose: tuple[float, float, float],
    circles: NDArray[np.float64],
    segments: NDArray[np.float64],
    first_polygon_edge: int,
    grid: PrimitiveGrid,
    scratch: tuple,
    stamp: int,
    beams: tuple,
    max_range: float,
) -> None:
    """Fill ``ranges`` (n,) with the exact ranges of one sensor at world ``pose``.

    ``scratch`` is ``(circle_seen, segment_seen, circle_ids, segment_ids)``, int64 arrays as
    long as ``circles`` and ``segments``; ``stamp`` (>= 1) must differ between the sensors of
    one call, so each gathers its candidates afresh without clearing ``seen``.
    """
    ox, oy, heading = pose
    if not (math.isfinite(ox) and math.isfinite(oy) and math.isfinite(heading)):
        raise ConfigError("sensor_poses: expected finite (K, 3) poses, got NaN or inf")
    circle_seen, segment_seen, circle_ids, segment_ids = scratch
    if odd_crossings(ox, oy, segments, first_polygon_edge, grid, segment_seen, -stamp):
        ranges[:] = 0.0
        return
    # Only primitives in the grid cells that overlap the sensor's range box can be seen.
    columns = (grid_cell(ox - max_range, grid.x0, grid.cell, grid.nx),
               grid_cell(ox + max_range, grid.x0, grid.cell, grid.nx))
    rows = (grid_cell(oy - max_range, grid.y0, grid.cell, grid.ny),
            grid_cell(oy + max_range, grid.y0, grid.cell, grid.ny))
    n_circles = _gather(grid.circle_start, grid.circle_ids, columns, rows, grid.nx,
                        circle_seen, stamp, circle_ids)
    n_segments = _gather(grid.segment_start, grid.segment_ids, columns, rows, grid.nx,
                         segment_seen, stamp, segment_ids)
    sorted_angles, order, step, cos_beam, sin_beam = beams
    _scan_one(ranges, ox, oy, heading, circles, segments, circle_ids[:n_circles],
              segment_ids[:n_segments], sorted_angles, order, step, cos_beam, sin_beam,
              max_range)


@njit(cache=True, fastmath=False)
def new_scratch(circles: NDArray[np.float64], segments: NDArray[np.float64]) -> tuple:
    """The work arrays of :func:`cast_sensor` for one call over several sensors."""
    return (np.zeros(circles.shape[0], dtype=np.int64),
            np.zeros(segments.shape[0], dtype=np.int64),
            np.empty(circles.shape[0], dtype=np.int64),
            np.empty(segments.shape[0], dtype=np.int64))


@njit(cache=True, fastmath=False)
def cast_rays_kernel(
    circles: NDArray[np.float64],
    segments: NDArray[np.float64],
    first_polygon_edge: int,
    grid: PrimitiveGrid,
    sensor_poses: NDArray[np.float64],
    beams: tuple,
    max_range: float,
) -> NDArray[np.float64]:
    """``(K, n)`` exact ranges of sensors at ``sensor_poses`` that share one beam set."""
    out = np.empty((sensor_poses.shape[0], beams[3].shape[0]))
    scratch = new_scratch(circles, segments)
    for k in range(sensor_poses.shape[0]):
        pose = (sensor_poses[k, 0], sensor_poses[k, 1], sensor_poses[k, 2])
        cast_sensor(out[k], pose, circles, segments, first_polygon_edge, grid, scratch, k + 1,
                    beams, max_range)
    return out


@njit(cache=True, fastmath=False)
def scan_kernel(
    circles: NDArray[np.float64],
    segments: NDArray[np.float64],
    first_polygon_edge: int,
    grid: PrimitiveGrid,
    sensor_poses: NDArray[np.float64],
    beams: tuple,
    max_range: float,
    below_max: float,
    noise_std: float,
    gaussians: NDArray[np.float64],
    dropout_prob: float,
    uniforms: NDArray[np.float64],
) -> NDArray[np.float32]:
    """The exact ranges of :func:`cast_rays_kernel` turned into float32 readings in one pass.

    A hit gets ``noise_std * gaussians[k, j]`` added (only when ``gaussians`` is not empty) and
    is clipped to ``[0, below_max]``; then a beam with ``uniforms[k, j] < dropout_prob`` (only
    when ``uniforms`` is not empty) reads ``max_range``. Returns a new ``(K, n)`` array.
    """
    ranges = cast_rays_kernel(
        circles, segments, first_polygon_edge, grid, sensor_poses, beams, max_range
    )
    noisy = gaussians.size > 0
    dropping = uniforms.size > 0
    out = np.empty(ranges.shape, dtype=np.float32)
    for k in range(ranges.shape[0]):
        for j in range(ranges.shape[1]):
            r = ranges[k, j]
            if r < max_range:
                if noisy:
                    r += noise_std * gaussians[k, j]
                r = min(max(r, 0.0), below_max)
            if dropping and uniforms[k, j] < dropout_prob:
                r = max_range
            out[k, j] = r
    return out


@lru_cache(maxsize=16)
def beam_geometry(angle_bytes: bytes) -> tuple:
    """Sorted wrapped angles, their order, the uniform step (0 if not uniform), cos and sin.

    Cached by the angles' bytes: a Lidar's beams are set up once, not on every scan.
    """
    angles = np.frombuffer(angle_bytes, dtype=np.float64)
    if len(angles) == 0 or not np.all(np.isfinite(angles)):
        raise ConfigError(
            f"beam_angles: expected a non-empty finite 1-D array [rad], got {angles}"
        )
    sorted_angles, order, step = _beam_order(angles)
    return sorted_angles, order, step, np.cos(angles), np.sin(angles)
