"""Tracking static obstacles across steps (:class:`ObstacleTracker`): nearest-neighbour
association with a gate. A detection joins the track whose position (circle centre for round
obstacles, else centroid) is nearest, if it lies within ``gate`` [m], or, if it is extended,
the track whose latest returns come within ``surface_gate`` [m] of its own (a wall's centroid
moves with the car, its surface does not); several detections may join one track in one step,
which is how the same obstacle seen by both Lidars gets one id. A round track's circle is the
joint Kåsa fit of every point it was given, so its centre sharpens as the arc is seen from
more sides. Detections come from :mod:`estimators.mapping.obstacles`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numba
import numpy as np
from numpy.typing import NDArray

from estimators.mapping.circle_fit import (
    CircleFit,
    kasa_circle,
    kasa_moments,
    solve_kasa,
)
from estimators.mapping.obstacles import Obstacle
from lidar_env.core import ConfigError


@numba.njit(cache=True)
def _nearest_distance(a: NDArray[np.float64], b: NDArray[np.float64]) -> float:
    """Smallest distance [m] between a point of ``a`` (m, 2) and a point of ``b`` (k, 2);
    brute force, as both are one obstacle's returns (tens of points)."""
    best = np.inf
    for i in range(len(a)):
        for j in range(len(b)):
            best = min(best, (a[i, 0] - b[j, 0]) ** 2 + (a[i, 1] - b[j, 1]) ** 2)
    return math.sqrt(best)


@dataclass
class Track:
    """One obstacle followed across steps.

    Attributes:
        id: stable identifier, unique within its tracker.
        position: ``(2,)`` world position [m]: the circle centre of a round track, else the
            latest centroid.
        circle: joint circle fit of all round detections, or ``None`` (updated every step, for
            association; :meth:`consensus_circle` is the one to report).
        points: ``(m, 2)`` world returns [m] of the latest step it was detected in.
        hits: detections joined so far.
        round_hits, circle_tests: detections found round, and tested for roundness.
        first_step, last_step: steps of the first and the latest detection.
    """

    id: int
    position: NDArray[np.float64]
    circle: CircleFit | None
    points: NDArray[np.float64]
    hits: int
    first_step: int
    last_step: int
    _origin: NDArray[np.float64] = field(repr=False)
    round_hits: int = 0
    circle_tests: int = 0
    _normal: NDArray[np.float64] = field(default_factory=lambda: np.zeros((3, 3)), repr=False)
    _rhs: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3), repr=False)
    # per round detection: its Kåsa normal equations about _origin, its own centre and rms
    _round: list[tuple[NDArray[np.float64], NDArray[np.float64], float, float, float]] = field(
        default_factory=list, repr=False)
    _positions: list[NDArray[np.float64]] = field(default_factory=list, repr=False)

    def reach(self) -> tuple[NDArray[np.float64], float]:
        """Centre (2,) [m] and radius [m] of a circle holding :attr:`points`: their mean and
        the largest distance from it."""
        centre = self.points.mean(axis=0)
        return centre, float(np.sqrt(np.max(np.sum((self.points - centre) ** 2, axis=1))))

    def surface_distance(self, points: NDArray[np.float64]) -> float:
        """Smallest distance [m] from ``points`` (m, 2) to this track's latest returns."""
        return _nearest_distance(np.ascontiguousarray(points, dtype=np.float64), self.points)

    def add(self, obstacle: Obstacle, step: int) -> None:
        """Join ``obstacle`` (detected at ``step``) to this track."""
        same_step = self.hits > 0 and step == self.last_step  # e.g. seen by both Lidars
        self.points = np.vstack([self.points, obstacle.points]) if same_step else obstacle.points
        self.hits += 1
        self.last_step = step
        self._positions.append(obstacle.position)
        self.circle_tests += obstacle.circle_tested
        if obstacle.circle is None:
            if self.circle is None:
                self.position = obstacle.centroid.copy()
            return
        self.round_hits += 1
        normal, rhs = kasa_moments(obstacle.points, self._origin)
        self._round.append((normal, rhs, obstacle.circle.cx, obstacle.circle.cy,
                            obstacle.circle.rms))
        self._normal += normal
        self._rhs += rhs
        cx, cy, radius, rms = kasa_circle(self._normal, self._rhs, obstacle.points,
                                           self._origin)
        if not math.isnan(radius):
            self.circle = CircleFit(cx, cy, radius, rms)
            self.position = self.circle.centre

    def centre_spread(self) -> float:
        """Median distance [m] of the round detections' own centres from their median: about a
        centimetre for a post, the extent of the path for a person walking (0 with fewer than
        two round detections)."""
        centres = np.array([(cx, cy) for _, _, cx, cy, _ in self._round]).reshape(-1, 2)
        if len(centres) < 2:
            return 0.0
        return float(np.median(np.hypot(*(centres - np.median(centres, axis=0)).T)))

    def travel(self) -> float:
        """Median distance [m] of its detections' positions (circle centre, else centroid) from
        their median: about a centimetre for a post seen round, a fraction of its radius when
        seen as short arcs, the extent of the path for a person walking."""
        positions = np.array(self._positions)
        return float(np.median(np.hypot(*(positions - np.median(positions, axis=0)).T)))

    def consensus_circle(self) -> CircleFit | None:
        """The joint Kåsa fit of the round detections whose own centre lies within three
        median distances of the median centre (about 3.5 sigma of a Gaussian scatter, whose
        median distance is 1.18 sigma), or ``None`` if none was round. A few short arcs that
        a circle fitted by chance (5 returns of a cylinder and of the wall behind it) would
        otherwise pull the centre by decimetres. ``rms`` is the median of the kept detections'."""
        if not self._round:
            return None
        centres = np.array([(cx, cy) for _, _, cx, cy, _ in self._round])
        distances = np.hypot(*(centres - np.median(centres, axis=0)).T)
        keep = distances <= 3.0 * np.median(distances)
        kept = [d for d, k in zip(self._round, keep, strict=True) if k]
        cx, cy, radius_squared = solve_kasa(sum(d[0] for d in kept), sum(d[1] for d in kept))
        if not radius_squared > 0.0:
            return None
        return CircleFit(cx + self._origin[0], cy + self._origin[1], math.sqrt(radius_squared),
                         float(np.median([d[4] for d in kept])))


@dataclass
class ObstacleTracker:
    """Gives each static obstacle one id across steps (nearest neighbour within a gate).

    A detection joins the nearest track by position (circle centre or centroid) within
    ``gate`` [m]; an extended (not round) detection may instead join the track whose latest
    returns come within ``surface_gate`` [m] of its own, so a wall whose centroid wanders as
    the car drives along it keeps its id.

    ``gate`` defaults to 0.5 m: several times the per-step drift of a usable pose estimate and
    larger than the radius of the round obstacles we fit (so an arc's centroid and its fitted
    centre fall in one gate), yet below the spacing of obstacles a car can pass between
    (its width, 0.5 m here, plus margins). ``surface_gate`` defaults to 0.2 m: the returns of
    one surface in consecutive scans lie within one beam spacing of each other (0.17 m at 10 m
    for 1-degree beams), while distinct obstacles this close are one obstacle to a car.

    The tracks' positions and bounding circles are kept in arrays, so that associating a
    detection costs a few vector operations over all tracks and an exact surface distance only
    to the tracks whose bounding circles come within ``surface_gate``."""

    gate: float = 0.5
    surface_gate: float = 0.2
    tracks: list[Track] = field(default_factory=list)
    _step: int = field(default=-1, repr=False)
    _positions: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 2)),
                                            repr=False)
    _reach: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3)), repr=False)

    def __post_init__(self) -> None:
        for name in ("gate", "surface_gate"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ConfigError(f"{name}: expected a positive distance [m], got {value!r}")

    def update(self, obstacles: list[Obstacle]) -> list[int]:
        """Associate one step's detections (from any number of Lidars); return their track ids."""
        self._step += 1
        ids = []
        for obstacle in obstacles:
            track = self.nearest(obstacle)
            if track is None:
                track = Track(
                    id=len(self.tracks), position=obstacle.position.copy(), circle=None,
                    points=obstacle.points, hits=0, first_step=self._step,
                    last_step=self._step, _origin=obstacle.centroid.copy(),
                )
                self.tracks.append(track)
                self._positions = np.vstack([self._positions, np.zeros((1, 2))])
                self._reach = np.vstack([self._reach, np.zeros((1, 3))])
            track.add(obstacle, self._step)
            self._positions[track.id] = track.position
            if track.points is obstacle.points:  # its first detection this step
                self._reach[track.id] = (*obstacle.centroid, obstacle.spread)
            else:
                centre, radius = track.reach()
                self._reach[track.id] = (*centre, radius)
            ids.append(track.id)
        return ids

    def nearest(self, obstacle: Obstacle) -> Track | None:
        """The track ``obstacle`` belongs to (see the class doc), or ``None``."""
        if not self.tracks:
            return None
        distances = np.hypot(self._positions[:, 0] - obstacle.position[0],
                             self._positions[:, 1] - obstacle.position[1])
        distances[distances > self.gate] = np.inf
        if obstacle.circle is None:
            # only tracks whose returns could be within surface_gate: bounding circles first
            near = (np.hypot(self._reach[:, 0] - obstacle.centroid[0],
                             self._reach[:, 1] - obstacle.centroid[1])
                    <= obstacle.spread + self._reach[:, 2] + self.surface_gate)
            for i in np.flatnonzero(near):
                surface = self.tracks[i].surface_distance(obstacle.points)
                if surface <= self.surface_gate:
                    distances[i] = min(distances[i], surface)
        best = int(np.argmin(distances))
        return self.tracks[best] if np.isfinite(distances[best]) else None

    def cylinders(self, min_hits: int = 3, min_round_share: float = 0.5,
                  max_centre_spread: float = 0.05, max_travel: float = 0.3
                  ) -> NDArray[np.float64]:
        """``(M, 3)`` rows ``cx, cy, r`` [m] (:meth:`Track.consensus_circle`) of the round
        tracks detected at least ``min_hits`` times (one detection may be a coincidence of
        noise), round in at least ``min_round_share`` of their roundness tests (the majority
        of the views that could tell) and standing still: :meth:`Track.centre_spread` at most
        ``max_centre_spread`` [m] (0.05: posts in the built-in worlds scatter 4-15 mm, people
        tracked for a second walked 7 cm and more) and :meth:`Track.travel` at most
        ``max_travel`` [m] (0.3: a post's centroids wander by up to about its radius as the
        view changes; this catches people seen round only once). Moving round things are
        :mod:`estimators.mapping.motion_tracking`'s.
        A cylinder is round in most of them, also one touching a wall, whose arc the detector
        cuts out of the wall's cluster (85-100 % in the built-in worlds and the tests); the
        convex corner of a box or of two walls in a few percent (a short arc of returns around
        it fits a circle), at most 11 % in the built-in worlds."""
        if not 0.0 <= min_round_share <= 1.0:
            raise ConfigError(
                f"min_round_share: expected a share in [0, 1], got {min_round_share!r}"
            )
        circles = [
            t.consensus_circle() for t in self.tracks
            if t.circle is not None and t.hits >= min_hits
            and t.round_hits >= min_round_share * t.circle_tests
            and t.centre_spread() <= max_centre_spread and t.travel() <= max_travel
        ]
        rows = [(c.cx, c.cy, c.radius) for c in circles if c is not None]
        return np.array(rows, dtype=np.float64).reshape(-1, 3)
