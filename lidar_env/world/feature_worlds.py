"""The feature-density world family: the paper's closed shapes with wall features placed from a
seed, so the paper's method can be measured against how much there is to lock onto.

A world name takes options after ``?``, like a URL query::

    "hallway?feature_density=4&feature_seed=1"
    "closed_to_open?feature_density=2"

``feature_density`` is in **features per 10 m of wall** (of the world's outline; default 0,
i.e. exactly today's world, bit for bit), at most :data:`MAX_FEATURE_DENSITY` (about one
feature per metre of wall: as many edges within a Lidar's reach as in the open area).
``feature_seed`` (an integer >= 0, default 0) places them. The features are of four kinds:

* ``door``: a recess cut into the wall (0.8-1.2 m wide, 0.3-0.8 m deep);
* ``pillar``: a box standing against the wall (0.3-0.6 m wide, 0.2-0.5 m out);
* ``corner``: an L-shaped wall stub (0.4-1.0 m out, 0.3-0.8 m along), two corners;
* ``clutter``: a cylinder or a box 0.1-0.8 m off the wall.

Candidates are drawn one after the other from ``numpy.random.default_rng(feature_seed)``; a
candidate is kept when it overlaps no earlier feature or obstacle, stays on its wall, and keeps
the world's default traces (every trace seed) ``clearance + 0.2`` m clear, until
``round(density * wall length / 10)`` are kept. The kept features of a lower density are
therefore the first ones of any higher density (same seed). Coordinates are metres, world
frame.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from lidar_env.core.errors import ConfigError, MapError
from lidar_env.world.polygons import segment_distances
from lidar_env.world.world import World

#: The worlds with a feature density: the paper's closed and closed-to-open areas.
FEATURE_WORLDS: tuple[str, ...] = ("hallway", "closed_to_open")

#: [features per 10 m of wall] the densest the family goes: about one feature per metre.
MAX_FEATURE_DENSITY = 10.0

FEATURE_KINDS: tuple[str, ...] = ("door", "pillar", "corner", "clutter")

#: Candidates drawn per feature asked for before placement gives up (dense walls saturate).
ATTEMPTS_PER_FEATURE = 30

#: [m] gap kept between the bounding circles of two features (or a feature and an obstacle).
FEATURE_GAP = 0.1

#: [m] extra clearance features keep from the default traces, as the built-in obstacles do.
TRACE_SPARE = 0.2

OPTION_KEYS: tuple[str, ...] = ("feature_density", "feature_seed")


@dataclass(frozen=True)
class FeatureOptions:
    """The options of a world name: density [features per 10 m of wall] and placement seed."""

    density: float = 0.0
    seed: int = 0


def _check_density(value: Any, name: str) -> float:
    try:
        density = float(value)
    except (TypeError, ValueError):
        density = math.nan
    if not math.isfinite(density) or not 0.0 <= density <= MAX_FEATURE_DENSITY:
        raise ConfigError(
            f"world {name!r}: feature_density: expected a number in [0, {MAX_FEATURE_DENSITY:g}] "
            f"features per 10 m of wall, got {value!r}"
        )
    return density


def _check_seed(value: Any, name: str) -> int:
    text = str(value)
    if not text.isdigit():
        raise ConfigError(
            f"world {name!r}: feature_seed: expected an integer >= 0, got {value!r}"
        )
    return int(text)


def parse_world_name(name: str) -> tuple[str, FeatureOptions]:
    """``"base?key=value&..."`` -> (base name, options); a name without ``?`` has none.

    Raises:
        ConfigError: an unknown key, a key twice, a bad density or seed, or options on a world
            outside :data:`FEATURE_WORLDS`.
    """
    base, sep, query = name.partition("?")
    if not sep:
        return base, FeatureOptions()
    if base not in FEATURE_WORLDS:
        raise ConfigError(
            f"world {name!r}: options after '?' are for {', '.join(FEATURE_WORLDS)} only, "
            f"got world {base!r}"
        )
    given: dict[str, str] = {}
    for item in query.split("&"):
        key, eq, value = item.partition("=")
        if not eq or key not in OPTION_KEYS or key in given:
            raise ConfigError(
                f"world {name!r}: expected options key=value joined by '&' with keys among "
                f"{', '.join(OPTION_KEYS)} (each once), got {item!r}"
            )
        given[key] = value
    return base, FeatureOptions(_check_density(given.get("feature_density", 0.0), name),
                                _check_seed(given.get("feature_seed", 0), name))


def feature_world_name(base: str, density: float, seed: int = 0) -> str:
    """The canonical name of ``base`` at ``density`` [features per 10 m of wall] placed from
    ``seed``; density 0 is the plain ``base`` (today's world)."""
    if base not in FEATURE_WORLDS:
        raise ConfigError(f"base: expected one of {', '.join(FEATURE_WORLDS)}, got {base!r}")
    density = _check_density(density, base)
    seed = _check_seed(seed, base)
    if density == 0.0:
        return base
    return f"{base}?feature_density={density:.12g}&feature_seed={seed}"


@dataclass
class _Placed:
    """What the features kept so far add to the world, and their bounding circles."""

    circles: list[tuple[float, float, float]] = field(default_factory=list)
    polygons: list[NDArray[np.float64]] = field(default_factory=list)
    stubs: list[NDArray[np.float64]] = field(default_factory=list)  # (4,) wall segments
    doors: list[tuple[int, float, float, float]] = field(default_factory=list)  # edge, t0, t1, d
    bounds: list[tuple[float, float, float]] = field(default_factory=list)  # cx, cy, r
    kinds: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class _Candidate:
    kind: str
    bound: tuple[float, float, float]  # bounding circle cx, cy, r [m]
    edge: int
    span: tuple[float, float]  # [m] along its wall edge
    circle: tuple[float, float, float] | None = None
    polygon: NDArray[np.float64] | None = None
    segments: NDArray[np.float64] | None = None  # (k, 4) lines it adds
    depth: float = 0.0  # [m] of a door recess


def _rectangle(origin: NDArray, u: NDArray, n: NDArray, along: tuple[float, float],
               out: tuple[float, float]) -> NDArray[np.float64]:
    """``(4, 2)`` corners ``origin + a u + b n`` for a in ``along``, b in ``out``."""
    (a0, a1), (b0, b1) = along, out
    return np.array([origin + a0 * u + b0 * n, origin + a1 * u + b0 * n,
                     origin + a1 * u + b1 * n, origin + a0 * u + b1 * n])


def _edges_of(points: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.hstack([points, np.roll(points, -1, axis=0)])


def _bound(points: NDArray[np.float64]) -> tuple[float, float, float]:
    centre = points.mean(axis=0)
    return (float(centre[0]), float(centre[1]),
            float(np.max(np.hypot(*(points - centre).T))))


def _draw(rng: np.random.Generator, edges: NDArray[np.float64],
          inward: NDArray[np.float64]) -> _Candidate:
    """One candidate feature at a uniformly drawn point of the outline."""
    lengths = np.hypot(*(edges[:, 2:] - edges[:, :2]).T)
    s = rng.uniform(0.0, float(lengths.sum()))
    k = min(int(np.searchsorted(np.cumsum(lengths), s, side="right")), len(edges) - 1)
    t = s - float(np.sum(lengths[:k]))
    a, u, n = edges[k, :2], (edges[k, 2:] - edges[k, :2]) / lengths[k], inward[k]
    kind = FEATURE_KINDS[int(rng.integers(len(FEATURE_KINDS)))]
    if kind == "door":
        half, depth = rng.uniform(0.4, 0.6), rng.uniform(0.3, 0.8)
        box = _rectangle(a, u, n, (t - half, t + half), (-depth, 0.0))
        lines = np.array([[*box[3], *box[0]], [*box[0], *box[1]], [*box[1], *box[2]]])
        return _Candidate(kind, _bound(box), k, (t - half, t + half), segments=lines,
                          depth=float(depth))
    if kind == "pillar":
        half, out = rng.uniform(0.15, 0.3), rng.uniform(0.2, 0.5)
        box = _rectangle(a, u, n, (t - half, t + half), (-0.05, out))
        return _Candidate(kind, _bound(box), k, (t - half, t + half), polygon=box)
    if kind == "corner":
        out, along = rng.uniform(0.4, 1.0), rng.uniform(0.3, 0.8) * rng.choice([-1.0, 1.0])
        p0, p1 = a + t * u, a + t * u + out * n
        p2 = p1 + along * u
        return _Candidate(kind, _bound(np.array([p0, p1, p2, p0 + along * u])), k,
                          (min(t, t + along), max(t, t + along)),
                          segments=np.array([[*p0, *p1], [*p1, *p2]]))
    gap = rng.uniform(0.1, 0.8)
    if rng.random() < 0.5:
        r = rng.uniform(0.15, 0.35)
        c = a + t * u + (gap + r) * n
        return _Candidate(kind, (float(c[0]), float(c[1]), float(r)), k, (t - r, t + r),
                          circle=(float(c[0]), float(c[1]), float(r)))
    hx, hy, angle = rng.uniform(0.15, 0.4), rng.uniform(0.15, 0.4), rng.uniform(0, math.pi)
    c, rot = a + t * u + (gap + max(hx, hy) * math.sqrt(2)) * n, np.array(
        [[math.cos(angle), math.sin(angle)], [-math.sin(angle), math.cos(angle)]])
    box = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]]) @ rot + c
    return _Candidate(kind, _bound(box), k, (t - hx, t + hx), polygon=box)


def _trace_gap(candidate: _Candidate, paths: NDArray[np.float64]) -> float:
    """[m] from the candidate's geometry to the nearest path point (inf when none is near)."""
    cx, cy, r = candidate.bound
    near = paths[np.hypot(paths[:, 0] - cx, paths[:, 1] - cy) < r + 5.0]
    if len(near) == 0:
        return math.inf
    if candidate.circle is not None:
        x, y, radius = candidate.circle
        return float(np.min(np.hypot(near[:, 0] - x, near[:, 1] - y)) - radius)
    lines = candidate.segments if candidate.polygon is None else _edges_of(candidate.polygon)
    return float(np.min(segment_distances(near, lines)))


def _fits(candidate: _Candidate, placed: _Placed, edges: NDArray[np.float64],
          obstacles: Sequence[tuple[float, float, float]], paths: NDArray[np.float64],
          clearance: float) -> bool:
    """The candidate stays on its wall, off the other walls, features and obstacles, and
    keeps ``clearance`` + :data:`TRACE_SPARE` [m] from the traces."""
    k, (t0, t1) = candidate.edge, candidate.span
    length = float(np.hypot(*(edges[k, 2:] - edges[k, :2])))
    if t0 < FEATURE_GAP or t1 > length - FEATURE_GAP:
        return False
    cx, cy, r = candidate.bound
    others = np.delete(edges, k, axis=0)
    if np.min(segment_distances(np.array([[cx, cy]]), others)) < r + FEATURE_GAP:
        return False
    for ox, oy, orad in (*obstacles, *placed.bounds):
        if math.hypot(cx - ox, cy - oy) < r + orad + FEATURE_GAP:
            return False
    return _trace_gap(candidate, paths) >= clearance + TRACE_SPARE


def _keep(candidate: _Candidate, placed: _Placed) -> None:
    placed.bounds.append(candidate.bound)
    placed.kinds.append(candidate.kind)
    if candidate.circle is not None:
        placed.circles.append(candidate.circle)
    elif candidate.polygon is not None:
        placed.polygons.append(candidate.polygon)
    elif candidate.kind == "door":
        placed.doors.append((candidate.edge, *candidate.span, candidate.depth))
        placed.stubs.extend(candidate.segments)
    else:
        placed.stubs.extend(candidate.segments)


def _walls(edges: NDArray[np.float64], doors: list[tuple[int, float, float, float]]
           ) -> NDArray[np.float64]:
    """The outline's edges with a gap cut where each door recess opens."""
    walls = []
    for k, edge in enumerate(edges):
        a, b = edge[:2], edge[2:]
        u = (b - a) / np.hypot(*(b - a))
        cuts = sorted((t0, t1) for j, t0, t1, _ in doors if j == k)
        start = 0.0
        for t0, t1 in cuts:
            walls.append([*(a + start * u), *(a + t0 * u)])
            start = t1
        walls.append([*(a + start * u), *b])
    return np.array(walls, dtype=np.float64)


def _inward_normals(outline: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(k, 2)`` unit normal of each outline edge pointing into the enclosed area."""
    edges = _edges_of(outline)
    d = edges[:, 2:] - edges[:, :2]
    d /= np.hypot(*d.T)[:, None]
    x, y = outline[:, 0], outline[:, 1]
    area2 = float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))  # > 0: counter-clockwise
    left = np.stack([-d[:, 1], d[:, 0]], axis=1)
    return left if area2 > 0 else -left


def add_features(world: World, outline: NDArray[np.float64], options: FeatureOptions,
                 paths: NDArray[np.float64], clearance: float, name: str
                 ) -> tuple[World, tuple[str, ...]]:
    """``world`` (whose walls are the closed ``outline`` (k, 2) [m]) with features at
    ``options.density`` per 10 m of outline, kept ``clearance`` [m] + spare off ``paths``
    ((N, 2) waypoints of the default traces), and the kinds of the features placed, in order.
    Density 0 returns ``world`` itself."""
    if options.density == 0.0:
        return world, ()
    edges = _edges_of(outline)
    if not np.array_equal(edges, world.walls):
        raise MapError(f"outline: expected the walls of world {world.name!r}")
    inward = _inward_normals(outline)
    perimeter = float(np.sum(np.hypot(*(edges[:, 2:] - edges[:, :2]).T)))
    wanted = round(options.density * perimeter / 10.0)
    obstacles = [tuple(float(v) for v in c) for c in world.circles]
    obstacles += [_bound(p) for p in world.polygons]
    rng = np.random.default_rng(options.seed)
    placed = _Placed()
    for _ in range(ATTEMPTS_PER_FEATURE * wanted):
        if len(placed.kinds) >= wanted:
            break
        candidate = _draw(rng, edges, inward)
        if _fits(candidate, placed, edges, obstacles, paths, clearance):
            _keep(candidate, placed)
    depth = max((d for *_, d in placed.doors), default=0.0)
    xmin, ymin, xmax, ymax = world.bounds
    featured = World(
        circles=np.vstack([world.circles, np.array(placed.circles).reshape(-1, 3)]),
        segments=np.vstack([_walls(edges, placed.doors), np.array(placed.stubs).reshape(-1, 4)]),
        polygons=[*world.polygons, *placed.polygons], name=name,
        bounds=(xmin - depth, ymin - depth, xmax + depth, ymax + depth),
    )
    return featured, tuple(placed.kinds)
