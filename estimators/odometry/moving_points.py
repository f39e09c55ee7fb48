"""Which points of a scan lie on moving things, from the scans alone: the odometry's filter.

:class:`MovingPointFilter` keeps the last scans and asks :mod:`estimators.odometry.free_space`
which points lie in space a scan saw as free: the new scan's points that earlier scans saw
through moved in, those next to earlier points the new scan sees through moved on, and map
points the new scan sees through are stale. :mod:`estimators.odometry.local_map` leaves them
out of the match and the map.

Units: metres, radians, seconds; points in the world frame unless said otherwise.
"""

from __future__ import annotations

import itertools
import math
from collections import deque
from collections.abc import Mapping
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from estimators.odometry.free_space import BeamGeometry
from estimators.odometry.thinned_scans import ThinnedScans
from lidar_env.core import ConfigError
from lidar_env.core.se2 import compose_floats, transform_points


@numba.njit(cache=True)
def _near_any_plain(points: NDArray[np.float64], anchors: NDArray[np.float64],
                    radius: float) -> NDArray[np.bool_]:
    """:func:`_near_any` by brute force over every pair (the tests' reference)."""
    out = np.zeros(points.shape[0], dtype=np.bool_)
    limit = radius * radius
    for i in range(points.shape[0]):
        for j in range(anchors.shape[0]):
            dx, dy = points[i, 0] - anchors[j, 0], points[i, 1] - anchors[j, 1]
            if dx * dx + dy * dy < limit:
                out[i] = True
                break
    return out


#: [m] coordinates beyond it (or not finite) send :func:`_near_any` to brute force: their
#: cells would not fit an int64 key.
_GRID_LIMIT = 1e9


@numba.njit(cache=True)
def _near_any(points: NDArray[np.float64], anchors: NDArray[np.float64],
              radius: float) -> NDArray[np.bool_]:
    """``(n,)`` True where ``points[i]`` lies within ``radius`` [m] of one of ``anchors``
    (m, 2), same frame: :func:`_near_any_plain`'s test, asked only of the anchors in the 3 x 3
    cells around the point (cells a little wider than ``radius``, the anchors sorted by cell):
    any anchor the test passes has ``|dx|, |dy| < radius``, so it lies in one of them."""
    cell = radius * (1.0 + 1e-6)
    if not (cell > 0.0 and np.all(np.abs(points) < _GRID_LIMIT * cell)
            and np.all(np.abs(anchors) < _GRID_LIMIT * cell)):
        return _near_any_plain(points, anchors, radius)
    keys = np.empty(anchors.shape[0], dtype=np.int64)
    for j in range(anchors.shape[0]):  # row-major cell index: a row's cells are one run
        keys[j] = (np.int64(math.floor(anchors[j, 0] / cell)) << 32) + np.int64(
            math.floor(anchors[j, 1] / cell))
    order = np.argsort(keys)
    keys, near = keys[order], anchors[order]
    out = np.zeros(points.shape[0], dtype=np.bool_)
    limit = radius * radius
    for i in range(points.shape[0]):
        cx = np.int64(math.floor(points[i, 0] / cell))
        cy = np.int64(math.floor(points[i, 1] / cell))
        for row in (cx - 1, cx, cx + 1):  # the row's three cells: one run of keys
            j, last = np.searchsorted(keys, (row << 32) + cy - 1), (row << 32) + cy + 1
            while j < len(keys) and keys[j] <= last:
                dx, dy = points[i, 0] - near[j, 0], points[i, 1] - near[j, 1]
                if dx * dx + dy * dy < limit:
                    out[i] = True
                    break
                j += 1
            if out[i]:
                break
    return out


def split_like(stacked: NDArray[np.bool_], parts: list[NDArray[np.float64]]
               ) -> list[NDArray[np.bool_]]:
    """``stacked`` (a mask over ``parts`` concatenated in order) cut into one mask per part."""
    ends = itertools.accumulate(len(part) for part in parts)
    return [stacked[end - len(part):end] for part, end in zip(parts, ends, strict=True)]


class MovingPointFilter:
    """Tells which points of each new scan lie on moving things, and which map points are
    trails of things that moved away, from the scans alone.

    A point of the new scan is *moving* if one of the last ``history`` scans saw through it (it
    moved in), or if it lies within ``radius`` of a point the new scan sees through: of the
    scans of the last ``anchor_time`` or of the map (it moved on from there: a person walking
    away from the sensor keeps hiding where they will be, but not where they were). Map points
    the new scan sees through are *stale*. Nothing is propagated further, so a misjudged point
    cannot spread a label along a wall.

    The new scan judges map points only where its beams lie at most ``stale_resolution`` apart:
    farther out, its beams can all pass an object thinner than their spacing (a door frame, a table
    leg at 8 m between 1-degree beams, 14 cm apart) that an earlier scan hit, and wrongly clearing
    it off the map is cumulative: the map loses the far end of a corridor that way, and the odometry
    stalls in it. A wrong "moved in" or "moved on" flag costs one scan's point, so those tests keep
    the full range: a walker far down a corridor is what pins (or drags) its axis, and one walking
    away at 0.5 m/s has left ``margin`` behind only after half a second. Only while the motion is
    steady, though: a pose that landed more than ``anchor_break`` from the motion model's guess in
    the last ``history`` scans may be off, and from a pose off by more than ``margin`` the new scan
    sees through its predecessors' far points; flagging the points next to them would lock the error
    in. Until the jumps have passed, the recent scans' points are judged like the map's, over the
    last ``history`` scans only.

    Args:
        setup: the sensors' mounts, beams and ranges
            (:class:`~estimators.base.SensorSetup`).
        margin: [m] of :func:`seen_through`.
        radius: [m] how far a moving thing's surface may be from where it was seen one scan
            before (0.3: a brisk walker's 10 Hz step plus the surface's change of shape).
        history: earlier scans a point is checked against (5: at 10 Hz, half a second, in
            which a walker at 0.5 m/s moves farther than ``margin``; one scan before, a
            walker's surface has moved only 5-15 cm into space seen free).
        min_range: [m] readings below it are no return.
        stale_resolution: [m] the widest beam spacing at which the new scan judges map points
            (0.1: the thinnest static things indoors; 5.7 m out at 1-degree beams).
        anchor_time: [s] how far back the scans go whose points mark what moved on (1.0: a
            walker at 0.2 m/s has left ``margin`` behind); at least ``history`` scans, at most
            ``max_anchor_scans`` (20: half a second at 40 Hz), ``history`` scans while the
            scan interval is unknown.
        anchor_spacing: [m] those points thinned to one per cell of this size (0.05: a
            quarter of ``margin``; a second of scans holds each surface ten times over).
        anchor_break: [m] a pose this far from the motion model's guess (0.05: a quarter of
            ``margin``; ten times the prior's 5 mm at 10 Hz) counts as a jump (above).
        map_clearance, map_support: [m] :meth:`mappable` (0.3: ``radius``; 0.1: two of the
            local map's 5 cm voxels).
    """

    def __init__(self, setup: Any, margin: float = 0.2, radius: float = 0.3,
                 history: int = 5, min_range: float = 0.0,
                 stale_resolution: float = 0.1, anchor_time: float = 1.0,
                 max_anchor_scans: int = 20, anchor_spacing: float = 0.05,
                 anchor_break: float = 0.05, map_clearance: float = 0.3,
                 map_support: float = 0.1) -> None:
        self.setup = setup
        self.margin = margin
        self.radius = radius
        self.min_range = min_range
        if not stale_resolution > 0:  # NaN too; inf judges every earlier point
            raise ConfigError(f"stale_resolution: expected a beam spacing > 0 [m] (inf: no "
                              f"limit), got {stale_resolution!r}")
        self.stale_resolution = stale_resolution
        distances = {"radius": radius, "anchor_break": anchor_break,
                     "map_clearance": map_clearance, "map_support": map_support}
        checks = {**{name: (value, value >= 0, "a distance >= 0 [m]")
                     for name, value in distances.items()},
                  "history": (history, history >= 0, "a scan count >= 0"),
                  "anchor_time": (anchor_time, anchor_time >= 0, "a duration >= 0 [s]"),
                  "max_anchor_scans": (max_anchor_scans, max_anchor_scans >= 1,
                                       "a scan count >= 1"),
                  "anchor_spacing": (anchor_spacing, anchor_spacing > 0, "a spacing > 0 [m]")}
        for name, (value, valid, expected) in checks.items():
            if not valid:  # NaN fails every comparison
                raise ConfigError(f"{name}: expected {expected}, got {value!r}")
        self.anchor_time = anchor_time
        self.anchor_spacing = anchor_spacing
        self.anchor_break = anchor_break
        self.map_clearance, self.map_support = map_clearance, map_support
        self._history_length = history
        angles = [s.beam_angles for s in setup.sensors]
        ranges = [s.max_range for s in setup.sensors]
        # the last n scans packed as one setup of n x K sensors (one call); n = 1: the new scan
        self._past_beams = [BeamGeometry(angles * n, ranges * n)
                            for n in range(1, max(history, 1) + 1)]
        self._beams = self._past_beams[0]
        self._mounts = [[float(v) for v in s.mount] for s in setup.sensors]
        self._keys = list(setup.keys)
        # the last scans' sensor poses and free reach (BeamGeometry.free), packed
        self._history: deque[tuple[NDArray[np.float64], NDArray[np.float64]]] = deque(
            maxlen=history)
        self._past_poses = np.zeros((0, 3))
        self._past_free = np.zeros(0)
        self._anchor_scans = ThinnedScans(max(max_anchor_scans, history), anchor_spacing)
        self._anchors = np.zeros((0, 2))  # their points, world frame, thinned
        self._anchor_resolution = math.inf
        self._jumps: deque[float] = deque(maxlen=max(history, 1))
        self._last_scan: tuple[Any, ...] | None = None  # what _at saw and gave last
        # the map arrays classify was given last and their concatenation (read-only, as scans)
        self._last_map: tuple[list[NDArray[np.float64]], NDArray[np.float64]] = (
            [], np.zeros((0, 2)))

    def _at(self, pose: NDArray[np.float64], points: NDArray[np.float64],
            scans: Mapping[str, NDArray[np.float64]],
            ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """The scan's world points (n, 2), its sensors' world poses (K, 3) (:func:`compose`'s
        floats) and its beams' free reach (:meth:`BeamGeometry.free`) at car ``pose``: the last
        ones again for the same arrays (as the filter keeps the scans it is given, it takes
        them as read-only), the reach for the same scans at any pose (a scan is classified at
        up to two poses, then remembered at the last)."""
        car = np.asarray(pose, dtype=np.float64)
        stamp = car.tobytes()
        arrays = [scans[key] for key in self._keys]
        last = self._last_scan
        same_scans = last is not None and all(
            a is b for a, b in zip(arrays, last[2], strict=True))
        if last is not None and same_scans and points is last[1] and stamp == last[0]:
            return last[3], last[4], last[5]
        free = (last[5] if last is not None and same_scans else
                self._beams.free(self._beams.pack(arrays, self.min_range), self.min_range))
        world = np.ascontiguousarray(transform_points(car, points), dtype=np.float64)
        floats = car.tolist()
        sensor_poses = np.array([compose_floats(floats, mount) for mount in self._mounts])
        self._last_scan = (stamp, points, arrays, world, sensor_poses, free)
        return world, sensor_poses, free

    def classify(
        self, points: NDArray[np.float64], pose: NDArray[np.float64],
        scans: Mapping[str, NDArray[np.float64]], map_points: list[NDArray[np.float64]],
    ) -> tuple[NDArray[np.bool_], list[NDArray[np.bool_]]]:
        """``(moving (n,), stale masks)`` for the new scan's car-frame ``points`` (n, 2) at
        (estimated) car ``pose`` and each world ``map_points`` array."""
        moving, stale = self.classify_stacked(points, pose, scans, map_points)
        return moving, split_like(stale, map_points)

    def classify_stacked(
        self, points: NDArray[np.float64], pose: NDArray[np.float64],
        scans: Mapping[str, NDArray[np.float64]], map_points: list[NDArray[np.float64]],
    ) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
        """:meth:`classify` with the stale masks as one: over ``map_points`` concatenated in
        order (one count and no split where few are stale)."""
        world, sensor_poses, free = self._at(pose, points, scans)
        if self._history:  # moved in: seen through by one of the last scans
            past = self._past_beams[len(self._history) - 1]
            moving = past.judge_free(world, self._past_poses, self._past_free, self.margin,
                                     self.min_range, math.inf)
        else:
            moving = np.zeros(len(points), dtype=np.bool_)
        stacked = self._stacked(map_points)
        near = self._anchors.compress(self._beams.judge_free(  # the recent scans'
            self._anchors, sensor_poses, free, self.margin, self.min_range,
            self._anchor_resolution), axis=0)
        if len(stacked):  # stale: map points it sees through, where its beams are dense
            stale = self._beams.judge_free(stacked, sensor_poses, free, self.margin,
                                           self.min_range, self.stale_resolution)
            near = np.concatenate((near, stacked.compress(stale, axis=0)))
        else:
            stale = np.zeros(0, dtype=np.bool_)
        if len(near) and len(world):  # moved on: next to a point the new scan sees through
            moving |= _near_any(world, near, self.radius)
        return moving, stale

    def _stacked(self, map_points: list[NDArray[np.float64]]) -> NDArray[np.float64]:
        """``map_points`` concatenated (C-contiguous float64, (0, 2) for none): the last
        concatenation again for the same arrays (a scan is classified up to three times
        against the same map)."""
        last, stacked = self._last_map
        if len(last) != len(map_points) or any(
                a is not b for a, b in zip(last, map_points, strict=True)):
            stacked = np.ascontiguousarray(np.concatenate([np.zeros((0, 2)), *map_points]),
                                           dtype=np.float64)
            self._last_map = (list(map_points), stacked)
        return stacked

    def seen_free_share(self, points: NDArray[np.float64], pose: NDArray[np.float64]) -> float:
        """The share of car-frame ``points`` (n, 2) that, with the car at ``pose`` (3,), lie
        in space the remembered scans saw as free (0 with none remembered): how much a
        candidate pose contradicts what the Lidar saw, where the share a map explains says
        nothing of the points that fall outside the map."""
        if not self._history or not len(points):
            return 0.0
        world = np.ascontiguousarray(transform_points(np.asarray(pose, dtype=np.float64),
                                                      points), dtype=np.float64)
        past = self._past_beams[len(self._history) - 1]
        seen = past.judge_free(world, self._past_poses, self._past_free, self.margin,
                               self.min_range, math.inf)
        return float(np.count_nonzero(seen)) / len(points)

    def mappable(self, world: NDArray[np.float64], moving: NDArray[np.bool_],
                 map_points: list[NDArray[np.float64]]) -> NDArray[np.bool_]:
        """``(n,)`` True for the scan's ``world`` points (n, 2) fit for the map, given which
        are ``moving`` (:meth:`classify`): neither moving nor within ``map_clearance`` of a
        moving one, unless one of ``map_points`` lies within ``map_support`` (a wall the map
        knows, beside a walker). The few points of a walker the filter misses lie next to
        those it caught; in a keyframe they stay while the walker walks on, and drag the
        estimate where little else pins it."""
        keep = ~moving
        if not np.any(moving) or self.map_clearance <= 0:
            return keep
        near = _near_any(world, np.ascontiguousarray(world[moving]), self.map_clearance)
        known = self._stacked(map_points)
        if np.any(near & keep) and self.map_support > 0 and len(known):
            near &= ~_near_any(world, known, self.map_support)
        return keep & ~near

    def remember(self, pose: NDArray[np.float64], scans: Mapping[str, NDArray[np.float64]],
                 points: NDArray[np.float64], interval: float | None = None,
                 jump: float = 0.0) -> None:
        """Keep the scans (and their car-frame ``points``) taken at car ``pose`` for the next
        :meth:`classify`; ``interval`` [s]: the typical scan interval (None: unknown); ``jump``
        [m]: how far ``pose`` landed from the motion model's guess."""
        world, sensor_poses, free = self._at(pose, points, scans)
        self._anchor_scans.add(world)
        self._jumps.append(jump)
        count = self._history_length
        steady = max(self._jumps) <= self.anchor_break
        # a pose that may be off sees through its predecessors' far points: judge them then
        # where the beams are dense only, and over the last ``history`` scans
        self._anchor_resolution = math.inf if steady else self.stale_resolution
        if steady and interval is not None and interval > 0:
            count = max(count, math.ceil(self.anchor_time / interval))
        self._anchors = self._anchor_scans.thinned(count)
        if not self._history.maxlen:  # history=0: nothing is kept
            return
        self._history.append((sensor_poses, free))
        # packed once here rather than at each classify (it runs up to twice a scan)
        self._past_poses = np.concatenate([poses for poses, _ in self._history])
        self._past_free = np.concatenate([free for _, free in self._history])
