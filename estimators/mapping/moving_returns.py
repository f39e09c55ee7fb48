"""Which returns of a run lie on moving things, told by the motion tracker, so that maps can
leave them out.

A pedestrian's returns are real surfaces where it stands, and an occupancy grid that takes
them as obstacles keeps the cells of every place it was seen until beams pass through them
again: behind a walker coming at the car, its own body hides the cells it left, and the trail
stays. The same returns, seen round, make the cylinder map take a walker for a post.
:class:`MovingReturns` runs a :class:`~estimators.mapping.motion_tracking.MotionTracker` over
the scans, step by step, and reports per step the detections on a track labelled moving (or,
not seen round this time, lying on one's circle) and, per Lidar, the beams that produced them.
A map then lets those beams clear the space before their return without marking the return
occupied (:meth:`~estimators.mapping.occupancy.OccupancyGrid.integrate`, ``moving=``), and the
cylinder tracker skips those detections. Nothing is read from the env's truth: the label comes
from the scans and the poses alone. A walker's first detections, before its track can be
labelled (``min_hits``, and a velocity known to 0.15 m/s), still reach the map; later beams
through those cells clear them where any pass.

Units: metres, seconds; detections in the world frame of the poses given (an estimator's).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimators.base import SensorSetup
from estimators.mapping.motion_tracking import MotionTracker, MovingTrack
from estimators.mapping.obstacles import DetectorParams, Obstacle, detect_per_lidar
from lidar_env.core import EstimatorInputError

#: [m] how far outside a moving track's circle the points of an untracked detection may lie
#: and still be on the mover (its arc's range noise and the track's position error).
MOVER_MARGIN = 0.1


@dataclass(frozen=True)
class MovingStep:
    """One step's detections and which of them are on moving tracks.

    Attributes:
        obstacles: every detection of the step, Lidar by Lidar in ``setup.keys`` order.
        moving: ``(len(obstacles),)`` True for a detection on a track labelled moving.
        beams: per Lidar key, ``(n_beams,)`` True for each beam whose return is on one.
    """

    obstacles: list[Obstacle]
    moving: NDArray[np.bool_]
    beams: dict[str, NDArray[np.bool_]]

    @property
    def static_obstacles(self) -> list[Obstacle]:
        """The detections not on a moving track."""
        return [o for o, m in zip(self.obstacles, self.moving, strict=True) if not m]


class MovingReturns:
    """Tracks a run's round obstacles step by step and labels their returns (module doc)."""

    def __init__(self, setup: SensorSetup, tracker: MotionTracker | None = None,
                 params: DetectorParams | None = None) -> None:
        self.setup = setup
        self.tracker = MotionTracker() if tracker is None else tracker
        self.params = params

    def update(self, observation: Mapping[str, ArrayLike], car_pose: ArrayLike,
               t: float) -> MovingStep:
        """Detect the obstacles of one observation (scans keyed by ``setup.keys``) taken at the
        (estimated) car pose ``car_pose`` (3,) at time ``t`` [s], track them, and label them."""
        per_lidar = detect_per_lidar(observation, car_pose, self.setup, self.params)
        obstacles = [obstacle for found in per_lidar.values() for obstacle in found]
        owners = [key for key, found in per_lidar.items() for _ in found]
        ids = self.tracker.update(obstacles, t)
        movers = self.tracker.moving_tracks()
        moving_ids = {track.id for track in movers}
        moving = np.array([i in moving_ids or (i is None and _on_a_mover(o, movers))
                           for i, o in zip(ids, obstacles, strict=True)], dtype=np.bool_)
        beams = {key: np.zeros(len(sensor.beam_angles), dtype=np.bool_)
                 for key, sensor in zip(self.setup.keys, self.setup.sensors, strict=True)}
        for obstacle, key, on_mover in zip(obstacles, owners, moving, strict=True):
            if on_mover:
                beams[key][obstacle.beams] = True
        return MovingStep(obstacles, moving, beams)


def _on_a_mover(obstacle: Obstacle, movers: list[MovingTrack]) -> bool:
    """Whether an untracked detection (a mover's arc not seen round this time) lies within
    :data:`MOVER_MARGIN` of a moving track's circle, all of it."""
    for track in movers:
        reach = track.radius + MOVER_MARGIN
        gap = obstacle.centroid - track.state[:2]
        if gap @ gap <= reach * reach and np.all(
                np.hypot(*(obstacle.points - track.state[:2]).T) <= reach):
            return True
    return False


def label_run(trajectory: ArrayLike, observations: Sequence[Mapping[str, ArrayLike]],
              setup: SensorSetup, times: ArrayLike,
              params: DetectorParams | None = None) -> list[MovingStep]:
    """:meth:`MovingReturns.update` over a whole run: ``observations[k]`` at car pose
    ``trajectory[k]`` (N, 3) and time ``times[k]`` [s], strictly increasing."""
    trajectory = np.asarray(trajectory, dtype=np.float64).reshape(-1, 3)
    times = np.asarray(times, dtype=np.float64).reshape(-1)
    if not len(trajectory) == len(observations) == len(times):
        raise EstimatorInputError(
            f"trajectory, observations, times: expected one of each per step, got "
            f"{len(trajectory)}, {len(observations)}, {len(times)}")
    labeller = MovingReturns(setup, params=params)
    return [labeller.update(observation, pose, float(t))
            for observation, pose, t in zip(observations, trajectory, times, strict=True)]
