"""Which points of a scan lie on moving things, from the scans alone: the odometry's filter.

:class:`MovingPointFilter` keeps the last scans and asks :mod:`estimators.odometry.free_space`
which points lie in space a scan saw as free: the new scan's points that earlier scans saw
through moved in, those next to earlier points the new scan sees through moved on, and map
points the new scan sees through are stale. :mod:`estimators.odometry.local_map` leaves them
out of the match and the map (README, "Moving obstacles: odometry, maps and tracking").

Units: metres, radians, seconds; points in the world frame unless said otherwise.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from estimators.matching.scan_matching import voxel_downsample
from estimators.odometry.free_space import BeamGeometry
from lidar_env.errors import ConfigError
from lidar_env.se2 import compose, transform_points


@numba.njit(cache=True)
def _near_any(points: NDArray[np.float64], anchors: NDArray[np.float64],
              radius: float) -> NDArray[np.bool_]:
    """``(n,)`` True where ``points[i]`` lies within ``radius`` of one of ``anchors`` (m, 2)
    (brute force: the anchors are the few points a scan sees through)."""
    out = np.zeros(points.shape[0], dtype=np.bool_)
    limit = radius * radius
    for i in range(points.shape[0]):
        for j in range(anchors.shape[0]):
            dx, dy = points[i, 0] - anchors[j, 0], points[i, 1] - anchors[j, 1]
            if dx * dx + dy * dy < limit:
                out[i] = True
                break
    return out



class MovingPointFilter:
    """Tells which points of each new scan lie on moving things, and which map points are
    trails of things that moved away, from the scans alone.

    A point of the new scan is *moving* if one of the last ``history`` scans saw through it (it
    moved in), or if it lies within ``radius`` of a point the new scan sees through: of the
    scans of the last ``anchor_time`` or of the map (it moved on from there: a person walking
    away from the sensor keeps hiding where they will be, but not where they were). Map points
    the new scan sees through are *stale*. Nothing is propagated further, so a misjudged point
    cannot spread a label along a wall.

    The new scan judges map points only where its beams lie at most ``stale_resolution``
    apart: farther out, its beams can all pass an object thinner than their spacing (a door
    frame, a table leg at 8 m between 1-degree beams, 14 cm apart) that an earlier scan hit,
    and wrongly clearing it off the map is cumulative: on Intel, the map lost the far end of a
    corridor that way, the odometry stalled in it (1.9 m short over 70 scans, 36 correlative
    fallbacks) and ``lidar_odometry`` lost 20 % of its accuracy (0.0435 -> 0.0522 m per
    keyframe pair). A wrong "moved in" or "moved on" flag costs one scan's point, so those
    tests keep the full range: a walker far down a corridor is what pins (or drags) its axis,
    and one walking away at 0.5 m/s has left ``margin`` behind only after half a second. Only
    while the motion is steady, though: a pose that landed more than ``anchor_break`` from the
    motion model's guess in the last ``history`` scans may be off, and from a pose off by more
    than ``margin`` the new scan sees through its predecessors' far points; flagging the
    points next to them would lock the error in (a car that braked hard in a corridor stayed
    0.8 m off). Until the jumps have passed, the recent scans' points are judged like the
    map's, over the last ``history`` scans only.

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
    """

    def __init__(self, setup: Any, margin: float = 0.2, radius: float = 0.3,
                 history: int = 5, min_range: float = 0.0,
                 stale_resolution: float = 0.1, anchor_time: float = 1.0,
                 max_anchor_scans: int = 20, anchor_spacing: float = 0.05,
                 anchor_break: float = 0.05) -> None:
        self.setup = setup
        self.margin = margin
        self.radius = radius
        self.min_range = min_range
        if not stale_resolution > 0:  # NaN too; inf judges every earlier point
            raise ConfigError(f"stale_resolution: expected a beam spacing > 0 [m] (inf: no "
                              f"limit), got {stale_resolution!r}")
        self.stale_resolution = stale_resolution
        checks = {"anchor_time": (anchor_time, anchor_time >= 0, "a duration >= 0 [s]"),
                  "max_anchor_scans": (max_anchor_scans, max_anchor_scans >= 1,
                                       "a scan count >= 1"),
                  "anchor_spacing": (anchor_spacing, anchor_spacing > 0, "a spacing > 0 [m]"),
                  "anchor_break": (anchor_break, anchor_break >= 0, "a distance >= 0 [m]")}
        for name, (value, valid, expected) in checks.items():
            if not valid:  # NaN fails every comparison
                raise ConfigError(f"{name}: expected {expected}, got {value!r}")
        self.anchor_time = anchor_time
        self.anchor_spacing = anchor_spacing
        self.anchor_break = anchor_break
        self._history_length = history
        angles = [s.beam_angles for s in setup.sensors]
        ranges = [s.max_range for s in setup.sensors]
        # the last n scans packed as one setup of n x K sensors (one call); n = 1: the new scan
        self._past_beams = [BeamGeometry(angles * n, ranges * n)
                            for n in range(1, max(history, 1) + 1)]
        self._beams = self._past_beams[0]
        self._history: deque[tuple[NDArray[np.float64], list[NDArray[np.float64]]]] = deque(
            maxlen=history)
        self._past_poses = np.zeros((0, 3))
        self._past_ranges = np.zeros(0)
        self._anchor_scans: deque[NDArray[np.float64]] = deque(
            maxlen=max(max_anchor_scans, history))
        self._anchors = np.zeros((0, 2))  # their points, world frame, thinned
        self._anchor_resolution = math.inf
        self._jumps: deque[float] = deque(maxlen=max(history, 1))

    def _sensor_poses(self, pose: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.array([compose(pose, s.mount) for s in self.setup.sensors])

    def classify(
        self, points: NDArray[np.float64], pose: NDArray[np.float64],
        scans: Mapping[str, NDArray[np.float64]], map_points: list[NDArray[np.float64]],
    ) -> tuple[NDArray[np.bool_], list[NDArray[np.bool_]]]:
        """``(moving (n,), stale masks)`` for the new scan's car-frame ``points`` (n, 2) at
        (estimated) car ``pose`` and each world ``map_points`` array."""
        world = np.ascontiguousarray(transform_points(pose, points), dtype=np.float64)
        if self._history:  # moved in: seen through by one of the last scans
            past = self._past_beams[len(self._history) - 1]
            moving = past.judge(world, self._past_poses, self._past_ranges, self.margin,
                                self.min_range, math.inf)
        else:
            moving = np.zeros(len(points), dtype=np.bool_)
        sensor_poses, ranges = self._sensor_poses(pose), [scans[key] for key in self.setup.keys]
        sizes = [len(p) for p in map_points]
        flags = [np.zeros(0, dtype=np.bool_) for _ in map_points]
        anchors = [self._anchors[self._beams.seen_through(  # the recent scans'
            self._anchors, sensor_poses, ranges, self.margin, self.min_range,
            self._anchor_resolution)]]
        if sum(sizes):  # stale: map points it sees through, where its beams are dense
            stacked = np.concatenate(map_points)
            seen = self._beams.seen_through(stacked, sensor_poses, ranges, self.margin,
                                            self.min_range, self.stale_resolution)
            ends = np.cumsum(sizes)
            flags = [seen[end - size:end] for size, end in zip(sizes, ends, strict=True)]
            anchors.append(stacked[seen])
        near = np.concatenate(anchors)
        if len(near) and len(world):  # moved on: next to a point the new scan sees through
            moving |= _near_any(world, near, self.radius)
        return moving, flags

    def remember(self, pose: NDArray[np.float64], scans: Mapping[str, NDArray[np.float64]],
                 points: NDArray[np.float64], interval: float | None = None,
                 jump: float = 0.0) -> None:
        """Keep the scans (and their car-frame ``points``) taken at car ``pose`` for the next
        :meth:`classify`; ``interval`` [s]: the typical scan interval (None: unknown); ``jump``
        [m]: how far ``pose`` landed from the motion model's guess."""
        self._anchor_scans.append(transform_points(pose, points))
        self._jumps.append(jump)
        count = self._history_length
        steady = max(self._jumps) <= self.anchor_break
        # a pose that may be off sees through its predecessors' far points: judge them then
        # where the beams are dense only, and over the last ``history`` scans
        self._anchor_resolution = math.inf if steady else self.stale_resolution
        if steady and interval is not None and interval > 0:
            count = max(count, math.ceil(self.anchor_time / interval))
        recent = list(self._anchor_scans)[-count:] if count else []
        self._anchors = (voxel_downsample(np.concatenate(recent), self.anchor_spacing) if recent
                         else np.zeros((0, 2)))
        self._history.append((self._sensor_poses(pose), [scans[key] for key in self.setup.keys]))
        if not self._history:  # history=0: nothing is kept
            return
        # packed once here rather than at each classify (it runs up to twice a scan)
        self._past_poses = np.concatenate([poses for poses, _ in self._history])
        self._past_ranges = np.concatenate([np.asarray(r, dtype=np.float64).ravel()
                                            for _, ranges in self._history for r in ranges])
