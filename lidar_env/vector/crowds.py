"""The moving obstacles of N envs, laid out for the compiled step of :mod:`lidar_env.vector.kernel`.

Env ``i``'s M movers are row ``i`` of ``(N, M, ...)`` arrays: the state
:func:`lidar_env.movers.kernels.advance_crowd` advances
(:attr:`lidar_env.movers.crowd.Crowd.arrays`), stepped inside the kernel with the single env's own
functions. A reset places env ``i``'s crowd with :meth:`lidar_env.movers.crowd.Crowd.spawn` (its
draws from the env's generator, in the single env's order) and copies the result into row ``i``.
Units: metres, seconds; world frame.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from lidar_env.config import EnvConfig
from lidar_env.movers.crowd import CAR_CIRCLES, WAYPOINT_TRIES, Crowd, car_circle_radius
from lidar_env.routes.trace_geometry import Trace
from lidar_env.world.world import World


class CrowdSlots:
    """The crowds of ``n`` envs of ``config`` (M = ``config.moving_obstacles``, 0 for none: then
    every array has no movers and the kernel skips the crowd) for a car of half sizes
    ``half_length`` and ``half_width`` [m]."""

    def __init__(self, n: int, config: EnvConfig, half_length: float, half_width: float) -> None:
        m = int(getattr(config, "moving_obstacles", 0))
        self.count = m
        self._crowd = (Crowd(m, config.mover_radius, config.mover_speed_range, config.mover_model)
                       if m else None)
        self._clearance = float(getattr(config, "mover_clearance", 0.0))
        self._car = (half_length, half_width)
        self.radius = float(getattr(config, "mover_radius", 0.0))
        yields = m > 0 and config.mover_model != "waypoints"
        self.positions = np.zeros((n, m, 2))  # [m]
        self._state_shape = (n, m, 5)
        self.velocities = np.zeros((n, m, 2))  # [m/s] held over the last step
        self.waypoints = np.zeros((n, m, 2))  # [m]
        self.speeds = np.zeros((n, m))  # [m/s]
        self.stuck = np.zeros((n, m), dtype=np.int64)
        self.needs = np.ones((n, m), dtype=np.bool_)
        self.bounds = np.zeros((n, 4))  # [m] each env's world bounds
        self.max_speed = np.zeros(n)  # [m/s] each crowd's fastest (0 without movers)
        #: radius [m], the car's circles' radius [m] (yielding movers see them; 0 otherwise)
        self.params = np.array([self.radius, car_circle_radius(half_length, half_width)
                                if yields else 0.0])
        self._work = (np.zeros((m, 3)), np.zeros((CAR_CIRCLES if yields else 0, 5)),
                      np.zeros(m * WAYPOINT_TRIES * 2))

    def spawn(self, i: int, world: World, trace: Trace, rng: np.random.Generator) -> None:
        """Env ``i``'s crowd placed anew for an episode on ``trace`` in ``world`` (what the
        single env's reset does after choosing its scene; nothing without movers)."""
        crowd = self._crowd
        if crowd is None:
            return
        crowd.spawn(world, trace.waypoints, (*trace.start_pose, *self._car), self._clearance,
                    rng)
        rows = (self.positions, self.velocities, self.waypoints, self.speeds, self.stuck,
                self.needs, self.bounds)
        for row, value in zip(rows, crowd.arrays, strict=True):
            row[i] = value
        self.max_speed[i] = crowd.max_speed

    @property
    def kernel(self) -> tuple:
        """``(positions, velocities, waypoints, speeds, stuck, needs, bounds, params, work)``
        as :func:`lidar_env.vector.kernel.step_envs` takes them; ``work`` is the scratch
        ``(circles (M, 3), car circles (CAR_CIRCLES or 0, 5), waypoint draws (M x
        WAYPOINT_TRIES x 2,))``."""
        return (self.positions, self.velocities, self.waypoints, self.speeds, self.stuck,
                self.needs, self.bounds, self.params, self._work)

    def state(self, mask: NDArray[np.bool_] | None) -> NDArray[np.float64]:
        """``(N, M, 5)`` x, y [m], vx, vy [m/s], radius [m] of every env's movers (the single
        env's ``info["moving_obstacles"]``), zeros for the envs outside ``mask``."""
        out = np.empty(self._state_shape)
        if not self.count:
            return out
        out[:, :, :2] = self.positions
        out[:, :, 2:4] = self.velocities
        out[:, :, 4] = self.radius
        if mask is not None:
            out[~mask] = 0.0
        return out

    def nbytes(self) -> int:
        """Bytes of the per-env crowd arrays."""
        arrays: list[Any] = [self.positions, self.velocities, self.waypoints, self.speeds,
                             self.stuck, self.needs, self.bounds, self.max_speed]
        return sum(a.nbytes for a in arrays)
