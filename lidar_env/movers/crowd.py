"""Moving obstacles: a crowd of pedestrians (circles) walking between random free waypoints.

:class:`Crowd` holds the state of ``M`` movers as plain arrays and advances it with the compiled
kernels of :mod:`lidar_env.movers.kernels` (motion, the no-overlap guarantee, waypoints,
placement). Units: metres, seconds, radians; world frame.

Motion models (``config["mover_model"]``, :data:`MOVER_MODELS`). "waypoints":
each mover walks in a straight line at its own
speed (drawn uniformly from ``speed_range`` at spawn) to a waypoint it can see, a free point
:data:`WAYPOINT_REACH` away in a random direction; at the waypoint, or after being stuck for a
second, it draws the next one. On the way it turns away from walls and other movers it would
come near within the next second, and it never overlaps an obstacle or another mover (see
:mod:`lidar_env.movers.kernels`). Movers ignore the car: driving around them is the car's job,
and touching one ends the episode like a wall; a mover may walk into a standing car. "yielding":
the same walk, but the car's box where it stands (covered by :data:`CAR_CIRCLES` circles)
counts like a standing mover, as real pedestrians keep clear of a vehicle: the look-ahead keeps
0.3 m from it, and no step ever brings a mover closer to it than 2 cm (nor, nearer already, any
closer), so a standing car is never walked into. They do not read the driver's intent (the
car's motion is not extrapolated): a car that drives on into a crossing pedestrian still hits
it, so giving way stays the driver's job (movers that also dodged the car's commanded motion
would leave a driver that sees nothing to show). "yielding" is the default: a
pedestrian does not walk into a standing car, and a crowd that does scores a driver for
crashes it did not cause. "waypoints" stays as the harder
crowd (standing still is no escape from it).

Random numbers, all from the generator passed in, in a fixed order so that the same seed gives
the same crowd bit for bit: at :meth:`Crowd.spawn`, ``(SPAWN_TRIES * M, 2)`` uniforms for the
candidate positions, then ``M`` uniforms for the speeds; at each :meth:`Crowd.step`, if any
mover needs a waypoint, ``(n, WAYPOINT_TRIES, 2)`` uniforms for the ``n`` that do (the first
step draws for all). A crowd of ``M = 0`` is never built, so it draws nothing.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from lidar_env.core.errors import ConfigError
from lidar_env.movers.kernels import WAYPOINT_REACH, advance_crowd, place_movers
from lidar_env.world.world import World

#: Valid values of ``EnvConfig.mover_model``: how the pedestrians move (see above).
MOVER_MODELS: tuple[str, ...] = ("yielding", "waypoints")

__all__ = ["CAR_CIRCLES", "MOVER_MODELS", "SPAWN_TRIES", "WAYPOINT_REACH", "WAYPOINT_TRIES",
"Crowd",
           "car_circle_radius", "car_circles", "fill_car_circles"]

#: Circles along the car's axis that together cover its box (for "yielding" movers).
CAR_CIRCLES = 3

#: Candidate waypoints drawn per mover that needs one (the first free, visible one is taken).
WAYPOINT_TRIES = 16
#: Candidate spawn positions drawn per mover asked for.
SPAWN_TRIES = 200
#: Stands in for the waypoint draws of a step where no mover needs one.
_NO_DRAWS = np.empty((0, WAYPOINT_TRIES, 2))
#: The car as "waypoints" movers see it: not at all.
_NO_CAR = np.empty((0, 5))


def car_circles(
    pose: ArrayLike, half_length: float, half_width: float, speed: float = 0.0,
    yaw_rate: float = 0.0,
) -> NDArray[np.float64]:
    """``(CAR_CIRCLES, 5)`` circles x, y [m], vx, vy [m/s], radius [m] covering the car's box
    at ``pose`` (x, y, heading) [m, rad], each with the velocity of its centre when the car
    drives at ``speed`` [m/s] and ``yaw_rate`` [rad/s] (the env passes a standing car).

    The centres sit on the axis ``2 s`` apart with ``s = half_length / CAR_CIRCLES`` (the end
    ones ``s`` from the box's ends), so each covers a ``2 s`` slice of the box with radius
    ``hypot(s, half_width)`` (:func:`car_circle_radius`): the union holds the whole box.
    """
    x, y, heading = (float(v) for v in np.asarray(pose, dtype=np.float64)[:3])
    out = np.empty((CAR_CIRCLES, 5))
    fill_car_circles(x, y, heading, half_length, half_width,
                     car_circle_radius(half_length, half_width), speed, yaw_rate, out)
    return out


def car_circle_radius(half_length: float, half_width: float) -> float:
    """[m] radius of each of :func:`car_circles`' circles (Python's ``math.hypot``, which
    rounds differently from numba's: computed here, outside the kernels, for both envs)."""
    return math.hypot(half_length / CAR_CIRCLES, half_width)


@njit(cache=True, fastmath=False)
def fill_car_circles(x: float, y: float, heading: float, half_length: float, half_width: float,
                     radius: float, speed: float, yaw_rate: float,
                     out: NDArray[np.float64]) -> None:
    """:func:`car_circles` into ``out`` (CAR_CIRCLES, 5), compiled: the single env calls it
    through :func:`car_circles`, the batched env (:mod:`lidar_env.vector.kernel`) inside its
    step."""
    c, s = math.cos(heading), math.sin(heading)
    half_slice = half_length / CAR_CIRCLES
    for k in range(CAR_CIRCLES):
        offset = half_slice * (2 * k - (CAR_CIRCLES - 1))
        out[k, 0] = x + offset * c
        out[k, 1] = y + offset * s
        out[k, 2] = speed * c - yaw_rate * offset * s
        out[k, 3] = speed * s + yaw_rate * offset * c
        out[k, 4] = radius


class Crowd:
    """``count`` movers of ``radius`` [m] with speeds [m/s] drawn from ``speed_range``.

    Attributes (after :meth:`spawn`): ``positions`` (M, 2) [m], ``velocities`` (M, 2) [m/s]
    (held over the last step; zero at spawn), ``waypoints`` (M, 2) [m], ``speeds`` (M,) [m/s].
    """

    def __init__(self, count: int, radius: float, speed_range: tuple[float, float],
                 model: str = "yielding") -> None:
        if model not in MOVER_MODELS:
            raise ConfigError(f"mover_model: expected one of {', '.join(MOVER_MODELS)}, got "
                              f"{model!r}")
        self.model = model
        self.count = int(count)
        self.radius = float(radius)
        self.speed_range = (float(speed_range[0]), float(speed_range[1]))
        self.positions = np.zeros((self.count, 2))
        self.velocities = np.zeros((self.count, 2))
        self.waypoints = np.zeros((self.count, 2))
        self.speeds = np.zeros(self.count)
        self._stuck = np.zeros(self.count, dtype=np.int64)
        self._needs = np.ones(self.count, dtype=np.bool_)
        self._bounds = np.zeros(4)
        self._max_speed = 0.0

    def spawn(
        self, world: World, anchors: ArrayLike, car_box: ArrayLike, car_clearance: float,
        rng: np.random.Generator,
    ) -> None:
        """Place the crowd in ``world`` and draw the speeds (see the module docstring).

        Args:
            anchors: ``(K, 2)`` points [m] the car drives through (the trace): each mover can
                walk straight to the nearest of them, so it is in the car's part of the world.
            car_box: (x, y, heading, half length, half width) [m, rad] of the car.
            car_clearance: [m] least distance of a mover's surface from the car's box.

        Raises:
            ConfigError: fewer than ``count`` movers fit (the world is too crowded).
        """
        self._bounds = np.array(world.bounds, dtype=np.float64)
        xmin, ymin, xmax, ymax = self._bounds
        draws = rng.random((SPAWN_TRIES * self.count, 2))
        candidates = np.column_stack([xmin + (xmax - xmin) * draws[:, 0],
                                      ymin + (ymax - ymin) * draws[:, 1]])
        car = np.array([*np.asarray(car_box, dtype=np.float64), float(car_clearance)])
        placed = place_movers(candidates, self.positions, self.radius, car,
                              np.ascontiguousarray(anchors, dtype=np.float64), self._bounds,
                              world.circles, world.segments, world.grid)
        if placed < self.count:
            raise ConfigError(
                f"moving_obstacles: placed {placed} of {self.count} movers of mover_radius "
                f"{self.radius:g} m in world {world.name!r} ({len(candidates)} random tries, "
                f"keeping {car_clearance:g} m from the car): the world is too crowded; expected "
                "fewer moving_obstacles, a smaller mover_radius or a smaller mover_clearance")
        low, high = self.speed_range
        self.speeds = low + (high - low) * rng.random(self.count)
        self._max_speed = float(self.speeds.max())
        self.velocities[:] = 0.0
        self.waypoints[:] = self.positions
        self._stuck[:] = 0
        self._needs[:] = True

    def step(self, world: World, dt: float, rng: np.random.Generator,
             car: NDArray[np.float64] | None = None) -> None:
        """Advance every mover by ``dt`` [s]: new waypoints where needed, then one move each.

        ``car``: the car's circles this step, a C-contiguous float64 ``(K, 5)`` array as
        :func:`car_circles` returns, which "yielding" movers avoid; "waypoints" movers ignore
        it, as they do when it is None.
        """
        waiting = int(np.count_nonzero(self._needs))
        draws = rng.random((waiting, WAYPOINT_TRIES, 2)) if waiting else _NO_DRAWS
        seen = _NO_CAR if car is None or self.model == "waypoints" else car
        advance_crowd(*self.arrays[:6], draws, self.radius, float(dt), self._bounds,
                      world.circles, world.segments, world.grid, seen)

    @property
    def arrays(self) -> tuple[NDArray, ...]:
        """``(positions, velocities, waypoints, speeds, stuck, needs, bounds)``: the state
        :func:`~lidar_env.movers.kernels.advance_crowd` advances (the crowd's own arrays, not
        copies; ``stuck`` counts stuck steps, ``needs`` marks the movers that need a new
        waypoint, ``bounds`` (4,) is the world's xmin, ymin, xmax, ymax [m])."""
        return (self.positions, self.velocities, self.waypoints, self.speeds, self._stuck,
                self._needs, self._bounds)

    @property
    def circles(self) -> NDArray[np.float64]:
        """``(M, 3)`` current circles x, y, radius [m] (a new array)."""
        out = np.empty((self.count, 3))
        out[:, :2] = self.positions
        out[:, 2] = self.radius
        return out

    @property
    def state(self) -> NDArray[np.float64]:
        """``(M, 5)`` x, y [m], vx, vy [m/s] (over the last step), radius [m] (a new array)."""
        out = np.empty((self.count, 5))
        out[:, :2] = self.positions
        out[:, 2:4] = self.velocities
        out[:, 4] = self.radius
        return out

    @property
    def max_speed(self) -> float:
        """[m/s] the fastest mover's speed (0 before :meth:`spawn`)."""
        return self._max_speed


