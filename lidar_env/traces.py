"""Trace seeds (the paper's "strict, right-turn, zigzag" paths, plus two that revisit places,
for loop closure: the closed ``loop`` and ``out_and_back``) and the traces built from them.

A *seed* is a shape: a list of pieces of constant curvature, given a total length [m] and a
bend scale (how large its turns are). A :class:`Trace` is that shape laid down from a start pose
(x [m], y [m], heading [rad], world frame) and densely resampled. :func:`make_trace` fits it to
a world: it shrinks the trace (first its bends, then its length) until every waypoint keeps
``clearance`` metres from every obstacle, and says so readably when nothing fits.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NamedTuple

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

#: (arc length [m], curvature [1/m], positive = turning left / CCW) of one piece of a seed.
Piece = tuple[float, float]

#: Waypoint spacing [m]: 5 cm is well under the car's size, so checking clearance at the
#: waypoints checks the whole path.
WAYPOINT_SPACING = 0.05

#: Scales tried, in order, when a trace does not fit its world: bends shrink before the length.
LENGTH_SCALES: tuple[float, ...] = (1.0, 0.9, 0.8, 0.7, 0.6, 0.5, 0.4, 0.3, 0.2, 0.1)
BEND_SCALES: tuple[float, ...] = (1.0, 0.75, 0.5)

#: Shortest trace [m] :func:`make_trace` accepts before giving up.
MIN_TRACE_LENGTH = 2.0

#: [m] how far a closed trace's last waypoint may lie from its first: far above the rounding
#: error of laying arcs down in closed form (~1e-13 m), far below the waypoint spacing.
CLOSURE_TOLERANCE = 1e-6


class TraceFitError(ValueError):
    """No shrunken version of a trace keeps the required clearance in its world."""


def _straight(length: float, bend: float) -> list[Piece]:
    """The paper's "strict" seed: one straight line."""
    return [(length, 0.0)]


RIGHT_TURN_RADIUS = 2.5  # [m] at bend scale 1: gentle for a 0.8 m car, tight for a Lidar view


def _right_turn(length: float, bend: float) -> list[Piece]:
    """Straight, a 90 degree right (clockwise) arc, straight; the two straights are equal."""
    radius = RIGHT_TURN_RADIUS * bend
    arc = 0.5 * math.pi * radius
    straight = max(length - arc, 0.0) / 2.0
    return [(straight, 0.0), (min(arc, length), -1.0 / radius), (straight, 0.0)]


ZIGZAG_AMPLITUDE = 1.0  # [m] lateral swing at bend scale 1 (fits a 4 m wide corridor)
ZIGZAG_ANGLE = math.radians(40.0)  # [rad] leg direction off the main axis
ZIGZAG_RADIUS = 1.5  # [m] corner radius at bend scale 1
ZIGZAG_LEAD = 1.0  # [m] straight lead-in and lead-out


def _zigzag(length: float, bend: float) -> list[Piece]:
    """Lead-in, legs alternating +-40 degrees off the axis joined by round corners, lead-out.

    The first and last legs are half legs so the path ends on its start axis; the number of
    full legs is the largest that fits ``length`` and the lead-out takes the remainder.
    """
    radius = ZIGZAG_RADIUS * bend
    leg = 2.0 * ZIGZAG_AMPLITUDE * bend / math.sin(ZIGZAG_ANGLE)
    corner = 2.0 * ZIGZAG_ANGLE * radius  # arc length of a 2*angle corner
    half_turn = ZIGZAG_ANGLE * radius
    # the half turns shift the path sideways; shorter first/last half legs undo that shift
    half_leg = leg / 2 - radius * (1 - math.cos(ZIGZAG_ANGLE)) / math.sin(ZIGZAG_ANGLE)
    fixed = 2 * ZIGZAG_LEAD + 2 * half_turn + 2 * half_leg
    if length < fixed + corner + leg:
        return _straight(length, bend)
    n_full = int((length - fixed - corner) // (corner + leg))
    pieces: list[Piece] = [(ZIGZAG_LEAD, 0.0), (half_turn, 1.0 / radius), (half_leg, 0.0)]
    sign = -1.0
    for _ in range(n_full):
        pieces += [(corner, sign / radius), (leg, 0.0)]
        sign = -sign
    pieces += [(corner, sign / radius), (half_leg, 0.0), (half_turn, -sign / radius)]
    used = sum(p[0] for p in pieces)
    pieces.append((length - used, 0.0))
    return pieces


LOOP_CORNER_RADIUS = 2.5  # [m] at bend scale 1, as gentle as the right turn's
LOOP_ASPECT = 2.0  # [-] long straight side / short straight side of the loop


def _loop(length: float, bend: float) -> list[Piece]:
    """A closed counter-clockwise circuit: a rectangle with quarter-circle corners.

    It starts (and ends) in the middle of a long side, so the seam lies on a straight. Corners
    never take more than half the length (short loops get tighter corners, keeping straights).
    """
    radius = min(LOOP_CORNER_RADIUS * bend, length / (4.0 * math.pi))
    short = (length - 2.0 * math.pi * radius) / (2.0 * (1.0 + LOOP_ASPECT))
    long = LOOP_ASPECT * short
    corner = (0.5 * math.pi * radius, 1.0 / radius)
    return [(long / 2, 0.0), corner, (short, 0.0), corner, (long, 0.0), corner, (short, 0.0),
            corner, (long / 2, 0.0)]


OUT_AND_BACK_RADIUS = 2.0  # [m] radius of the turn-around's arcs at bend scale 1
OUT_AND_BACK_OFFSET = 2.0  # [m] return lane left of the outward one at bend scale 1: both lanes
#                            fit a 5 m corridor with 1.5 m to spare on either side


def _out_and_back(length: float, bend: float) -> list[Piece]:
    """Out along a straight, turn around, and back along a parallel lane to the left.

    The turn-around is a bulb of three arcs of one radius ``R``: right by ``a``, left by
    ``pi + 2 a``, right by ``a``; it shifts the path ``R (4 cos a - 2)`` to the left, which sets
    ``a`` for the wanted offset. A plain U-turn between lanes 2 m apart would need a 1 m radius,
    near the car's tightest turn at cruise speed; the bulb keeps the gentle radius of the other
    seeds. The trace ends beside its start, facing back. The turn-around shrinks (radius and
    offset together) so that it takes at most half the length.
    """
    angle = math.acos((OUT_AND_BACK_OFFSET / OUT_AND_BACK_RADIUS + 2.0) / 4.0)
    turn_at_scale_1 = OUT_AND_BACK_RADIUS * (math.pi + 4.0 * angle)
    radius = OUT_AND_BACK_RADIUS * min(bend, length / (2.0 * turn_at_scale_1))
    straight = (length - radius * (math.pi + 4.0 * angle)) / 2.0
    return [(straight, 0.0), (radius * angle, -1.0 / radius),
            (radius * (math.pi + 2.0 * angle), 1.0 / radius), (radius * angle, -1.0 / radius),
            (straight, 0.0)]


@dataclass(frozen=True)
class TraceSeed:
    """A named trace shape.

    Attributes:
        name: the seed's name.
        pieces: ``(length [m], bend scale) -> [(arc length [m], curvature [1/m]), ...]``.
        closed: the trace ends where it starts, with the same heading (a circuit).
    """

    name: str
    pieces: Callable[[float, float], list[Piece]]
    closed: bool = False


TRACE_SEEDS: dict[str, TraceSeed] = {
    seed.name: seed
    for seed in (
        TraceSeed("straight", _straight),
        TraceSeed("right_turn", _right_turn),
        TraceSeed("zigzag", _zigzag),
        TraceSeed("loop", _loop, closed=True),
        TraceSeed("out_and_back", _out_and_back),
    )
}
TRACE_NAMES: tuple[str, ...] = tuple(TRACE_SEEDS)


def check_trace_name(name: Any) -> str:
    """Return ``name`` if it is a trace seed, else raise a ``ValueError`` listing the seeds."""
    if not isinstance(name, str) or name not in TRACE_SEEDS:
        raise ValueError(f"unknown trace {name!r}: expected one of {', '.join(TRACE_NAMES)}")
    return name


def integrate_pieces(
    start_pose: ArrayLike, pieces: list[Piece], spacing: float = WAYPOINT_SPACING
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Lay ``pieces`` down from ``start_pose`` exactly (arcs in closed form).

    Returns ``(points (M, 2) [m], headings (M,) [rad])`` spaced at most ``spacing`` apart along
    the arc, first row = the start.
    """
    x, y, heading = (float(v) for v in np.asarray(start_pose, dtype=np.float64))
    points = [np.array([[x, y]])]
    headings = [np.array([heading])]
    for length, curvature in pieces:
        if length <= 0:
            continue
        s = np.linspace(0.0, length, max(1, math.ceil(length / spacing)) + 1)[1:]
        if abs(curvature) < 1e-12:
            px = x + s * math.cos(heading)
            py = y + s * math.sin(heading)
            ph = np.full_like(s, heading)
        else:
            ph = heading + curvature * s
            px = x + (np.sin(ph) - math.sin(heading)) / curvature
            py = y - (np.cos(ph) - math.cos(heading)) / curvature
        points.append(np.stack([px, py], axis=1))
        headings.append(ph)
        x, y, heading = float(px[-1]), float(py[-1]), float(ph[-1])
    return np.concatenate(points), np.concatenate(headings)


class TraceProjection(NamedTuple):
    """Where a point lies relative to a trace."""

    progress: float  # [-] arc_position / length: in [0, 1], except on a closed trace (see below)
    cross_track_error: float  # [m] signed distance to the trace, positive = left of it
    arc_position: float  # [m] arc length of the closest trace point from the start


@numba.njit(cache=True)
def _closest_on_segments(
    points: np.ndarray, arc: np.ndarray, px: float, py: float, lo: float, hi: float
) -> tuple[float, float, float]:
    """Closest point to (px, py) on the segments of ``points`` overlapping arc [lo, hi] [m].

    Returns (squared distance [m^2], arc position [m], side: > 0 left of the trace); the
    distance is ``inf`` when no segment overlaps.
    """
    last = points.shape[0] - 1
    first = max(np.searchsorted(arc, lo) - 1, 0)
    stop = min(np.searchsorted(arc, hi) + 1, last)
    best_d2, best_s, best_side = np.inf, 0.0, 0.0
    for i in range(first, stop):
        ax, ay = points[i, 0], points[i, 1]
        dx, dy = points[i + 1, 0] - ax, points[i + 1, 1] - ay
        seg2 = dx * dx + dy * dy
        u = 0.0
        if seg2 > 0.0:
            u = min(max(((px - ax) * dx + (py - ay) * dy) / seg2, 0.0), 1.0)
        ex, ey = px - (ax + u * dx), py - (ay + u * dy)
        d2 = ex * ex + ey * ey
        if d2 < best_d2:
            best_d2 = d2
            best_s = arc[i] + u * (arc[i + 1] - arc[i])
            best_side = dx * ey - dy * ex
    return best_d2, best_s, best_side


@numba.njit(cache=True)
def project_onto_polyline(
    points: np.ndarray,
    arc: np.ndarray,
    px: float,
    py: float,
    near: float,
    window: float,
    closed: bool = False,
) -> tuple[float, float]:
    """Closest point to (px, py) on the polyline ``points`` (M, 2) with arc lengths ``arc``.

    Only the polyline within ``window`` [m] of arc position ``near`` is searched
    (``window = inf`` searches all and returns an arc position in [0, arc[-1]]). On a
    ``closed`` polyline (last point = first) the window wraps across the seam and the arc
    position is unwrapped to the lap of ``near``: it keeps growing past ``arc[-1]`` through
    the seam and goes negative behind the start, so it counts distance driven around the loop.
    Returns (arc position [m], signed distance [m], positive = left).
    """
    length = arc[-1]
    if window == np.inf:
        best_d2, best_s, best_side = _closest_on_segments(points, arc, px, py, -np.inf, np.inf)
    elif not closed:
        best_d2, best_s, best_side = _closest_on_segments(
            points, arc, px, py, near - window, near + window
        )
    else:
        lap = math.floor(near / length) * length
        local = near - lap  # in [0, length)
        best_d2, best_s, best_side = np.inf, 0.0, 0.0
        for shift in (-length, 0.0, length):  # the window's part on the previous, same, next lap
            lo, hi = local - window - shift, local + window - shift
            if hi < 0.0 or lo > length:
                continue
            d2, s, side = _closest_on_segments(points, arc, px, py, lo, hi)
            s += shift + lap
            # a window over half a lap sees a point on two laps: keep the lap nearest ``near``
            if d2 < best_d2 or (d2 == best_d2 and abs(s - near) < abs(best_s - near)):
                best_d2, best_s, best_side = d2, s, side
    distance = math.sqrt(best_d2)
    return best_s, distance if best_side >= 0.0 else -distance


class Trace:
    """A trace laid down in the world: dense waypoints with arc length and heading.

    Attributes:
        seed: name of the seed it was built from.
        waypoints: ``(M, 2)`` [m] world-frame points, at most ``WAYPOINT_SPACING`` apart.
        headings: ``(M,)`` [rad] path direction at each waypoint, continuous (not wrapped: a
            counter-clockwise loop ends at its start heading + 2 pi).
        arc: ``(M,)`` [m] arc length from the start to each waypoint.
        closed: a circuit: its last waypoint is its first, and arc positions wrap around.
    """

    def __init__(
        self,
        seed: str,
        waypoints: NDArray[np.float64],
        headings: NDArray[np.float64],
        closed: bool = False,
    ) -> None:
        waypoints = np.ascontiguousarray(waypoints, dtype=np.float64)
        if waypoints.ndim != 2 or waypoints.shape[1] != 2 or len(waypoints) < 2:
            raise ValueError(f"waypoints: expected shape (M >= 2, 2), got {waypoints.shape}")
        self.seed = seed
        self.waypoints = waypoints
        self.headings = np.asarray(headings, dtype=np.float64)
        steps = np.hypot(*np.diff(waypoints, axis=0).T)
        self.arc = np.concatenate([[0.0], np.cumsum(steps)])
        self.closed = closed
        gap = float(np.hypot(*(waypoints[-1] - waypoints[0])))
        if closed and gap > CLOSURE_TOLERANCE:
            raise ValueError(
                f"closed trace {seed!r}: expected the last waypoint to meet the first (within "
                f"{CLOSURE_TOLERANCE:g} m), got a gap of {gap:.6g} m"
            )
        for array in (self.waypoints, self.headings, self.arc):
            array.flags.writeable = False

    def __repr__(self) -> str:
        x, y, h = self.start_pose
        return (
            f"Trace({self.seed!r}, start=({x:.2f}, {y:.2f}, {h:.2f}), length={self.length:.2f} m)"
        )

    @property
    def length(self) -> float:
        """[m] total arc length."""
        return float(self.arc[-1])

    @property
    def start_pose(self) -> NDArray[np.float64]:
        """(x [m], y [m], heading [rad]) of the first waypoint."""
        return np.array([*self.waypoints[0], self.headings[0]])

    @property
    def end_pose(self) -> NDArray[np.float64]:
        """(x [m], y [m], heading [rad]) of the last waypoint."""
        return np.array([*self.waypoints[-1], self.headings[-1]])

    def project(
        self, point: ArrayLike, near: float | None = None, window: float = 2.0
    ) -> TraceProjection:
        """Project ``point`` (x, y) [m] onto the trace.

        With ``near`` (an arc position [m], e.g. the previous projection), only the trace within
        ``window`` metres of it is searched: progress then cannot jump across to a neighbouring
        leg of a zigzag that passes close by. On a closed trace the search wraps across the
        seam and the arc position is the one nearest ``near`` on any lap: tracked step by step it
        counts the distance driven around the loop (past ``length`` after the seam, negative
        behind the start), and so does ``progress`` (1 = one lap). Without ``near`` the whole
        trace is searched and the arc position lies in [0, length].
        """
        x, y = (float(v) for v in np.asarray(point, dtype=np.float64)[:2])
        if near is None:
            near, window = 0.0, np.inf
        s, cte = project_onto_polyline(
            self.waypoints, self.arc, x, y, float(near), window, self.closed
        )
        return TraceProjection(s / self.length, cte, s)

    def point_at(self, arc_position: float) -> NDArray[np.float64]:
        """(x, y) [m] at ``arc_position`` [m] (clamped to the trace, or wrapped when closed)."""
        s = arc_position % self.length if self.closed else min(max(arc_position, 0.0), self.length)
        x = np.interp(s, self.arc, self.waypoints[:, 0])
        return np.array([x, np.interp(s, self.arc, self.waypoints[:, 1])])

    def lookahead(
        self, point: ArrayLike, distance: float, near: float | None = None
    ) -> NDArray[np.float64]:
        """The trace point ``distance`` [m] of arc ahead of ``point``'s projection."""
        return self.point_at(self.project(point, near).arc_position + distance)


def build_trace(
    seed: str, start_pose: ArrayLike, length: float, bend_scale: float = 1.0
) -> Trace:
    """Lay seed ``seed`` of ``length`` [m] down from ``start_pose``, without fitting."""
    spec = TRACE_SEEDS[check_trace_name(seed)]
    pose = np.asarray(start_pose, dtype=np.float64)
    if pose.shape != (3,) or not np.all(np.isfinite(pose)):
        raise ValueError(f"start_pose: expected 3 finite numbers (x, y, heading), got {pose}")
    if not math.isfinite(length) or length <= 0:
        raise ValueError(f"length: expected a positive trace length [m], got {length!r}")
    points, headings = integrate_pieces(pose, spec.pieces(length, bend_scale))
    return Trace(seed, points, headings, spec.closed)


def make_trace(
    seed: str,
    start_pose: ArrayLike,
    length: float,
    world: Any = None,
    clearance: float = 0.77,
) -> Trace:
    """Build seed ``seed`` from ``start_pose`` and fit it to ``world``.

    Args:
        seed: one of :data:`TRACE_NAMES`.
        start_pose: (x [m], y [m], heading [rad]) in the world frame.
        length: wanted arc length [m].
        world: anything with ``clearance(points (N, 2)) -> (N,)`` [m] and ``bounds``
            (xmin, ymin, xmax, ymax) [m]; ``None`` skips fitting.
        clearance: [m] free distance every waypoint must keep (car half-diagonal + margin).

    Returns the first trace, trying bend scales :data:`BEND_SCALES` within length scales
    :data:`LENGTH_SCALES`, whose waypoints all stay inside the bounds with ``clearance``.

    Raises:
        TraceFitError: when none does (the message names the tightest spot found).
    """
    if world is None:
        return build_trace(seed, start_pose, length)
    worst: tuple[float, NDArray[np.float64]] | None = None
    for length_scale in LENGTH_SCALES:
        if length * length_scale < MIN_TRACE_LENGTH:
            break
        for bend_scale in BEND_SCALES:
            trace = build_trace(seed, start_pose, length * length_scale, bend_scale)
            margin = free_margin(world, trace.waypoints) - clearance
            if np.all(margin >= 0):
                return trace
            i = int(np.argmin(margin))
            if worst is None:
                worst = (float(margin[i] + clearance), trace.waypoints[i])
    free, where = worst if worst is not None else (0.0, np.asarray(start_pose)[:2])
    x, y, heading = (float(v) for v in np.asarray(start_pose, dtype=np.float64))
    raise TraceFitError(
        f"trace {seed!r} from ({x:.3f}, {y:.3f}, {heading:.3f}) does not "
        f"fit in world {getattr(world, 'name', '?')!r}: expected every waypoint {clearance:.2f} m "
        f"clear of obstacles and bounds, but at full size the point ({where[0]:.2f}, "
        f"{where[1]:.2f}) is {free:.2f} m clear, and no shrunken version down to "
        f"{max(MIN_TRACE_LENGTH, length * LENGTH_SCALES[-1]):.1f} m fits"
    )


def free_margin(world: Any, points: NDArray[np.float64]) -> NDArray[np.float64]:
    """[m] distance from each point to the nearest obstacle or edge of ``world.bounds``."""
    xmin, ymin, xmax, ymax = world.bounds
    to_edge = np.minimum.reduce(
        [points[:, 0] - xmin, xmax - points[:, 0], points[:, 1] - ymin, ymax - points[:, 1]]
    )
    return np.minimum(np.asarray(world.clearance(points), dtype=np.float64), to_edge)
