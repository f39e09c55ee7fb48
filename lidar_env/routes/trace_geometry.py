"""The geometry of one trace: pieces of constant curvature laid down into dense waypoints, the
:class:`Trace` type, and the compiled projection of a point onto it.

All positions are metres and headings radians in the world frame; arc positions are metres of
arc length from the trace's start. Which shapes exist, and fitting them to a world, live in
:mod:`lidar_env.routes.traces`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from lidar_env.core.errors import MapError

#: (arc length [m], curvature [1/m], positive = turning left / CCW) of one piece of a seed.
Piece = tuple[float, float]

#: Waypoint spacing [m]: 5 cm is well under the car's size, so checking clearance at the
#: waypoints checks the whole path.
WAYPOINT_SPACING = 0.05

#: [m] how far a closed trace's last waypoint may lie from its first: far above the rounding
#: error of laying arcs down in closed form (~1e-13 m), far below the waypoint spacing.
CLOSURE_TOLERANCE = 1e-6


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
            raise MapError(f"waypoints: expected shape (M >= 2, 2), got {waypoints.shape}")
        self.seed = seed
        self.waypoints = waypoints
        self.headings = np.asarray(headings, dtype=np.float64)
        steps = np.hypot(*np.diff(waypoints, axis=0).T)
        self.arc = np.concatenate([[0.0], np.cumsum(steps)])
        self.closed = closed
        gap = float(np.hypot(*(waypoints[-1] - waypoints[0])))
        if closed and gap > CLOSURE_TOLERANCE:
            raise MapError(
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

    def points_at(self, arc_positions: ArrayLike) -> NDArray[np.float64]:
        """``(n, 2)`` [m]: :meth:`point_at` of each of ``arc_positions`` (n,) [m], the same
        numbers in one pass (point_at keeps its scalar form: 5 us a call against 9 through
        this)."""
        arcs = np.asarray(arc_positions, dtype=np.float64).reshape(-1)
        s = arcs % self.length if self.closed else np.minimum(np.maximum(arcs, 0.0), self.length)
        return np.column_stack([np.interp(s, self.arc, self.waypoints[:, 0]),
                                np.interp(s, self.arc, self.waypoints[:, 1])])

    def lookahead(
        self, point: ArrayLike, distance: float, near: float | None = None
    ) -> NDArray[np.float64]:
        """The trace point ``distance`` [m] of arc ahead of ``point``'s projection."""
        return self.point_at(self.project(point, near).arc_position + distance)

