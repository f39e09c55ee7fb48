"""The car: a box-shaped body with unicycle kinematics and exact collision checks.

Motion is integrated exactly: under a constant linear speed ``v`` [m/s] and yaw rate ``w``
[rad/s] the car runs along a circular arc (a straight line when ``w = 0``), so no integration
error accumulates however long the episode. The control step is split into ``substeps`` poses
along that arc (more when the move is long: no corner of the box moves more than a quarter of
its width between two checks, so it cannot jump over a wall), and at each one the car's box
is tested against every obstacle (circles and line segments) by a compiled kernel; the first
touching substep ends the motion with the car left at the last free substep. Moving obstacles
(circles, :mod:`lidar_env.movers.crowd`) move during the substeps too:
:func:`drive_arc_among_movers` tests the box at each substep against each mover where its straight,
constant-velocity move of the control step has taken it by then, and adds substeps for fast movers.
Measured against stepping a pymunk body through the same substeps plus a shape query, this is exact
and about 5x cheaper per control step (see ``benchmarks/bench_env.py``); pymunk's own shape query
stays the test oracle for the kernel.

The car's pymunk body (kinematic, one box shape) lives in the world's space so pymunk users
see the car; :meth:`Car.sync_body` moves it to the current pose on demand.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import pymunk
from numpy.typing import ArrayLike

from lidar_env.core.errors import ConfigError

#: ``collision_type`` of the car's pymunk shape.
CAR_COLLISION_TYPE: int = 2

#: [-] no point of the car's box moves more than this fraction of its smaller side between two
#: collision checks, so it cannot jump over a (zero-thickness) wall: a box can only clear a
#: wall by moving at least its width past it.
MAX_STEP_FRACTION: float = 0.25

#: [-] most collision checks one control step may need; a motion that needs more (a speed or a
#: control step far beyond what a car does) is rejected rather than simulated for minutes.
MAX_SUBSTEPS: int = 100_000


@numba.njit(cache=True)
def box_touches_obstacles(
    x: float,
    y: float,
    heading: float,
    half_length: float,
    half_width: float,
    circles: np.ndarray,
    segments: np.ndarray,
) -> bool:
    """True when the box centred at (x, y) [m], rotated by ``heading`` [rad], touches an obstacle.

    ``circles`` (N, 3) rows cx, cy, r; ``segments`` (M, 4) rows x1, y1, x2, y2 (zero thickness).
    Touching (distance 0) counts as a collision.
    """
    return turned_box_touches_obstacles(x, y, math.cos(heading), math.sin(heading), half_length,
                                        half_width, circles, segments)


@numba.njit(cache=True)
def turned_box_touches_obstacles(
    x: float,
    y: float,
    c: float,
    s: float,
    half_length: float,
    half_width: float,
    circles: np.ndarray,
    segments: np.ndarray,
) -> bool:
    """:func:`box_touches_obstacles` for a heading given by its cosine ``c`` and sine ``s``
    (the substeps of :func:`drive_arc` have them from :func:`arc_pose`)."""
    for i in range(circles.shape[0]):
        dx, dy = circles[i, 0] - x, circles[i, 1] - y
        # the circle centre in the car frame, then its distance to the box
        lx, ly = c * dx + s * dy, -s * dx + c * dy
        ex = max(abs(lx) - half_length, 0.0)
        ey = max(abs(ly) - half_width, 0.0)
        if ex * ex + ey * ey <= circles[i, 2] * circles[i, 2]:
            return True
    for i in range(segments.shape[0]):
        ax, ay = segments[i, 0] - x, segments[i, 1] - y
        bx, by = segments[i, 2] - x, segments[i, 3] - y
        p0x, p0y = c * ax + s * ay, -s * ax + c * ay
        p1x, p1y = c * bx + s * by, -s * bx + c * by
        # Liang-Barsky: clip the segment to the box; any part left means they touch
        t0, t1 = 0.0, 1.0
        dx, dy = p1x - p0x, p1y - p0y
        hit = True
        for p, q in (
            (-dx, p0x + half_length),
            (dx, half_length - p0x),
            (-dy, p0y + half_width),
            (dy, half_width - p0y),
        ):
            if p == 0.0:
                if q < 0.0:
                    hit = False
                    break
            else:
                r = q / p
                if p < 0.0:
                    t0 = max(t0, r)
                else:
                    t1 = min(t1, r)
                if t0 > t1:
                    hit = False
                    break
        if hit:
            return True
    return False


@numba.njit(cache=True)
def arc_pose(x0: float, y0: float, h0: float, cos0: float, sin0: float, speed: float,
             yaw_rate: float, t: float) -> tuple[float, float, float, float, float]:
    """The pose (x [m], y [m], unwrapped heading h [rad]) ``t`` [s] along the unicycle arc from
    ``(x0, y0, h0)`` at ``speed`` [m/s] and ``yaw_rate`` [rad/s] (a line below 1e-9 rad/s), then
    cos h and sin h; ``cos0``, ``sin0`` are cos h0 and sin h0 (a caller's substeps share them)."""
    h = h0 + yaw_rate * t
    c, s = math.cos(h), math.sin(h)
    if abs(yaw_rate) < 1e-9:
        return x0 + speed * t * cos0, y0 + speed * t * sin0, h, c, s
    radius = speed / yaw_rate
    return x0 + radius * (s - sin0), y0 - radius * (c - cos0), h, c, s


@numba.njit(cache=True)
def drive_arc(
    pose: np.ndarray,
    speed: float,
    yaw_rate: float,
    duration: float,
    substeps: int,
    half_length: float,
    half_width: float,
    circles: np.ndarray,
    segments: np.ndarray,
) -> bool:
    """Move ``pose`` (x [m], y [m], heading [rad], updated in place) along the unicycle arc.

    The arc of ``duration`` [s] is checked at ``substeps`` evenly spaced poses; at the first
    one that touches an obstacle the pose stays at the previous free one and True is returned.
    """
    x0, y0, h0 = pose[0], pose[1], pose[2]
    cos0, sin0 = math.cos(h0), math.sin(h0)
    free = 0  # the last free substep
    free_pose = (x0, y0, h0)
    for k in range(1, substeps + 1):
        t = duration * k / substeps
        x, y, h, c, s = arc_pose(x0, y0, h0, cos0, sin0, speed, yaw_rate, t)
        if turned_box_touches_obstacles(x, y, c, s, half_length, half_width, circles, segments):
            break
        free, free_pose = k, (x, y, h)
    return _moved_to(pose, free, free_pose, substeps)


@numba.njit(cache=True)
def drive_arc_among_movers(
    pose: np.ndarray,
    speed: float,
    yaw_rate: float,
    duration: float,
    substeps: int,
    half_length: float,
    half_width: float,
    circles: np.ndarray,
    segments: np.ndarray,
    movers: np.ndarray,
    mover_velocities: np.ndarray,
) -> bool:
    """:func:`drive_arc` among moving circles too: ``movers`` (M, 3) x, y, radius [m] at the
    start of the move, each going at ``mover_velocities`` (M, 2) [m/s] during it; at each
    substep the box is tested against the statics and the movers where they are then."""
    x0, y0, h0 = pose[0], pose[1], pose[2]
    cos0, sin0 = math.cos(h0), math.sin(h0)
    moved = movers.copy()
    no_segments = np.empty((0, 4))
    free = 0
    free_pose = (x0, y0, h0)
    for k in range(1, substeps + 1):
        t = duration * k / substeps
        x, y, h, c, s = arc_pose(x0, y0, h0, cos0, sin0, speed, yaw_rate, t)
        for i in range(movers.shape[0]):
            moved[i, 0] = movers[i, 0] + mover_velocities[i, 0] * t
            moved[i, 1] = movers[i, 1] + mover_velocities[i, 1] * t
        if (turned_box_touches_obstacles(x, y, c, s, half_length, half_width, circles, segments)
                or turned_box_touches_obstacles(x, y, c, s, half_length, half_width, moved,
                                                no_segments)):
            break
        free, free_pose = k, (x, y, h)
    return _moved_to(pose, free, free_pose, substeps)


@numba.njit(cache=True)
def _moved_to(pose: np.ndarray, free: int, free_pose: tuple[float, float, float],
              substeps: int) -> bool:
    """``pose`` set to the last free substep's ``free_pose`` (heading wrapped to [-pi, pi);
    left as it is when the first substep touched, ``free`` = 0); True (a hit) when a substep
    before the last touched. The drives wrap the heading once, not at every substep."""
    if free > 0:
        pose[0], pose[1] = free_pose[0], free_pose[1]
        pose[2] = (free_pose[2] + math.pi) % (2.0 * math.pi) - math.pi
    return free < substeps


@numba.njit(cache=True)
def mount_poses(pose: np.ndarray, mounts: np.ndarray, out: np.ndarray) -> None:
    """World poses of sensors ``mounts`` (K, 3, car frame) on a car at ``pose`` into ``out``."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    for k in range(mounts.shape[0]):
        out[k, 0] = pose[0] + c * mounts[k, 0] - s * mounts[k, 1]
        out[k, 1] = pose[1] + s * mounts[k, 0] + c * mounts[k, 1]
        out[k, 2] = (pose[2] + mounts[k, 2] + math.pi) % (2.0 * math.pi) - math.pi


class Car:
    """A ``length`` x ``width`` [m] box driven as a unicycle among ``circles`` and ``segments``.

    Args:
        length: [m] along the car's forward (x) axis.
        width: [m] along its left (y) axis.
        circles: ``(N, 3)`` obstacle circles cx, cy, r [m] (world frame).
        segments: ``(M, 4)`` obstacle segments x1, y1, x2, y2 [m] (world frame).
    """

    def __init__(
        self, length: float, width: float, circles: ArrayLike, segments: ArrayLike
    ) -> None:
        self.half_length = 0.5 * float(length)
        self.half_width = 0.5 * float(width)
        self.circles = np.ascontiguousarray(circles, dtype=np.float64).reshape(-1, 3)
        self.segments = np.ascontiguousarray(segments, dtype=np.float64).reshape(-1, 4)
        self.pose = np.zeros(3)
        self.body: pymunk.Body | None = None

    def collides_at(self, pose: ArrayLike) -> bool:
        """True when the car placed at ``pose`` (x, y, heading) touches an obstacle."""
        x, y, heading = (float(v) for v in np.asarray(pose, dtype=np.float64))
        return bool(
            box_touches_obstacles(
                x, y, heading, self.half_length, self.half_width, self.circles, self.segments
            )
        )

    def place(self, pose: ArrayLike) -> None:
        """Put the car at ``pose`` (x [m], y [m], heading [rad]) without a collision check."""
        self.pose[:] = np.asarray(pose, dtype=np.float64)

    def substeps_for(self, speed: float, yaw_rate: float, duration: float, substeps: int,
                     other_speed: float = 0.0) -> int:
        """Collision checks for a ``duration`` [s] move: at least ``substeps``, and enough that
        no corner of the box moves more than :data:`MAX_STEP_FRACTION` of its smaller side
        between two checks (translation ``|speed| dt`` plus rotation ``|yaw_rate| dt`` times
        the half diagonal, plus ``other_speed`` [m/s] x dt of the fastest mover, if any).

        Raises:
            ConfigError: ``speed``, ``yaw_rate`` or ``duration`` is not finite, ``duration`` is
                negative, or the move needs more than :data:`MAX_SUBSTEPS` checks.
        """
        for name, value in (("speed", speed), ("yaw_rate", yaw_rate), ("duration", duration)):
            if not math.isfinite(value):
                raise ConfigError(f"car {name}: expected a finite value, got {value!r}")
        if duration < 0.0:
            raise ConfigError(f"car duration: expected a value >= 0 [s], got {duration!r}")
        half_diagonal = math.hypot(self.half_length, self.half_width)
        corner_travel = (abs(speed) + abs(yaw_rate) * half_diagonal) * duration  # [m]
        if other_speed > 0.0:  # relative to the fastest mover
            corner_travel += other_speed * duration
        max_step = MAX_STEP_FRACTION * 2.0 * min(self.half_length, self.half_width)
        needed = math.ceil(corner_travel / max_step) if max_step > 0.0 else int(substeps)
        if needed > MAX_SUBSTEPS:
            raise ConfigError(
                f"car motion: speed {speed!r} m/s and yaw rate {yaw_rate!r} rad/s for "
                f"{duration!r} s move a corner {corner_travel:.3g} m, which needs {needed} "
                f"collision checks (at most {MAX_SUBSTEPS}); lower max_speed, max_yaw_rate or "
                "control_dt"
            )
        return max(int(substeps), needed, 1)

    def drive(
        self, speed: float, yaw_rate: float, duration: float, substeps: int,
        movers: np.ndarray | None = None, mover_velocities: np.ndarray | None = None,
        mover_speed: float | None = None,
    ) -> bool:
        """Drive ``duration`` [s] at ``speed`` [m/s] and ``yaw_rate`` [rad/s]; True on collision.

        ``substeps`` is the least number of collision checks; more are made when the move is
        long (see :meth:`substeps_for`), so the car never tunnels through a wall. ``movers``
        (M, 3: x, y, radius [m] at the start) moving at ``mover_velocities`` (M, 2) [m/s]
        during the move are checked at every substep where they are then
        (:func:`drive_arc_among_movers`); ``mover_speed`` [m/s] bounds their speeds (default:
        the fastest of ``mover_velocities``) and adds collision checks for fast movers.
        """
        if movers is not None and len(movers) > 0:
            velocities = np.ascontiguousarray(mover_velocities, dtype=np.float64).reshape(-1, 2)
            fastest = (float(np.sqrt(np.max(np.sum(velocities**2, axis=1))))
                       if mover_speed is None else float(mover_speed))
            checks = self.substeps_for(speed, yaw_rate, duration, substeps, fastest)
            return drive_arc_among_movers(
                self.pose, speed, yaw_rate, duration, checks, self.half_length,
                self.half_width, self.circles, self.segments,
                np.ascontiguousarray(movers, dtype=np.float64), velocities)
        checks = self.substeps_for(speed, yaw_rate, duration, substeps)
        return drive_arc(
            self.pose, speed, yaw_rate, duration, checks,
            self.half_length, self.half_width, self.circles, self.segments,
        )

    def __getstate__(self) -> dict:
        # the pymunk body belongs to a space that is rebuilt on demand, so it is not pickled
        return {**self.__dict__, "pose": self.pose.copy(), "body": None}

    def add_to_space(self, space: pymunk.Space) -> pymunk.Body:
        """Add the car as a kinematic box body to ``space`` (once); return the body."""
        body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        shape = pymunk.Poly.create_box(body, (2 * self.half_length, 2 * self.half_width))
        shape.collision_type = CAR_COLLISION_TYPE
        space.add(body, shape)
        self.body = body
        self.sync_body()
        return body

    def sync_body(self) -> None:
        """Move the pymunk body (if any) to the current pose and reindex its shape."""
        if self.body is None or self.body.space is None:
            return
        self.body.position = (float(self.pose[0]), float(self.pose[1]))
        self.body.angle = float(self.pose[2])
        self.body.space.reindex_shapes_for_body(self.body)
