"""Routes the user brings: ``(N, 2)`` waypoints [m] or a :class:`Trace`, checked and smoothed.

:func:`waypoint_trace` checks the polyline through the waypoints for clearance like the trace
seeds (every point of every segment at least ``clearance`` [m] from obstacles and the map's
edge; the error names the first blocked segment and where), then rounds each corner with a
circular arc (radius :data:`CORNER_RADIUS` x the car's body scale, ``EnvConfig.body_scale``;
smaller where the legs are short) so that the car can drive it, and lays it down as a dense
:class:`Trace` whose heading follows the path. A waypoint where the route turns by more than
:data:`MAX_TURN` is refused: rounding it would cut the route far short of the waypoint (a
U-turn would reverse onto itself); a U-turn is drawn as two or more turns. World frame, metres
and radians.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from lidar_env.core.errors import ConfigError
from lidar_env.routes.trace_geometry import WAYPOINT_SPACING, Trace
from lidar_env.routes.traces import TraceFitError, free_margin

#: [m] radius of the arc that rounds each corner at body scale 1 (the paper's car; the scripted
#: driver follows it down to 0.67 m).
CORNER_RADIUS = 1.0
#: [rad] sharpest turn accepted at a waypoint: 150 degrees.
MAX_TURN = math.radians(150.0)
#: [m] largest waypoint coordinate accepted (a route beyond it lies in no map).
MAX_COORDINATE = 1e6
#: [m] points closer than this to the previous waypoint are dropped as repeats.
REPEAT_TOLERANCE = 1e-6


def check_waypoints(value: Any) -> NDArray[np.float64]:
    """``value`` as ``(N >= 2, 2)`` finite waypoints [m], repeats dropped."""
    try:
        points = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise ConfigError(f"trace: expected (N, 2) waypoints [m], got {value!r}") from error
    if points.ndim != 2 or points.shape[1] != 2:
        raise ConfigError(f"trace: expected (N, 2) waypoints [m], got shape {points.shape}")
    if len(points) < 2:
        raise ConfigError(f"trace: expected at least 2 distinct waypoints, got {len(points)}")
    usable = np.all(np.isfinite(points) & (np.abs(points) <= MAX_COORDINATE), axis=1)
    if not np.all(usable):
        bad = int(np.argmin(usable))
        raise ConfigError(f"trace: waypoint {bad} is {points[bad].tolist()}: expected finite "
                          f"coordinates [m] within +-{MAX_COORDINATE:g}")
    keep = np.concatenate([[True], np.hypot(*np.diff(points, axis=0).T) > REPEAT_TOLERANCE])
    points = points[keep]
    if len(points) < 2:
        raise ConfigError(f"trace: expected at least 2 distinct waypoints, got {len(points)}")
    return points


def _blocked(world: Any, a: NDArray, b: NDArray, clearance: float) -> tuple[float, NDArray] | None:
    """The least free margin [m] along segment ``a``-``b`` and where, if below ``clearance``."""
    n = max(2, int(math.ceil(np.hypot(*(b - a)) / (0.5 * WAYPOINT_SPACING))) + 1)
    samples = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
    margin = free_margin(world, samples)
    worst = int(np.argmin(margin))
    return (float(margin[worst]), samples[worst]) if margin[worst] < clearance else None


def check_clearance(world: Any, points: NDArray[np.float64], clearance: float,
                    what: str = "segment") -> None:
    """A :class:`TraceFitError` naming the first of the polyline's segments that passes closer
    than ``clearance`` [m] to an obstacle or the edge of ``world``."""
    for k in range(len(points) - 1):
        hit = _blocked(world, points[k], points[k + 1], clearance)
        if hit is not None:
            free, where = hit
            raise TraceFitError(
                f"trace: {what} {k} from ({points[k][0]:.2f}, {points[k][1]:.2f}) to "
                f"({points[k + 1][0]:.2f}, {points[k + 1][1]:.2f}) is blocked in world "
                f"{getattr(world, 'name', '?')!r}: at ({where[0]:.2f}, {where[1]:.2f}) it is "
                f"{free:.2f} m clear, expected >= {clearance:.2f} m (car half-diagonal + margin)")


def check_turns(points: NDArray[np.float64]) -> None:
    """A ``ConfigError`` naming the first waypoint where the route turns by more than
    :data:`MAX_TURN`."""
    steps = np.diff(points, axis=0)
    headings = np.arctan2(steps[:, 1], steps[:, 0])
    turns = np.abs((np.diff(headings) + math.pi) % (2 * math.pi) - math.pi)
    sharp = np.flatnonzero(turns > MAX_TURN)
    if len(sharp):
        k = int(sharp[0]) + 1
        raise ConfigError(
            f"trace: the route turns by {math.degrees(turns[k - 1]):.1f} degrees at waypoint {k} "
            f"({points[k][0]:g}, {points[k][1]:g}): expected at most "
            f"{math.degrees(MAX_TURN):.0f} degrees (a sharper corner is cut far short of its "
            "waypoint, a U-turn reverses onto itself); make a U-turn of two or more turns by "
            "adding a waypoint beside it")


def rounded_path(points: NDArray[np.float64], radius: float = CORNER_RADIUS) -> NDArray[np.float64]:
    """The polyline with each corner replaced by a tangent circular arc, sampled at most
    :data:`WAYPOINT_SPACING` apart; the arc's radius shrinks so its tangent points stay within
    half of each adjacent leg."""
    out = [points[0]]
    for k in range(1, len(points) - 1):
        before, after = points[k] - points[k - 1], points[k + 1] - points[k]
        la, lb = np.hypot(*before), np.hypot(*after)
        u, v = before / la, after / lb
        turn = math.atan2(u[0] * v[1] - u[1] * v[0], float(u @ v))
        if abs(turn) < 1e-9:
            continue
        cut = min(radius * math.tan(abs(turn) / 2), 0.5 * la, 0.5 * lb)
        r = cut / math.tan(abs(turn) / 2)
        start = points[k] - cut * u
        centre = start + math.copysign(r, turn) * np.array([-u[1], u[0]])
        a0 = math.atan2(*(start - centre)[::-1])
        n = max(2, int(math.ceil(r * abs(turn) / WAYPOINT_SPACING)) + 1)
        angles = a0 + np.linspace(0.0, turn, n)
        out.extend(centre + r * np.column_stack([np.cos(angles), np.sin(angles)]))
    out.append(points[-1])
    return _densify(np.array(out))


def _densify(points: NDArray[np.float64]) -> NDArray[np.float64]:
    pieces = [points[:1]]
    for a, b in zip(points[:-1], points[1:], strict=True):
        n = max(1, int(math.ceil(np.hypot(*(b - a)) / WAYPOINT_SPACING)))
        pieces.append(a + np.linspace(0.0, 1.0, n + 1)[1:, None] * (b - a))
    dense = np.vstack(pieces)
    keep = np.concatenate([[True], np.hypot(*np.diff(dense, axis=0).T) > REPEAT_TOLERANCE])
    return dense[keep]


def waypoint_trace(value: Any, world: Any, clearance: float,
                   radius: float = CORNER_RADIUS) -> Trace:
    """A drivable :class:`Trace` through the user's waypoints ``value`` (N, 2) [m] in
    ``world``, corners rounded with ``radius`` [m], or a :class:`TraceFitError` naming the
    first blocked segment."""
    points = check_waypoints(value)
    check_turns(points)
    check_clearance(world, points, clearance)
    path = rounded_path(points, radius)
    check_clearance(world, path, clearance, what="rounded piece")
    steps = np.diff(path, axis=0)
    headings = np.unwrap(np.arctan2(steps[:, 1], steps[:, 0]))
    return Trace("waypoints", path, np.concatenate([headings, headings[-1:]]))


def user_trace(value: Any, world: Any, clearance: float,
               radius: float = CORNER_RADIUS) -> Trace:
    """``value`` (waypoints or a :class:`Trace`) as a checked trace in ``world``; waypoint
    corners are rounded with ``radius`` [m]."""
    if isinstance(value, Trace):
        check_clearance(world, value.waypoints, clearance, what="piece")
        return value
    return waypoint_trace(value, world, clearance, radius)
