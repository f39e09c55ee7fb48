"""What ``DualLidar-v0`` shows of its state besides observations: the pymunk ``Space`` and the
rendered frames (a mixin of :class:`lidar_env.env.DualLidarEnv`, kept apart so the env module
holds only the episode logic).

Poses are ``(x [m], y [m], heading [rad])`` in the world frame. pygame is imported only when a
``human`` window is first shown (:mod:`lidar_env.rendering.renderer`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import ArrayLike, NDArray

from lidar_env.core.errors import ArgumentTypeError, ConfigError, ResetNeededError

#: ``collision_type`` of the movers' pymunk shapes.
MOVER_COLLISION_TYPE: int = 3


class EnvViews:
    """The pymunk space, pickling without it, and rendering, for :class:`DualLidarEnv`."""

    # set by DualLidarEnv
    world: Any
    car: Any
    crowd: Any
    trace: Any
    config: Any
    lidar: Any
    render_mode: str | None
    metadata: dict[str, Any]
    _space: Any
    _space_world: Any
    _space_movers: list
    _renderer: Any
    _trajectories: dict[str, NDArray[np.float64]]
    _render_map: Any
    _last_scans: Any
    _sensor_poses: NDArray[np.float64]
    _world_aligned: bool
    _world_arg: Any
    _world_source: Any

    @property
    def space(self) -> Any:
        """The pymunk ``Space``: the world's static obstacles, the car's kinematic box and, with
        ``moving_obstacles``, one kinematic circle per mover.

        Built on first access for each world; the car's and movers' bodies are moved to their
        current poses on every access (the simulation itself does not need pymunk; see
        :mod:`lidar_env.vehicle.car` and :mod:`lidar_env.movers.crowd`).
        """
        if self.world is None or self.car is None:
            raise ResetNeededError("call reset() before reading space")
        if self._space is None or self._space_world is not self.world:
            self._space = self.world.build_space()
            self._space_world = self.world
            self._space_movers = []
            self.car.add_to_space(self._space)
        self.car.sync_body()
        self._sync_movers()
        return self._space

    def _sync_movers(self) -> None:
        """One kinematic pymunk circle per mover, at its current position and velocity."""
        import pymunk

        count = 0 if self.crowd is None else self.crowd.count
        while len(self._space_movers) < count:
            body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
            shape = pymunk.Circle(body, self.crowd.radius)
            shape.collision_type = MOVER_COLLISION_TYPE
            self._space.add(body, shape)
            self._space_movers.append(body)
        for i, body in enumerate(self._space_movers[:count]):
            body.position = (float(self.crowd.positions[i, 0]), float(self.crowd.positions[i, 1]))
            body.velocity = (float(self.crowd.velocities[i, 0]),
                             float(self.crowd.velocities[i, 1]))
            self._space.reindex_shapes_for_body(body)

    def __getstate__(self) -> dict[str, Any]:
        # the pymunk space and the pygame window are rebuilt on demand after unpickling
        state = self.__dict__.copy()
        state["_space"] = None
        state["_space_world"] = None
        state["_space_movers"] = []
        state["_renderer"] = None
        return state

    # ------------------------------------------------------------------ rendering
    def set_render_trajectories(self, trajectories: Mapping[str, ArrayLike]) -> None:
        """Trajectories to draw, ``{name: (N, 2) or (N, 3) world-frame poses [m]}``.

        Cleared at every reset.
        """
        checked = {}
        for name, poses in trajectories.items():
            array = np.asarray(poses, dtype=np.float64)
            if array.ndim != 2 or array.shape[1] not in (2, 3):
                raise ConfigError(
                    f"trajectory {name!r}: expected shape (N, 2) or (N, 3), got {array.shape}"
                )
            checked[str(name)] = array[:, :2].copy()
        self._trajectories = checked

    def set_render_map(self, grid: Any) -> None:
        """An occupancy map to draw under the trajectories, or ``None`` for none: anything with
        ``bounds``, ``resolution`` and ``probabilities()``
        (:class:`lidar_env.rendering.renderer.OccupancyMap`, e.g. an
        ``estimators.mapping.occupancy.OccupancyGrid``; the env imports no estimator).
        The env builds no map itself: a user (or the scoring wrapper) builds one from the scans
        at its estimated poses. The grid is kept by reference, so cells integrated into it
        later show in the next frame. Cleared at every reset.
        """
        from lidar_env.rendering.renderer import OccupancyMap

        if grid is not None and not isinstance(grid, OccupancyMap):
            raise ArgumentTypeError(
                "render map: expected an estimators.mapping.occupancy.OccupancyGrid or "
                f"None, got {type(grid).__name__}")
        self._render_map = grid

    def render(self) -> NDArray[np.uint8] | None:
        if self.render_mode is None:
            gym.logger.warn(
                "render() called without a render_mode; pass render_mode='rgb_array' or 'human' "
                "to gym.make"
            )
            return None
        if self.car is None or self._last_scans is None:
            raise ResetNeededError("call reset() before render()")
        from lidar_env.rendering.renderer import Renderer, show_in_window

        if self._renderer is None or self._renderer.world is not self.world:
            from lidar_env.rendering.overlays import UnknownCells

            window = self._renderer.window if self._renderer is not None else None
            source = getattr(self, "_world_source", None)
            unknown = UnknownCells.of(source) if self.world is self._world_arg else None
            self._renderer = Renderer(self.world, self.config.render_size, unknown,
                                      f"DualLidar-v0: {self.world.name}")
            self._renderer.window = window
        frame = self._renderer.draw(
            car_pose=self.car.pose,
            car_size=(self.config.car_length, self.config.car_width),
            sensor_poses=self._sensor_poses,
            scans=self._last_scans,
            beam_angles=list(self.lidar.beam_angles),
            max_range=[lidar.max_range for lidar in self.config.lidars],
            world_aligned=self._world_aligned,
            trace=self.trace.waypoints if self.trace is not None else None,
            trajectories=self._trajectories,
            occupancy=self._render_map,
            movers=None if self.crowd is None else self.crowd.state,
        )
        if self.render_mode == "rgb_array":
            return frame
        show_in_window(self._renderer, frame, self.metadata["render_fps"])
        return None

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
