"""Which scene an episode of ``DualLidar-v0`` starts in: reset options, start-pose checks and
the bounded cache of fitted scenes.

A scene is a world and a trace fitted to it (:class:`lidar_env.world.built_in.Scene`). Poses are
``(x [m], y [m], heading [rad])`` in the world frame; clearances and car sizes are metres.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from lidar_env.core.errors import ConfigError
from lidar_env.routes.trace_geometry import Trace
from lidar_env.routes.traces import check_trace_name
from lidar_env.routes.user_traces import CORNER_RADIUS, check_waypoints, user_trace
from lidar_env.vehicle.car import Car
from lidar_env.world.built_in import PAPER_TRACES, Scene, built_in_layout, make_scene
from lidar_env.world.user_worlds import resolve_world, user_scene
from lidar_env.world.world import World

#: Keys accepted in ``reset(options=...)``.
RESET_OPTIONS: tuple[str, ...] = ("world", "trace", "start")

#: Trace seed driven in a user world when none is given.
USER_WORLD_TRACE = "straight"

#: Fitted traces kept per env (built-in worlds only): every default start and a few custom ones.
MAX_CACHED_SCENES = 32


class StartPoseError(ConfigError):
    """The requested start pose (a reset option) lies outside the map or puts the car inside or
    onto an obstacle."""


def check_reset_options(options: Mapping[str, Any] | None) -> dict[str, Any]:
    """``options`` as a new dict, or a ``ValueError`` naming keys not in :data:`RESET_OPTIONS`."""
    options = dict(options or {})
    unknown = sorted(set(options) - set(RESET_OPTIONS))
    if unknown:
        raise ConfigError(
            f"unknown reset option(s) {', '.join(map(repr, unknown))}: expected some of "
            f"{', '.join(RESET_OPTIONS)}"
        )
    return options


def check_start_pose(
    start: Any, world_name: str, car_length: float, car_width: float
) -> tuple[float, float, float]:
    """``start`` as a pose, checked to lie inside built-in world ``world_name`` with the car's
    box (``car_length`` x ``car_width`` [m]) clear of its obstacles (a ``random`` world is
    drawn around its trace, so any start is accepted there); see :func:`check_user_start`."""
    if world_name == "random":
        return _as_pose(start)
    world = built_in_layout(world_name).world
    return check_user_start(start, world, car_length, car_width, world_name)


def _as_pose(start: Any) -> tuple[float, float, float]:
    expected = "options['start']: expected 3 finite numbers (x [m], y [m], heading [rad]), got"
    try:
        pose = np.asarray(start, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise ConfigError(f"{expected} {start!r}") from error
    if pose.shape != (3,) or not np.all(np.isfinite(pose)):
        raise ConfigError(f"{expected} {start!r}")
    return float(pose[0]), float(pose[1]), float(pose[2])


def check_user_start(
    start: Any, world: World, car_length: float, car_width: float, name: str | None = None
) -> tuple[float, float, float]:
    """``start`` as a pose inside ``world``'s bounds with the car's box (``car_length`` x
    ``car_width`` [m]) clear of its obstacles.

    Raises:
        ConfigError: ``start`` is not 3 finite numbers.
        StartPoseError: the pose is outside the map, or the car would touch or lie inside an
            obstacle.
    """
    x, y, heading = _as_pose(start)
    name = world.name if name is None else name
    xmin, ymin, xmax, ymax = world.bounds
    if not (xmin < x < xmax and ymin < y < ymax):
        raise StartPoseError(f"start pose ({x:g}, {y:g}, {heading:g}) is outside the map "
                             f"{name!r}: expected x in ({xmin:g}, {xmax:g}) and y in "
                             f"({ymin:g}, {ymax:g})")
    car = Car(car_length, car_width, world.circles, world.segments)
    if car.collides_at(np.array([x, y, heading])) or world.contains(np.array([[x, y]]))[0]:
        raise StartPoseError(f"start pose ({x:g}, {y:g}, {heading:g}) puts the {car_length} m x "
                             f"{car_width} m car into an obstacle of world {name!r}: expected a "
                             "pose where the car's box is clear")
    return x, y, heading


class SceneCache:
    """The world and fitted trace of each (world, trace, start) asked for.

    Built-in scenes are kept, so resetting into one again reuses its fitted trace (at most
    :data:`MAX_CACHED_SCENES`; the cache is emptied when full); random worlds are drawn anew
    from the generator every time and never kept.
    """

    def __init__(self) -> None:
        self._scenes: dict[tuple[Any, str, tuple[float, ...] | None], Scene] = {}

    def for_episode(
        self,
        options: Mapping[str, Any],
        world_arg: Any,
        trace_name: str | None,
        config: Any,
        rng: np.random.Generator,
    ) -> Scene:
        """The scene of one episode: ``options`` (checked) over the env's ``world_arg`` (a
        built-in name or a World) and ``trace_name``; ``config`` an ``EnvConfig``."""

        world = (resolve_world(options["world"], config.map_resolution) if "world" in options
                 else world_arg)
        trace_name = options.get("trace", trace_name)
        start = options.get("start")
        if trace_name is not None and not isinstance(trace_name, str):  # the user's route
            return self.get_route(world, trace_name, start, config)
        if not isinstance(world, str):  # a user world: no built-in starts
            trace_name = check_trace_name(USER_WORLD_TRACE if trace_name is None else trace_name)
            if start is not None:
                start = check_user_start(start, world, config.car_length, config.car_width)
            return self.get_user(world, trace_name, start, config.trace_clearance,
                                 config.body_scale)
        trace_name = check_trace_name(PAPER_TRACES[world] if trace_name is None else trace_name)
        if start is not None:
            start = check_start_pose(start, world, config.car_length, config.car_width)
        return self.get(world, trace_name, start, rng, config.trace_clearance)

    def get_route(self, world: Any, route: Any, start: Any, config: Any) -> Scene:
        """The scene of a user route (waypoints or a Trace) in ``world`` (a built-in name or
        a World), cached per world object and route."""
        if start is not None:
            raise ConfigError("options['start']: a waypoint route starts at its first "
                              "waypoint; expected no start with it")
        if isinstance(world, str):
            if world == "random":
                raise ConfigError("trace: a waypoint route needs a fixed world; 'random' is "
                                  "drawn around a trace seed")
            world = built_in_layout(world).world
        route_key = route if isinstance(route, Trace) else check_waypoints(route).tobytes()

        def fit() -> Scene:
            trace = user_trace(route, world, config.trace_clearance,
                               CORNER_RADIUS * config.body_scale)
            check_user_start(trace.start_pose, world, config.car_length, config.car_width)
            return Scene(world, trace)

        return self._cached((("route", id(world)), route_key, None), world, fit)

    def _cached(self, key: tuple, world: Any, fit: Callable[[], Scene]) -> Scene:
        """The scene under ``key``, fitted by ``fit()`` unless cached for this very ``world``
        object (an id can be reused by a new one)."""
        cached = self._scenes.get(key)
        if cached is None or cached.world is not world:
            if len(self._scenes) >= MAX_CACHED_SCENES:
                self._scenes.clear()
            self._scenes[key] = cached = fit()
        return cached

    def get_user(
        self,
        world: Any,
        trace_name: str,
        start: tuple[float, float, float] | None,
        clearance: float,
        scale: float = 1.0,
    ) -> Scene:
        """The scene of a user :class:`~lidar_env.world.world.World`, cached per world object;
        ``scale`` is the car's body scale."""
        return self._cached((("world", id(world)), trace_name, start), world,
                            lambda: user_scene(world, trace_name, start, clearance, scale))

    def get(
        self,
        world_name: str,
        trace_name: str,
        start: tuple[float, float, float] | None,
        rng: np.random.Generator,
        clearance: float,
    ) -> Scene:
        """The scene, fitting the trace with ``clearance`` [m]; ``rng`` draws random worlds."""
        if world_name == "random":
            return make_scene(world_name, trace_name, rng, clearance, start)
        key = (world_name, trace_name, start)
        if key not in self._scenes:
            if len(self._scenes) >= MAX_CACHED_SCENES:
                self._scenes.clear()
            self._scenes[key] = make_scene(world_name, trace_name, None, clearance, start)
        return self._scenes[key]
