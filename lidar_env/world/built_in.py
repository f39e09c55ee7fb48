"""Built-in worlds reproducing the paper's three surroundings (Fig. 7), and random worlds.

* ``open_cylinders`` (group 1, right-turn trace): an open area with many single cylinders,
  rich in features; no walls within the Lidar's reach of the trace.
* ``hallway`` (group 2, zigzag trace): a closed hallway, narrow (5 m) at its start and end
  and broad (14 m) in the middle, with plain walls: few features.
* ``closed_to_open`` (group 3, zigzag trace): a 5 m corridor that opens into a large hall with
  a few cylinders and boxes: medium features.
* ``random``: rooms, walls, boxes and cylinders drawn from the reset's random generator
  around a trace generated first, so the trace is always collision free.

``hallway`` and ``closed_to_open`` take a feature density [features per 10 m of wall] in their
name: ``"hallway?feature_density=4&feature_seed=1"`` adds door recesses, pillars, corners and
clutter along the walls, placed from the seed (:mod:`lidar_env.world.feature_worlds`); density 0
(the default) is the plain world, bit for bit.

Every built-in world has a default start pose and length for each trace seed, placed so the
full-size trace fits (tests check this; :func:`lidar_env.routes.traces.make_trace` would shrink it
otherwise). Coordinates are metres, world frame.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import cache
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lidar_env.core.errors import ArgumentTypeError, ConfigError
from lidar_env.routes.traces import TRACE_NAMES, Trace, build_trace, check_trace_name, make_trace
from lidar_env.world.feature_worlds import add_features, feature_world_name, parse_world_name
from lidar_env.world.polygons import segment_distances
from lidar_env.world.world import World

Pose = tuple[float, float, float]


@dataclass(frozen=True)
class WorldLayout:
    """A built-in world with the default start pose and length of each trace seed on it."""

    world: World
    starts: Mapping[str, Pose]  # (x [m], y [m], heading [rad]) per trace seed
    lengths: Mapping[str, float]  # [m] trace length per trace seed
    features: tuple[str, ...] = ()  # kinds of the wall features added (feature-density worlds)


@dataclass(frozen=True)
class Scene:
    """What an episode runs in: a world and the trace laid down in it."""

    world: World
    trace: Trace


class _PaperTraces(dict):
    """The paper trace per world name; a name with options (``"hallway?..."``) has its base's."""

    def __missing__(self, key: Any) -> str:
        if isinstance(key, str) and "?" in key:
            return self[key.partition("?")[0]]
        raise KeyError(key)


#: The trace seed the paper drives in each world (Fig. 7 groups 1-3).
PAPER_TRACES: dict[str, str] = _PaperTraces({
    "open_cylinders": "right_turn",
    "hallway": "zigzag",
    "closed_to_open": "zigzag",
    "random": "zigzag",
})
WORLD_NAMES: tuple[str, ...] = tuple(PAPER_TRACES)


def check_world_name(name: Any) -> str:
    """``name`` if it is a world name (a name with feature options in its canonical form,
    :func:`~lidar_env.world.feature_worlds.feature_world_name`), else a ``ValueError`` listing the
    names (a :class:`~lidar_env.core.errors.ConfigError` for bad options)."""
    if isinstance(name, str) and "?" in name:
        base, options = parse_world_name(name)
        return feature_world_name(base, options.density, options.seed)
    if not isinstance(name, str) or name not in WORLD_NAMES:
        raise ConfigError(f"unknown world {name!r}: expected one of {', '.join(WORLD_NAMES)}")
    return name


def _polyline(points: ArrayLike, closed: bool = False) -> NDArray[np.float64]:
    """``(k, 4)`` segments joining consecutive ``points`` (k, 2), closing the loop if asked."""
    p = np.asarray(points, dtype=np.float64)
    q = np.roll(p, -1, axis=0)
    segments = np.hstack([p, q])
    return segments if closed else segments[:-1]


def _box(cx: float, cy: float, half_x: float, half_y: float, angle: float = 0.0) -> NDArray:
    """``(4, 2)`` corners of a rectangle centred at (cx, cy) [m], rotated by ``angle`` [rad]."""
    corners = np.array([[-half_x, -half_y], [half_x, -half_y], [half_x, half_y], [-half_x, half_y]])
    c, s = math.cos(angle), math.sin(angle)
    return corners @ np.array([[c, s], [-s, c]]) + (cx, cy)


def _keep_clear(
    circles: NDArray[np.float64], paths: list[NDArray[np.float64]], clearance: float
) -> NDArray[np.float64]:
    """The circles whose surfaces stay ``clearance`` [m] away from every path point."""
    points = np.vstack(paths)
    gaps = np.hypot(points[:, None, 0] - circles[:, 0], points[:, None, 1] - circles[:, 1])
    return circles[np.min(gaps, axis=0) - circles[:, 2] >= clearance]


def _open_cylinders(clearance: float) -> WorldLayout:
    """40 m x 40 m of open ground with cylinders on a jittered 3.5 m lattice.

    The jitter and radii follow fixed trigonometric patterns (no random generator: the world
    is the same everywhere); cylinders within ``clearance`` of a default trace are left out.
    """
    # the loop and out_and_back mostly reuse the lanes the other traces clear (one cylinder more
    # each is removed): the loop runs between the zigzag's and the right turn's, out_and_back
    # goes out along the straight's
    starts = {"right_turn": (6.0, 30.0, 0.0), "straight": (4.0, 8.0, 0.0),
              "zigzag": (4.0, 20.0, 0.0), "loop": (18.0, 21.0, 0.0),
              "out_and_back": (12.0, 8.0, 0.0)}
    lengths = {"right_turn": 30.0, "straight": 32.0, "zigzag": 32.0, "loop": 40.0,
               "out_and_back": 40.0}
    i, j = np.meshgrid(np.arange(12), np.arange(12), indexing="ij")
    i, j = i.ravel().astype(float), j.ravel().astype(float)
    x = 1.5 + 3.5 * i + 0.9 * np.sin(1.7 * i + 2.3 * j)
    y = 1.5 + 3.5 * j + 0.9 * np.cos(2.9 * i - 1.1 * j)
    radius = 0.2 + 0.25 * (1.0 + np.sin(0.7 * i * j + i)) / 2.0
    circles = np.stack([x, y, radius], axis=1)
    paths = [build_trace(s, starts[s], lengths[s]).waypoints for s in TRACE_NAMES]
    world = World(
        circles=_keep_clear(circles, paths, clearance + 0.2), name="open_cylinders",
        bounds=(0.0, 0.0, 40.0, 40.0),
    )
    return WorldLayout(world, starts, lengths)


_HALLWAY_UPPER = [(0, 2.5), (8, 2.5), (11, 7), (29, 7), (32, 2.5), (40, 2.5)]
#: [m] the hallway's closed wall outline.
HALLWAY_OUTLINE = np.array(_HALLWAY_UPPER + [(x, -y) for x, y in reversed(_HALLWAY_UPPER)],
                           dtype=float)
#: [m] the closed-to-open world's wall outline: the corridor and the hall.
CLOSED_TO_OPEN_OUTLINE = np.array(
    [(0, -2.5), (0, 2.5), (14, 2.5), (14, 15), (40, 15), (40, -15), (14, -15), (14, -2.5)],
    dtype=float,
)


def _hallway(clearance: float) -> WorldLayout:
    """A closed 40 m hallway: 5 m wide for its first and last 8 m, 14 m wide in the middle."""
    world = World(segments=_polyline(HALLWAY_OUTLINE, closed=True), name="hallway",
                  bounds=(-1.0, -8.0, 41.0, 8.0))
    # the loop circles the broad middle; out_and_back goes out through the narrow start, turns
    # around in the broad part and comes back through the narrow part 2 m to the left
    starts = {"zigzag": (1.5, 0.0, 0.0), "straight": (1.5, 0.0, 0.0),
              "right_turn": (12.0, 4.0, 0.0), "loop": (20.0, -4.5, 0.0),
              "out_and_back": (1.5, -1.0, 0.0)}
    lengths = {"zigzag": 40.0, "straight": 37.0, "right_turn": 18.0, "loop": 40.0,
               "out_and_back": 40.0}
    return WorldLayout(world, starts, lengths)


def _closed_to_open(clearance: float) -> WorldLayout:
    """A 5 m wide, 14 m long corridor opening into a 26 m x 30 m hall with cylinders and boxes."""
    # the loop circles a cylinder in the hall; out_and_back goes out of the corridor, turns
    # around at the hall's entrance and comes back through the corridor 2 m to the left
    starts = {"zigzag": (1.5, 0.0, 0.0), "straight": (1.5, 0.0, 0.0),
              "right_turn": (1.5, 1.0, 0.0), "loop": (32.0, -7.0, 0.0),
              "out_and_back": (1.5, -1.0, 0.0)}
    lengths = {"zigzag": 36.0, "straight": 36.0, "right_turn": 28.0, "loop": 40.0,
               "out_and_back": 40.0}
    circles = np.array(
        [(18, 6, 0.4), (21, -5, 0.3), (25, 9, 0.5), (27, -9, 0.4), (31, 5, 0.3), (33, -4, 0.5),
         (36, 10, 0.4), (22, 12, 0.3), (37, -11, 0.3), (19, -11, 0.5), (29, 0, 0.3)],
        dtype=float,
    )
    paths = [build_trace(s, starts[s], lengths[s]).waypoints for s in TRACE_NAMES]
    boxes = [_box(20, -8, 1.0, 0.6, 0.3), _box(26, 5, 0.8, 0.8, 0.0),
             _box(34, 12, 1.5, 0.5, -0.2), _box(30, -12, 0.7, 1.2, 0.5)]
    world = World(
        circles=_keep_clear(circles, paths, clearance + 0.2),
        segments=_polyline(CLOSED_TO_OPEN_OUTLINE, closed=True),
        polygons=[b for b in boxes if np.min(World(polygons=[b]).clearance(np.vstack(paths)))
                  >= clearance + 0.2],
        name="closed_to_open",
        bounds=(-1.0, -16.0, 41.0, 16.0),
    )
    return WorldLayout(world, starts, lengths)


_BUILT_IN: dict[str, Callable[[float], WorldLayout]] = {
    "open_cylinders": _open_cylinders,
    "hallway": _hallway,
    "closed_to_open": _closed_to_open,
}

#: Clearance [m] the built-in worlds keep around their default traces: the default car's
#: half-diagonal (0.47 m) plus the default margin (0.3 m) and 0.2 m to spare.
LAYOUT_CLEARANCE = 0.77


_OUTLINES: dict[str, NDArray[np.float64]] = {
    "hallway": HALLWAY_OUTLINE, "closed_to_open": CLOSED_TO_OPEN_OUTLINE,
}


@cache
def built_in_layout(name: str) -> WorldLayout:
    """The (cached, deterministic) layout of built-in world ``name`` (with its feature options:
    features placed clear of every default trace, so each still fits at full size)."""
    name = check_world_name(name)
    if name == "random":
        raise ConfigError("world 'random' has no fixed layout: use make_scene with a generator")
    base, options = parse_world_name(name)
    layout = _BUILT_IN[base](LAYOUT_CLEARANCE)
    if options.density == 0.0:
        return layout
    paths = np.vstack([build_trace(s, layout.starts[s], layout.lengths[s]).waypoints
                       for s in TRACE_NAMES])
    world, kinds = add_features(layout.world, _OUTLINES[base], options, paths,
                                LAYOUT_CLEARANCE, name)
    return WorldLayout(world, layout.starts, layout.lengths, kinds)


# Random worlds: sizes [m] chosen so a random world looks like the built-in ones.
RANDOM_TRACE_LENGTH = (15.0, 35.0)  # [m] drawn uniformly
RANDOM_ROOM_MARGIN = (3.0, 8.0)  # [m] room walls this far beyond the trace's bounding box
RANDOM_WALLS = (2, 7)  # interior walls (drawn in [low, high))
RANDOM_WALL_LENGTH = (2.0, 8.0)  # [m]
RANDOM_BOXES = (0, 5)
RANDOM_CYLINDERS = (5, 40)
RANDOM_CYLINDER_RADIUS = (0.15, 0.6)  # [m]
RANDOM_ATTEMPTS = 20  # draws per obstacle before it is skipped


def _random_scene(
    trace_name: str, rng: np.random.Generator, clearance: float, start: Pose | None
) -> Scene:
    """A room around a random trace, filled with walls, boxes and cylinders kept clear of it."""
    length = float(rng.uniform(*RANDOM_TRACE_LENGTH))
    pose = start if start is not None else (0.0, 0.0, float(rng.uniform(-math.pi, math.pi)))
    trace = build_trace(trace_name, pose, length)
    path = trace.waypoints
    margin = rng.uniform(*RANDOM_ROOM_MARGIN, size=4)
    lo = path.min(axis=0) - margin[:2] - clearance
    hi = path.max(axis=0) + margin[2:] + clearance
    room = _polyline([(lo[0], lo[1]), (hi[0], lo[1]), (hi[0], hi[1]), (lo[0], hi[1])], True)
    size = hi - lo

    def draw(make: Callable[[], Any], gap: Callable[[Any], float], count: int) -> list[Any]:
        kept = []
        for _ in range(count):
            for _ in range(RANDOM_ATTEMPTS):
                candidate = make()
                if gap(candidate) >= clearance:
                    kept.append(candidate)
                    break
        return kept

    def random_wall() -> NDArray[np.float64]:
        a = lo + rng.random(2) * size
        angle = rng.choice([0.0, 0.5 * math.pi]) + rng.normal(0.0, 0.1)
        b = a + rng.uniform(*RANDOM_WALL_LENGTH) * np.array([math.cos(angle), math.sin(angle)])
        return np.concatenate([a, np.clip(b, lo, hi)])

    def random_box() -> NDArray[np.float64]:
        cx, cy = lo + rng.random(2) * size
        hx, hy = rng.uniform(0.3, 1.5, size=2)
        return _box(cx, cy, hx, hy, rng.uniform(-math.pi, math.pi))

    def random_cylinder() -> NDArray[np.float64]:
        return np.array([*(lo + rng.random(2) * size), rng.uniform(*RANDOM_CYLINDER_RADIUS)])

    walls = draw(random_wall, lambda w: float(np.min(segment_distances(path, w[None]))),
                 int(rng.integers(*RANDOM_WALLS)))
    boxes = draw(random_box, lambda b: float(np.min(World(polygons=[b]).clearance(path))),
                 int(rng.integers(*RANDOM_BOXES)))
    cylinders = draw(
        random_cylinder,
        lambda c: float(np.min(np.hypot(*(path - c[:2]).T)) - c[2]),
        int(rng.integers(*RANDOM_CYLINDERS)),
    )
    world = World(
        circles=np.array(cylinders).reshape(-1, 3),
        segments=np.vstack([room, *[w[None] for w in walls]]),
        polygons=boxes,
        name="random",
        bounds=(lo[0] - 0.5, lo[1] - 0.5, hi[0] + 0.5, hi[1] + 0.5),
    )
    return Scene(world, trace)


def make_scene(
    name: str,
    trace: str | None = None,
    rng: np.random.Generator | None = None,
    clearance: float = LAYOUT_CLEARANCE,
    start: Pose | None = None,
) -> Scene:
    """World ``name`` with trace seed ``trace`` (default: the paper's) fitted into it.

    Args:
        name: one of :data:`WORLD_NAMES`, or ``hallway``/``closed_to_open`` with feature options
            (``"hallway?feature_density=4&feature_seed=1"``, :mod:`lidar_env.world.feature_worlds`).
        trace: one of the trace seeds, or ``None`` for :data:`PAPER_TRACES` ``[name]``.
        rng: the generator random worlds are drawn from (required for ``"random"``).
        clearance: [m] every trace waypoint keeps from obstacles.
        start: (x [m], y [m], heading [rad]) to start the trace from instead of the default.
    """
    name = check_world_name(name)
    trace = check_trace_name(trace if trace is not None else PAPER_TRACES[name])
    if name == "random":
        if not isinstance(rng, np.random.Generator):
            raise ArgumentTypeError(
                f"rng: world 'random' needs a numpy.random.Generator, got {type(rng).__name__}"
            )
        return _random_scene(trace, rng, clearance, start)
    layout = built_in_layout(name)
    pose = layout.starts[trace] if start is None else start
    return Scene(layout.world, make_trace(trace, pose, layout.lengths[trace], layout.world,
                                          clearance))


def make_world(
    name: str, rng: np.random.Generator | None = None, trace: str | None = None
) -> World:
    """World ``name`` alone (for ``"random"``, the one generated around ``trace``)."""
    return make_scene(name, trace, rng).world
