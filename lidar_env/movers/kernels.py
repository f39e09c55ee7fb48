"""Compiled geometry and motion of the moving obstacles (pedestrians): plain arrays in and out.

A mover is a circle of radius ``radius`` [m] at ``positions[i]`` (x, y) [m], world frame,
walking at ``speeds[i]`` [m/s] towards ``waypoints[i]``. :func:`step_movers` advances all of
them by one control step ``dt`` [s], one after the other in index order, each along a straight
line at a constant velocity: the first heading of a fan around the waypoint's direction whose
next ``LOOKAHEAD`` seconds stay clear of walls, circles, polygon edges, the map's bounds and the
other movers (their velocities extrapolated) is taken, so a mover turns away before it gets
close; failing that, a half-speed step that is merely safe; failing that, it stands still.

The guarantee (tested): no mover ever comes within :data:`HARD_GAP` of a static surface or of
another mover, at any instant, not only at the step ends. A move is accepted only if its swept
circle clears every static primitive (exact segment-to-circle and segment-to-segment
distances), stays in the bounds, and keeps its distance from every mover already moved this
step (exact closest approach of the two linear motions over ``[0, dt]``) and from every mover
still to move, taken as standing: if that one then moves, its own check is against this motion.

Static primitives come from the world's :class:`~lidar_env.world.primitive_grid.PrimitiveGrid`
(the cells near the mover), so a map of thousands of edges costs little more than a few.

The car (motion model "yielding", :mod:`lidar_env.movers.crowd`): ``car`` is a ``(K, 5)`` array of
circles x, y [m], vx, vy [m/s], radius [m] that cover the car's box (the env gives them zero
velocity: the car as it stands; empty for "waypoints": the car is ignored). A yielding mover
takes the car's circles like movers already moved: its look-ahead keeps :data:`CAR_COMFORT_GAP`
from them, and its step keeps :data:`CAR_HARD_GAP` (or, nearer already, does not get closer),
so a mover never walks into the car; the car can still drive into a mover.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from lidar_env.world.primitive_grid import PrimitiveGrid, grid_cell, segment_distance2

#: [m] least distance a mover keeps from any surface and from other movers, at every instant.
HARD_GAP = 1e-3
#: [m] extra distance a mover plans to keep (its look-ahead and its waypoints).
COMFORT_GAP = 0.1
#: [s] how far ahead a mover checks the heading it takes.
LOOKAHEAD = 1.0
#: [rad] headings tried, relative to the waypoint's direction, in order (right first, as
#: pedestrians keep right).
HEADING_FAN = np.array([0.0, -1.0, 1.0, -2.0, 2.0, -3.0, 3.0, -4.0, 4.0, -5.0, 5.0, -6.0, 6.0]
                       ) * (math.pi / 8.0)
#: [-] a mover that gained less than this fraction of its step towards its waypoint is stuck;
#: after :data:`STUCK_STEPS` stuck steps in a row it picks a new waypoint.
STUCK_FRACTION = 0.25
STUCK_STEPS = 10
#: [m] distance a yielding mover plans to keep from the car's circles over its look-ahead.
CAR_COMFORT_GAP = 0.3
#: [m] least distance a yielding mover's step keeps from the car's circles (circles given a
#: velocity move in a straight line over the step, while a car drives an arc: at most about
#: 5 mm apart for a 0.15 m step on the tightest 1 m turn, which this covers).
CAR_HARD_GAP = 0.02
#: [m] (min, max) distance of a new waypoint from the mover.
WAYPOINT_REACH = (1.0, 10.0)


@njit(cache=True, fastmath=False)
def _segments_cross(p: NDArray[np.float64], q: NDArray[np.float64]) -> bool:
    """Segments ``p`` and ``q`` (x1, y1, x2, y2) properly cross each other."""
    ex, ey = p[2] - p[0], p[3] - p[1]
    fx, fy = q[2] - q[0], q[3] - q[1]
    s1 = ex * (q[1] - p[1]) - ey * (q[0] - p[0])
    s2 = ex * (q[3] - p[1]) - ey * (q[2] - p[0])
    s3 = fx * (p[1] - q[1]) - fy * (p[0] - q[0])
    s4 = fx * (p[3] - q[1]) - fy * (p[2] - q[0])
    return s1 * s2 < 0.0 and s3 * s4 < 0.0


@njit(cache=True, fastmath=False)
def _segments_distance(p: NDArray[np.float64], q: NDArray[np.float64]) -> float:
    """[m] distance between segments ``p`` and ``q`` (0 when they cross)."""
    if _segments_cross(p, q):
        return 0.0
    d2 = min(segment_distance2(p[0], p[1], q), segment_distance2(p[2], p[3], q),
             segment_distance2(q[0], q[1], p), segment_distance2(q[2], q[3], p))
    return math.sqrt(d2)


@njit(cache=True, fastmath=False)
def gather_statics(
    x_lo: float, y_lo: float, x_hi: float, y_hi: float, grid: PrimitiveGrid,
    scratch: tuple, stamp: int,
) -> tuple[int, int]:
    """Ids of the circles and segments listed in the grid cells over the box, written to
    ``scratch[2]`` and ``scratch[3]`` (``scratch`` as :func:`new_mover_scratch`); their counts.

    ``stamp`` must differ between calls that share ``scratch``.
    """
    circle_seen, segment_seen, circle_ids, segment_ids = scratch
    c0, c1 = grid_cell(x_lo, grid.x0, grid.cell, grid.nx), grid_cell(x_hi, grid.x0, grid.cell,
                                                                     grid.nx)
    r0, r1 = grid_cell(y_lo, grid.y0, grid.cell, grid.ny), grid_cell(y_hi, grid.y0, grid.cell,
                                                                     grid.ny)
    n_circles, n_segments = 0, 0
    for row in range(r0, r1 + 1):
        for c in range(row * grid.nx + c0, row * grid.nx + c1 + 1):
            for p in range(grid.circle_start[c], grid.circle_start[c + 1]):
                i = grid.circle_ids[p]
                if circle_seen[i] != stamp:
                    circle_seen[i] = stamp
                    circle_ids[n_circles] = i
                    n_circles += 1
            for p in range(grid.segment_start[c], grid.segment_start[c + 1]):
                i = grid.segment_ids[p]
                if segment_seen[i] != stamp:
                    segment_seen[i] = stamp
                    segment_ids[n_segments] = i
                    n_segments += 1
    return n_circles, n_segments


@njit(cache=True, fastmath=False)
def new_mover_scratch(circles: NDArray[np.float64], segments: NDArray[np.float64]) -> tuple:
    """Work arrays of :func:`gather_statics` (seen stamps, id lists)."""
    return (np.zeros(circles.shape[0], dtype=np.int64),
            np.zeros(segments.shape[0], dtype=np.int64),
            np.empty(circles.shape[0], dtype=np.int64),
            np.empty(segments.shape[0], dtype=np.int64))


@njit(cache=True, fastmath=False)
def path_clearance(
    path: NDArray[np.float64], circles: NDArray[np.float64], segments: NDArray[np.float64],
    scratch: tuple, n_circles: int, n_segments: int, bounds: NDArray[np.float64], cap: float,
) -> float:
    """[m] least distance from the segment ``path`` (x1, y1, x2, y2) to the surfaces of the
    gathered statics and to the edges of ``bounds`` (xmin, ymin, xmax, ymax; negative when an
    end lies outside), or ``cap`` if that is less (primitives farther than ``cap`` are skipped
    by their bounding boxes). A zero-length path is a point."""
    best = cap
    for end in range(2):
        x, y = path[2 * end], path[2 * end + 1]
        best = min(best, x - bounds[0], bounds[2] - x, y - bounds[1], bounds[3] - y)
    x_lo, x_hi = min(path[0], path[2]), max(path[0], path[2])
    y_lo, y_hi = min(path[1], path[3]), max(path[1], path[3])
    circle_ids, segment_ids = scratch[2], scratch[3]
    for k in range(n_circles):
        i = circle_ids[k]
        cx, cy, r = circles[i, 0], circles[i, 1], circles[i, 2]
        if max(x_lo - cx, cx - x_hi, y_lo - cy, cy - y_hi) - r >= best:
            continue
        best = min(best, math.sqrt(segment_distance2(cx, cy, path)) - r)
    for k in range(n_segments):
        seg = segments[segment_ids[k]]
        if max(min(seg[0], seg[2]) - x_hi, x_lo - max(seg[0], seg[2]),
               min(seg[1], seg[3]) - y_hi, y_lo - max(seg[1], seg[3])) >= best:
            continue
        best = min(best, _segments_distance(path, seg))
    return best


@njit(cache=True, fastmath=False)
def closest_approach2(dx: float, dy: float, vx: float, vy: float, duration: float) -> float:
    """[m^2] least squared distance over ``t`` in [0, duration] of the relative position
    ``d + v t``."""
    vv = vx * vx + vy * vy
    t = 0.0 if vv == 0.0 else min(max(-(dx * vx + dy * vy) / vv, 0.0), duration)
    ex, ey = dx + vx * t, dy + vy * t
    return ex * ex + ey * ey


@njit(cache=True, fastmath=False)
def _movers_clear(i: int, vx: float, vy: float, positions: NDArray[np.float64],
                  velocities: NDArray[np.float64], standing_from: int, duration: float,
                  least: float) -> bool:
    """Mover ``i`` moving at (vx, vy) for ``duration`` [s] keeps ``least`` [m] (centre to
    centre) from every other mover, those from ``standing_from`` on taken as standing and the
    rest at ``velocities``; or, already nearer than that, at least does not get closer."""
    least2 = least * least
    for j in range(positions.shape[0]):
        if j == i:
            continue
        dx, dy = positions[i, 0] - positions[j, 0], positions[i, 1] - positions[j, 1]
        wx, wy = vx, vy
        if j < standing_from:
            wx, wy = vx - velocities[j, 0], vy - velocities[j, 1]
        d2 = dx * dx + dy * dy
        bound = least + (abs(wx) + abs(wy)) * duration  # no closer than |d| - |w| duration
        if d2 > bound * bound:
            continue
        gap2 = closest_approach2(dx, dy, wx, wy, duration)
        if gap2 < least2 and gap2 < d2 - 1e-12:
            return False
    return True


@njit(cache=True, fastmath=False)
def _car_clear(px: float, py: float, vx: float, vy: float, radius: float,
               car: NDArray[np.float64], duration: float, gap: float) -> bool:
    """A mover of ``radius`` at (px, py) moving at (vx, vy) for ``duration`` [s] keeps ``gap``
    [m] from every circle of ``car`` (rows x, y, vx, vy, radius); or, nearer already, does not
    get closer."""
    for k in range(car.shape[0]):
        dx, dy = px - car[k, 0], py - car[k, 1]
        least = radius + car[k, 4] + gap
        d2 = dx * dx + dy * dy
        gap2 = closest_approach2(dx, dy, vx - car[k, 2], vy - car[k, 3], duration)
        if gap2 < least * least and gap2 < d2 - 1e-12:
            return False
    return True


@njit(cache=True, fastmath=False)
def step_movers(
    positions: NDArray[np.float64], velocities: NDArray[np.float64],
    waypoints: NDArray[np.float64], speeds: NDArray[np.float64], stuck: NDArray[np.int64],
    radius: float, dt: float, bounds: NDArray[np.float64], circles: NDArray[np.float64],
    segments: NDArray[np.float64], grid: PrimitiveGrid, car: NDArray[np.float64],
) -> NDArray[np.bool_]:
    """Move every mover one step ``dt`` [s] (see the module docstring; ``car`` (K, 5) the car's
    moving circles, K = 0 to ignore it); ``positions``,
    ``velocities`` (the velocity held over this step) and ``stuck`` are updated in place.

    Returns ``(M,)`` True for each mover that reached its waypoint or has been stuck for
    :data:`STUCK_STEPS` steps: it needs a new waypoint (:func:`choose_waypoints`).
    """
    m = positions.shape[0]
    needs = np.zeros(m, dtype=np.bool_)
    scratch = new_mover_scratch(circles, segments)
    path = np.empty(4)
    hard = radius + HARD_GAP
    comfort = radius + COMFORT_GAP
    for i in range(m):
        px, py = positions[i, 0], positions[i, 1]
        speed = speeds[i]
        to_x, to_y = waypoints[i, 0] - px, waypoints[i, 1] - py
        distance = math.hypot(to_x, to_y)
        look = min(speed * LOOKAHEAD, distance)
        reach = max(look, speed * dt) + comfort
        n_c, n_s = gather_statics(px - reach, py - reach, px + reach, py + reach, grid, scratch,
                                  i + 1)
        path[0], path[1], path[2], path[3] = px, py, px, py
        here = path_clearance(path, circles, segments, scratch, n_c, n_s, bounds, comfort)
        base = math.atan2(to_y, to_x)
        vx, vy, chosen = 0.0, 0.0, False
        for attempt in range(2):  # full speed with look-ahead, then half speed merely safe
            scale = 1.0 if attempt == 0 else 0.5
            for offset in HEADING_FAN:
                cx, cy = math.cos(base + offset), math.sin(base + offset)
                wx, wy = scale * speed * cx, scale * speed * cy
                if attempt == 0 and look > 0.0:
                    path[2], path[3] = px + look * cx, py + look * cy
                    ahead = path_clearance(path, circles, segments, scratch, n_c, n_s, bounds,
                                           comfort)
                    if ahead < min(comfort, here) or not _movers_clear(
                            i, wx, wy, positions, velocities, m, look / speed,
                            2.0 * radius + COMFORT_GAP) or not _car_clear(
                            px, py, wx, wy, radius, car, look / speed, CAR_COMFORT_GAP):
                        continue
                path[2], path[3] = px + wx * dt, py + wy * dt
                if path_clearance(path, circles, segments, scratch, n_c, n_s, bounds,
                                  hard) < min(hard, here):
                    continue
                if not _movers_clear(i, wx, wy, positions, velocities, i + 1, dt,
                                     2.0 * radius + HARD_GAP) or not _car_clear(
                                         px, py, wx, wy, radius, car, dt, CAR_HARD_GAP):
                    continue
                vx, vy, chosen = wx, wy, True
                break
            if chosen or speed == 0.0:
                break
        velocities[i, 0], velocities[i, 1] = vx, vy
        gained = distance - math.hypot(waypoints[i, 0] - px - vx * dt,
                                       waypoints[i, 1] - py - vy * dt)
        stuck[i] = stuck[i] + 1 if gained < STUCK_FRACTION * speed * dt else 0
        needs[i] = distance <= speed * dt or stuck[i] >= STUCK_STEPS
    for i in range(m):
        positions[i, 0] += velocities[i, 0] * dt
        positions[i, 1] += velocities[i, 1] * dt
    return needs


@njit(cache=True, fastmath=False)
def choose_waypoints(
    positions: NDArray[np.float64], waypoints: NDArray[np.float64], needs: NDArray[np.bool_],
    draws: NDArray[np.float64], reach: tuple[float, float], radius: float,
    bounds: NDArray[np.float64], circles: NDArray[np.float64], segments: NDArray[np.float64],
    grid: PrimitiveGrid,
) -> None:
    """A new waypoint for each mover with ``needs[i]``, from its row of ``draws``
    (``(needs.sum(), C, 2)`` uniforms in [0, 1): distance in ``reach`` (min, max) [m], then
    direction): the first candidate in free space that the mover can walk to in a straight line
    with :data:`COMFORT_GAP` to spare. A mover whose C candidates all fail keeps its waypoint
    and its ``needs`` flag (it tries again next step)."""
    scratch = new_mover_scratch(circles, segments)
    path = np.empty(4)
    row = 0
    for i in range(positions.shape[0]):
        if not needs[i]:
            continue
        px, py = positions[i, 0], positions[i, 1]
        for c in range(draws.shape[1]):
            length = reach[0] + (reach[1] - reach[0]) * draws[row, c, 0]
            angle = 2.0 * math.pi * draws[row, c, 1]
            qx, qy = px + length * math.cos(angle), py + length * math.sin(angle)
            n_c, n_s = gather_statics(min(px, qx) - radius - COMFORT_GAP,
                                      min(py, qy) - radius - COMFORT_GAP,
                                      max(px, qx) + radius + COMFORT_GAP,
                                      max(py, qy) + radius + COMFORT_GAP, grid, scratch,
                                      row * draws.shape[1] + c + 1)
            path[0], path[1], path[2], path[3] = px, py, qx, qy
            if path_clearance(path, circles, segments, scratch, n_c, n_s, bounds,
                              radius + COMFORT_GAP) >= radius + COMFORT_GAP:
                waypoints[i, 0], waypoints[i, 1] = qx, qy
                needs[i] = False
                break
        row += 1


@njit(cache=True, fastmath=False)
def place_movers(
    candidates: NDArray[np.float64], out: NDArray[np.float64], radius: float,
    car: NDArray[np.float64], anchors: NDArray[np.float64], bounds: NDArray[np.float64],
    circles: NDArray[np.float64], segments: NDArray[np.float64], grid: PrimitiveGrid,
) -> int:
    """Fill ``out`` (M, 2) with the first candidates (N, 2) [m] where a mover fits; return how
    many were placed (at most M).

    A mover fits where it keeps :data:`COMFORT_GAP` from every static surface, the bounds and
    the movers placed before it, keeps ``car[5]`` [m] from the car's box ``car[:5]`` (x, y,
    heading, half length, half width), and can walk in a straight line to the nearest of
    ``anchors`` (K, 2) (the trace's points: so it lies in the region the car drives through,
    not outside a closed world or inside a polygon).
    """
    scratch = new_mover_scratch(circles, segments)
    path = np.empty(4)
    need = radius + COMFORT_GAP
    c, s = math.cos(car[2]), math.sin(car[2])
    placed = 0
    for k in range(candidates.shape[0]):
        if placed == out.shape[0]:
            break
        px, py = candidates[k, 0], candidates[k, 1]
        lx, ly = c * (px - car[0]) + s * (py - car[1]), -s * (px - car[0]) + c * (py - car[1])
        ex, ey = max(abs(lx) - car[3], 0.0), max(abs(ly) - car[4], 0.0)
        if math.hypot(ex, ey) < radius + car[5]:
            continue
        crowded = False
        for j in range(placed):
            if math.hypot(px - out[j, 0], py - out[j, 1]) < 2.0 * radius + COMFORT_GAP:
                crowded = True
                break
        if crowded:
            continue
        nearest, best = 0, math.inf
        for a in range(anchors.shape[0]):
            d2 = (anchors[a, 0] - px) ** 2 + (anchors[a, 1] - py) ** 2
            if d2 < best:
                nearest, best = a, d2
        path[0], path[1] = px, py
        path[2], path[3] = anchors[nearest, 0], anchors[nearest, 1]
        n_c, n_s = gather_statics(min(path[0], path[2]) - need, min(path[1], path[3]) - need,
                                  max(path[0], path[2]) + need, max(path[1], path[3]) + need,
                                  grid, scratch, k + 1)
        if path_clearance(path, circles, segments, scratch, n_c, n_s, bounds, need) < need:
            continue
        out[placed, 0], out[placed, 1] = px, py
        placed += 1
    return placed


@njit(cache=True, fastmath=False)
def advance_crowd(
    positions: NDArray[np.float64], velocities: NDArray[np.float64],
    waypoints: NDArray[np.float64], speeds: NDArray[np.float64], stuck: NDArray[np.int64],
    needs: NDArray[np.bool_], draws: NDArray[np.float64], radius: float, dt: float,
    bounds: NDArray[np.float64], circles: NDArray[np.float64], segments: NDArray[np.float64],
    grid: PrimitiveGrid, car: NDArray[np.float64],
) -> None:
    """One crowd step in one call: :func:`choose_waypoints` for the movers with ``needs``
    (``draws`` holds their rows; empty when none needs one), then :func:`step_movers` (``car``
    as there); ``needs`` is updated in place."""
    if draws.shape[0] > 0:
        choose_waypoints(positions, waypoints, needs, draws, WAYPOINT_REACH, radius, bounds,
                         circles, segments, grid)
    needs |= step_movers(positions, velocities, waypoints, speeds, stuck, radius, dt, bounds,
                         circles, segments, grid, car)
