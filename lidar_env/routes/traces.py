"""Trace seeds (the paper's "strict, right-turn, zigzag" paths, plus two that revisit places,
for loop closure: the closed ``loop`` and ``out_and_back``) and the traces built from them.

A *seed* is a shape: a list of pieces of constant curvature, given a total length [m] and a
bend scale (how large its turns are). A :class:`Trace` is that shape laid down from a start pose
(x [m], y [m], heading [rad], world frame) and densely resampled. :func:`make_trace` fits it to
a world: it shrinks the trace (first its bends, then its length) until every waypoint keeps
``clearance`` metres from every obstacle, and says so readably when nothing fits.

The :class:`Trace` type itself and its projection live in :mod:`lidar_env.routes.trace_geometry`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lidar_env.core.errors import ConfigError, MapError
from lidar_env.routes.trace_geometry import Piece, Trace, integrate_pieces

#: Scales tried, in order, when a trace does not fit its world: bends shrink before the length.
LENGTH_SCALES: tuple[float, ...] = (1.0, 0.9, 0.8, 0.7, 0.6, 0.5, 0.4, 0.3, 0.2, 0.1)
BEND_SCALES: tuple[float, ...] = (1.0, 0.75, 0.5)

#: Shortest trace [m] :func:`make_trace` accepts before giving up.
MIN_TRACE_LENGTH = 2.0

class TraceFitError(MapError):
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
        raise ConfigError(f"unknown trace {name!r}: expected one of {', '.join(TRACE_NAMES)}")
    return name


def build_trace(
    seed: str, start_pose: ArrayLike, length: float, bend_scale: float = 1.0
) -> Trace:
    """Lay seed ``seed`` of ``length`` [m] down from ``start_pose``, without fitting."""
    spec = TRACE_SEEDS[check_trace_name(seed)]
    pose = np.asarray(start_pose, dtype=np.float64)
    if pose.shape != (3,) or not np.all(np.isfinite(pose)):
        raise ConfigError(f"start_pose: expected 3 finite numbers (x, y, heading), got {pose}")
    if not math.isfinite(length) or length <= 0:
        raise ConfigError(f"length: expected a positive trace length [m], got {length!r}")
    points, headings = integrate_pieces(pose, spec.pieces(length, bend_scale))
    return Trace(seed, points, headings, spec.closed)


def make_trace(
    seed: str,
    start_pose: ArrayLike,
    length: float,
    world: Any = None,
    clearance: float = 0.77,
    scale: float = 1.0,
) -> Trace:
    """Build seed ``seed`` from ``start_pose`` and fit it to ``world``.

    Args:
        seed: one of :data:`TRACE_NAMES`.
        start_pose: (x [m], y [m], heading [rad]) in the world frame.
        length: wanted arc length [m].
        world: anything with ``clearance(points (N, 2)) -> (N,)`` [m] and ``bounds``
            (xmin, ymin, xmax, ymax) [m]; ``None`` skips fitting.
        clearance: [m] free distance every waypoint must keep (car half-diagonal + margin).
        scale: [-] the car's body scale (``EnvConfig.body_scale``): the seed's bends and the
            shortest accepted length are scaled by it, so a small robot gets tighter turns.

    Returns the first trace, trying bend scales :data:`BEND_SCALES` within length scales
    :data:`LENGTH_SCALES`, whose waypoints all stay inside the bounds with ``clearance``.

    Raises:
        TraceFitError: when none does (the message names the tightest spot found).
    """
    if world is None:
        return build_trace(seed, start_pose, length)
    worst: tuple[float, NDArray[np.float64]] | None = None
    shortest = MIN_TRACE_LENGTH * scale
    for length_scale in LENGTH_SCALES:
        if length * length_scale < shortest:
            break
        for bend_scale in BEND_SCALES:
            trace = build_trace(seed, start_pose, length * length_scale, bend_scale * scale)
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
        f"{max(shortest, length * LENGTH_SCALES[-1]):.1f} m fits"
    )


def free_margin(world: Any, points: NDArray[np.float64]) -> NDArray[np.float64]:
    """[m] distance from each point to the nearest obstacle or edge of ``world.bounds``."""
    xmin, ymin, xmax, ymax = world.bounds
    to_edge = np.minimum.reduce(
        [points[:, 0] - xmin, xmax - points[:, 0], points[:, 1] - ymin, ymax - points[:, 1]]
    )
    return np.minimum(np.asarray(world.clearance(points), dtype=np.float64), to_edge)
