"""Scoring moving-obstacle tracks against the env's ground truth ``info["moving_obstacles"]``.

:class:`MoverScore` takes, step by step, the tracks a tracker updated
(:class:`estimators.mapping.motion_tracking.MovingTrack`), the true movers (``(M, 5)`` rows x,
y, vx, vy, radius [m, m/s], world frame), the car's true position and the step's Lidar returns
in the world frame. A mover counts at a step if it is within ``near`` [m] of the car and
*visible*: at least ``min_returns`` returns lie within ``surface_tolerance`` of its circle (a
mover hidden behind a wall cannot be detected, and is not held against the tracker). Each
visible mover is matched to the nearest track updated this step within ``match_distance``.

Reported (:meth:`MoverScore.summary`):
    * ``recall``: matched / visible mover-steps;
    * ``position_error`` [m]: mean distance of matched track centres from the true centres;
    * ``velocity_error`` [m/s]: mean |track velocity - true velocity| over matches whose track
      has at least ``settled_hits`` detections (a filter needs a few steps to learn a speed);
    * ``id_switches``: times a mover's matched track id changed;
    * ``moving_precision``: of the track-steps labelled moving, the share that lie within
      ``match_distance`` of a mover (any mover: one too far or too hidden to count for recall
      is still a mover);
    * ``label_accuracy``: of the track-steps with at least ``settled_hits`` detections, the
      share whose label (moving or static) is right in that sense.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimators.mapping.motion_tracking import MovingTrack
from lidar_env.core import EstimatorInputError


@dataclass
class MoverScore:
    """Accumulates the scores of the module docstring over the steps of one or more drives."""

    near: float = 5.0
    match_distance: float = 0.3
    min_returns: int = 5
    surface_tolerance: float = 0.05
    settled_hits: int = 5
    visible: int = 0
    matched: int = 0
    id_switches: int = 0
    _position_errors: list[float] = field(default_factory=list, repr=False)
    _velocity_errors: list[float] = field(default_factory=list, repr=False)
    _labelled_moving: int = 0
    _moving_right: int = 0
    _labelled: int = 0
    _label_right: int = 0
    _last_id: dict[int, int] = field(default_factory=dict, repr=False)

    def add(
        self,
        tracks: Sequence[MovingTrack],
        movers: ArrayLike,
        car_position: ArrayLike,
        returns: ArrayLike,
    ) -> None:
        """Score one step: the ``tracks`` updated at it, the true ``movers`` (M, 5), the true
        ``car_position`` (2,) [m] and the step's world returns (n, 2) [m]."""
        truth = np.asarray(movers, dtype=np.float64).reshape(-1, 5)
        car = np.asarray(car_position, dtype=np.float64)[:2]
        points = np.asarray(returns, dtype=np.float64).reshape(-1, 2)
        if not (np.all(np.isfinite(truth)) and np.all(np.isfinite(car))):
            raise EstimatorInputError("movers, car_position: expected finite values")
        centres = np.array([t.position for t in tracks]).reshape(-1, 2)
        matched_track: dict[int, int] = {}  # track index -> mover index
        for m, (x, y, vx, vy, radius) in enumerate(truth):
            if math.hypot(x - car[0], y - car[1]) > self.near or not self._seen(points, x, y,
                                                                                   radius):
                continue
            self.visible += 1
            if not len(centres):
                continue
            distances = np.hypot(centres[:, 0] - x, centres[:, 1] - y)
            best = int(np.argmin(distances))
            if distances[best] > self.match_distance or best in matched_track:
                continue
            matched_track[best] = m
            track = tracks[best]
            self.matched += 1
            self._position_errors.append(float(distances[best]))
            if track.hits >= self.settled_hits:
                self._velocity_errors.append(float(np.hypot(*(track.velocity - (vx, vy)))))
            if m in self._last_id and self._last_id[m] != track.id:
                self.id_switches += 1
            self._last_id[m] = track.id
        for k, track in enumerate(tracks):  # a label is right if a mover is there, seen or not
            is_mover = k in matched_track or bool(len(truth)) and bool(np.min(np.hypot(
                truth[:, 0] - track.position[0], truth[:, 1] - track.position[1]))
                <= self.match_distance)
            if track.moving:
                self._labelled_moving += 1
                self._moving_right += is_mover
            if track.hits >= self.settled_hits:
                self._labelled += 1
                self._label_right += track.moving == is_mover

    def _seen(self, points: NDArray[np.float64], x: float, y: float, radius: float) -> bool:
        if not len(points):
            return False
        gap = np.abs(np.hypot(points[:, 0] - x, points[:, 1] - y) - radius)
        return int(np.count_nonzero(gap <= self.surface_tolerance)) >= self.min_returns

    def summary(self) -> dict[str, float]:
        """The scores of the module docstring (``nan`` where nothing was counted)."""
        def share(part: int, whole: int) -> float:
            return part / whole if whole else math.nan

        return {
            "visible": float(self.visible),
            "recall": share(self.matched, self.visible),
            "position_error": float(np.mean(self._position_errors)) if self._position_errors
            else math.nan,
            "velocity_error": float(np.mean(self._velocity_errors)) if self._velocity_errors
            else math.nan,
            "id_switches": float(self.id_switches),
            "moving_precision": share(self._moving_right, self._labelled_moving),
            "label_accuracy": share(self._label_right, self._labelled),
        }
