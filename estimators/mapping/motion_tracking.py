"""Tracking round obstacles that may move (:class:`MotionTracker`): one constant-velocity
Kalman filter per track, each with a velocity and a static/moving label.

Pedestrians, posts and pillars show a planar Lidar the same thing: an arc of returns that a
circle explains (:mod:`estimators.mapping.obstacles`). The tracker follows the centres of those
round detections in the world frame: detections of one step lying within ``merge_distance`` of
each other are one obstacle (seen by two Lidars, or split by a beam gap) and give one
measurement, the circle fitted to their joint returns; measurements are associated with the
tracks' predicted positions by global nearest neighbour within ``gate``; each track is a
Kalman filter on (x, y, vx, vy) with white-noise acceleration (Bar-Shalom, Li & Kirubarajan,
"Estimation with Applications to Tracking and Navigation", 2001, sec. 6.3.2). A track is
*moving* once it has ``min_hits`` detections and its speed exceeds ``moving_speed``, and static
again only below half of it (hysteresis, so noise at the threshold does not flip the label);
while its velocity is uncertain by more than half of ``moving_speed`` (1 sigma: a new track,
or one just after a maneuver) the label stays as it was. A measurement far from the
prediction (``maneuver_gate``) is taken as a maneuver, the velocity covariance reset.
Extended clusters (walls, boxes) are not tracked here: their centroid slides as the car
passes, so they would look like movers; :class:`estimators.mapping.tracking.ObstacleTracker`
maps them as static obstacles.

Units: metres, seconds, radians; everything in the world frame of the poses the detections
were made at (an estimator's, so pose drift shows as a slow apparent motion of static things,
far below ``moving_speed`` for a usable estimate).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from estimators.mapping.circle_fit import fit_circle
from estimators.mapping.obstacles import Obstacle
from lidar_env.core import ConfigError, EstimatorInputError


@dataclass
class MovingTrack:
    """One round obstacle followed across steps.

    Attributes:
        id: stable identifier, unique within its tracker.
        state: ``(4,)`` x [m], y [m], vx [m/s], vy [m/s], world frame.
        covariance: ``(4, 4)`` of ``state``.
        radius: [m] the latest measured radius.
        hits: detections joined so far.
        first_time, last_time: [s] times of the first and the latest detection.
        time: [s] the time ``state`` is predicted to (the tracker's latest update).
        moving: the static/moving label (see the module docstring).
    """

    id: int
    state: NDArray[np.float64]
    covariance: NDArray[np.float64]
    radius: float
    hits: int
    first_time: float
    last_time: float
    time: float
    moving: bool = False

    @property
    def position(self) -> NDArray[np.float64]:
        """``(2,)`` [m] the filtered centre."""
        return self.state[:2].copy()

    @property
    def velocity(self) -> NDArray[np.float64]:
        """``(2,)`` [m/s] the filtered velocity."""
        return self.state[2:].copy()

    @property
    def speed(self) -> float:
        """[m/s] the filtered speed."""
        return float(math.hypot(self.state[2], self.state[3]))


@dataclass
class MotionTracker:
    """Follows round obstacles (static or moving) with one Kalman filter each.

    Args:
        gate: [m] largest distance from a track's predicted centre to a measurement it takes
            (0.6: a pedestrian at 1.5 m/s moves 0.15 m per 10 Hz scan, and a new track's speed
            is unknown for its first steps).
        merge_distance: [m] detections of one step closer than this are one obstacle (0.3:
            under the spacing of two people passing each other, above the centre scatter of
            one seen by two Lidars).
        measurement_sigma: [m] 1-sigma error of a detected centre (0.03: the circle fit of a
            short arc with 1 cm range noise).
        acceleration_sigma: [m/s^2] 1-sigma white-noise acceleration (1.0: walking people
            turn and change pace).
        initial_speed_sigma: [m/s] prior 1-sigma of a new track's velocity (1.5: walking pace).
        maneuver_gate: a measurement farther than this many sigmas (Mahalanobis distance of
            the innovation) from a track's prediction is a maneuver, an abrupt turn or stop:
            the track's velocity covariance is reset to ``initial_speed_sigma`` before the
            update, so the velocity follows at once instead of over many steps (Bar-Shalom
            et al., sec. 11.2, covariance resetting). ``inf`` turns it off.
        moving_speed: [m/s] speed above which a track is moving (0.3: slow walking is 0.5-1).
        min_hits: detections before a track can be labelled moving.
        max_age: [s] a track not detected for longer is dropped (1.0: bridges short
            occlusions by the prediction alone).
    """

    gate: float = 0.6
    merge_distance: float = 0.3
    measurement_sigma: float = 0.03
    acceleration_sigma: float = 1.0
    initial_speed_sigma: float = 1.5
    maneuver_gate: float = 4.0
    moving_speed: float = 0.3
    min_hits: int = 3
    max_age: float = 1.0
    tracks: list[MovingTrack] = field(default_factory=list)
    _next_id: int = field(default=0, repr=False)
    _time: float | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        for name in ("gate", "merge_distance", "measurement_sigma", "acceleration_sigma",
                     "initial_speed_sigma", "moving_speed", "max_age", "maneuver_gate"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and value > 0  # NaN fails it too
                    and (math.isfinite(value) or name == "maneuver_gate")):
                raise ConfigError(f"{name}: expected a positive number, got {value!r}")
        if not isinstance(self.min_hits, int) or self.min_hits < 1:
            raise ConfigError(f"min_hits: expected an integer >= 1, got {self.min_hits!r}")

    def update(self, obstacles: list[Obstacle], t: float) -> list[int | None]:
        """Take one step's detections (from any number of Lidars) made at time ``t`` [s];
        return each detection's track id (``None`` for an extended, untracked one)."""
        t = float(t)
        if not math.isfinite(t) or (self._time is not None and t <= self._time):
            raise EstimatorInputError(f"t: expected a finite time after {self._time}, got {t!r}")
        self._time = t
        self.tracks = [tr for tr in self.tracks if t - tr.last_time <= self.max_age]
        for track in self.tracks:  # an undetected track coasts on its prediction
            _predict(track, t - track.time, self.acceleration_sigma)
            track.time = t
        groups = self._merge([i for i, o in enumerate(obstacles) if o.circle is not None],
                             obstacles)
        ids: list[int | None] = [None] * len(obstacles)
        measured = [_measurement(obstacles, group) for group in groups]
        for g, track in self._associate([m[0] for m in measured]).items():
            centre, radius = measured[g]
            if track is None:
                track = self._new_track(centre, radius, t)
            else:
                _correct(track, centre, self.measurement_sigma, self.maneuver_gate,
                         self.initial_speed_sigma)
                track.radius, track.hits, track.last_time = radius, track.hits + 1, t
            self._label(track)
            for i in groups[g]:
                ids[i] = track.id
        return ids

    def moving_tracks(self) -> list[MovingTrack]:
        """The tracks labelled moving."""
        return [track for track in self.tracks if track.moving]

    def detected_tracks(self) -> list[MovingTrack]:
        """The tracks detected at the latest update."""
        return [track for track in self.tracks if track.last_time == self._time]

    def _merge(self, round_ids: list[int], obstacles: list[Obstacle]) -> list[list[int]]:
        """Round detections grouped by single linkage within ``merge_distance``."""
        groups: list[list[int]] = []
        for i in round_ids:
            position = obstacles[i].position
            joined = [g for g in groups if any(
                np.hypot(*(obstacles[j].position - position)) <= self.merge_distance for j in g)]
            merged = [i] + [j for g in joined for j in g]
            groups = [g for g in groups if g not in joined] + [sorted(merged)]
        return groups

    def _associate(self, centres: list[NDArray[np.float64]]) -> dict[int, MovingTrack | None]:
        """Measurement index -> its track (``None``: a new one), greedy nearest first."""
        pairs = sorted(
            (float(np.hypot(*(centre - track.state[:2]))), g, k)
            for g, centre in enumerate(centres) for k, track in enumerate(self.tracks))
        taken_g: set[int] = set()
        taken_k: set[int] = set()
        result: dict[int, MovingTrack | None] = {}
        for distance, g, k in pairs:
            if distance > self.gate:
                break
            if g not in taken_g and k not in taken_k:
                taken_g.add(g)
                taken_k.add(k)
                result[g] = self.tracks[k]
        for g in range(len(centres)):
            result.setdefault(g, None)
        return dict(sorted(result.items()))

    def _new_track(self, centre: NDArray[np.float64], radius: float, t: float) -> MovingTrack:
        covariance = np.diag([self.measurement_sigma, self.measurement_sigma,
                              self.initial_speed_sigma, self.initial_speed_sigma]) ** 2
        track = MovingTrack(self._next_id, np.array([*centre, 0.0, 0.0]), covariance, radius,
                            1, t, t, t)
        self._next_id += 1
        self.tracks.append(track)
        return track

    def _label(self, track: MovingTrack) -> None:
        if track.hits < self.min_hits:
            track.moving = False
        elif max(track.covariance[2, 2], track.covariance[3, 3]) > (0.5 * self.moving_speed) ** 2:
            pass  # the velocity is too uncertain (just after a maneuver) to change the label
        elif track.moving:
            track.moving = track.speed > 0.5 * self.moving_speed
        else:
            track.moving = track.speed > self.moving_speed


def _measurement(obstacles: list[Obstacle], group: list[int]) -> tuple[NDArray[np.float64], float]:
    """Centre (2,) [m] and radius [m] of one obstacle seen as the detections ``group``."""
    if len(group) > 1:
        circle = fit_circle(np.vstack([obstacles[i].points for i in group]))
        if circle is not None:
            return np.array(circle.centre, dtype=np.float64), float(circle.radius)
    circles = [obstacles[i].circle for i in group]
    centre = np.mean([c.centre for c in circles if c is not None], axis=0)
    return centre, float(np.mean([c.radius for c in circles if c is not None]))


def _predict(track: MovingTrack, dt: float, acceleration_sigma: float) -> None:
    """Constant-velocity prediction by ``dt`` [s] with white-noise acceleration."""
    transition = np.eye(4)
    transition[0, 2] = transition[1, 3] = dt
    q = acceleration_sigma ** 2
    block = np.array([[dt ** 4 / 4, dt ** 3 / 2], [dt ** 3 / 2, dt ** 2]]) * q
    noise = np.zeros((4, 4))
    noise[np.ix_([0, 2], [0, 2])] = block
    noise[np.ix_([1, 3], [1, 3])] = block
    track.state = transition @ track.state
    track.covariance = transition @ track.covariance @ transition.T + noise


def _correct(track: MovingTrack, centre: NDArray[np.float64], sigma: float,
             maneuver_gate: float, speed_sigma: float) -> None:
    """Kalman update with a measured centre (2,) [m] of 1-sigma ``sigma`` [m]; an innovation
    beyond ``maneuver_gate`` sigmas first resets the velocity covariance to ``speed_sigma``
    [m/s] (see :class:`MotionTracker`)."""
    innovation = centre - track.state[:2]
    gain_denominator = track.covariance[:2, :2] + np.eye(2) * sigma ** 2
    if innovation @ np.linalg.solve(gain_denominator, innovation) > maneuver_gate ** 2:
        # As if the velocity had been unknown (1-sigma speed_sigma) since the last detection,
        # dt ago: the position inherits dt times that uncertainty, and the two correlate.
        dt, q = track.time - track.last_time, speed_sigma ** 2
        covariance = track.covariance
        covariance[:2, :2] += np.eye(2) * dt * dt * q
        covariance[:2, 2:] = covariance[2:, :2] = np.eye(2) * dt * q
        covariance[2:, 2:] = np.eye(2) * q
        gain_denominator = covariance[:2, :2] + np.eye(2) * sigma ** 2
    gain = track.covariance[:, :2] @ np.linalg.inv(gain_denominator)
    track.state = track.state + gain @ innovation
    track.covariance = (np.eye(4) - gain @ np.eye(2, 4)) @ track.covariance
