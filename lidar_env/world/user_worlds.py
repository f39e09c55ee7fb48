"""Worlds the user brings: a :class:`World`, a grayscale matrix, an image or a ROS map.

:func:`resolve_world` turns the env's ``world`` argument into a built-in name or a
:class:`World`; :func:`user_scene` lays a trace seed into a user world from ``start`` or, when
none is given, from a deterministic collision-free start near the map's centre (the free
point of largest clearance, with the centre preferred among near-equals), heading along the
one of :data:`START_HEADINGS` where the fitted trace is longest. The start depends on the
world alone, so a scene can be cached per world object and the same seed gives the same
episode whatever came before. Positions in metres, world frame; headings in radians.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from lidar_env.core.errors import ConfigError
from lidar_env.routes.traces import TraceFitError, make_trace
from lidar_env.world.built_in import WORLD_NAMES, Scene, check_world_name
from lidar_env.world.world import World

#: [m] default trace length in a user world (shrunk by the fitting when it does not fit).
USER_TRACE_LENGTH = 20.0
#: [m] spacing of the candidate start points.
START_SPACING = 0.25
#: Most candidate start points tested (the spacing grows on large maps).
MAX_START_CANDIDATES = 40_000
#: [m of clearance per m from the centre] how much a start near the centre is preferred.
CENTRE_PREFERENCE = 0.05
#: [rad] headings tried, in this order, before a trace seed is declared not to fit.
START_HEADINGS: tuple[float, ...] = tuple(
    k * math.pi / 4 for k in (0, 4, 2, -2, 1, 3, -1, -3))


def resolve_world(value: Any, resolution: float) -> str | World:
    """A built-in world name (checked) or a :class:`World` from ``value``: a ``World``; a 2-D
    array (0 = free, > 0 = obstacle; ``resolution`` [m/px]); a path to an image; or a path to
    a ROS map_server YAML (``.yaml``/``.yml``)."""
    if isinstance(value, World):
        return value
    if isinstance(value, np.ndarray):
        return World.from_image(value, resolution)
    if isinstance(value, (str, os.PathLike)):
        path = Path(value)
        if path.suffix.lower() in (".yaml", ".yml"):
            return World.from_ros_map(path)
        if isinstance(value, os.PathLike) or path.suffix.lower() in (".png", ".pgm", ".bmp",
                                                                     ".jpg", ".jpeg", ".tif"):
            if not path.exists():
                raise ConfigError(f"world: no such image file {path}")
            return World.from_image(path, resolution)
        return check_world_name(value)
    raise ConfigError(f"world: expected one of {', '.join(WORLD_NAMES)}, a World, a 2-D array, "
                      f"an image path or a ROS map YAML path, got {type(value).__name__}")


def start_candidates(world: World, clearance: float) -> np.ndarray:
    """``(M, 2)`` free points [m] at least ``clearance`` from obstacles and the bounds, best
    first: largest clearance, minus :data:`CENTRE_PREFERENCE` per metre from the centre."""
    xmin, ymin, xmax, ymax = world.bounds
    spacing = max(START_SPACING, math.sqrt((xmax - xmin) * (ymax - ymin) / MAX_START_CANDIDATES))
    xs = np.arange(xmin + spacing / 2, xmax, spacing)
    ys = np.arange(ymin + spacing / 2, ymax, spacing)
    points = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    to_edge = np.minimum.reduce([points[:, 0] - xmin, xmax - points[:, 0],
                                 points[:, 1] - ymin, ymax - points[:, 1]])
    free = np.minimum(world.clearance(points), to_edge)
    keep = free >= clearance
    centre = np.array([(xmin + xmax) / 2, (ymin + ymax) / 2])
    score = free[keep] - CENTRE_PREFERENCE * np.linalg.norm(points[keep] - centre, axis=1)
    return points[keep][np.argsort(-score, kind="stable")]


def user_scene(
    world: World,
    trace: str,
    start: tuple[float, float, float] | None,
    clearance: float,
    scale: float = 1.0,
) -> Scene:
    """Trace seed ``trace`` fitted into ``world`` from ``start`` or a seeded free start; its
    length and bends are scaled by the car's body ``scale`` (``EnvConfig.body_scale``)."""
    length = USER_TRACE_LENGTH * scale
    if start is not None:
        return Scene(world, make_trace(trace, start, length, world, clearance, scale))
    candidates = start_candidates(world, clearance)
    if len(candidates) == 0:
        raise TraceFitError(f"world {world.name!r} has no point {clearance:.2f} m clear of "
                            "obstacles and bounds to start the car from: pass options['start']")
    x, y = candidates[0]
    fitted, last = [], None
    for heading in START_HEADINGS:
        try:
            fitted.append(make_trace(trace, (x, y, heading), length, world, clearance, scale))
        except TraceFitError as error:
            last = error
    if not fitted:
        assert last is not None
        raise last
    return Scene(world, max(fitted, key=lambda t: t.length))  # the first of the longest
