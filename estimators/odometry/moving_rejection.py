"""``lidar_odometry``'s points on moving things left out: its
:class:`~estimators.odometry.moving_points.MovingPointFilter` and what the filter's verdicts do
to the scan and to the local map.

Why the points are judged at the matched pose and matched again without them, with the
measurements: the module docstring of :mod:`estimators.odometry.local_map` and the README's
"Moving obstacles: odometry, maps and tracking". Distances [m]; points (n, 2).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from estimators.base import SensorSetup
from estimators.odometry.motion_prior import ScanClock
from estimators.odometry.moving_points import MovingPointFilter

FloatArray = NDArray[np.float64]
Scans = dict[str, FloatArray]

#: Fewer points judged moving (or stale) change nothing: the robust loss bounds what 1-2 pull.
MIN_MOVING_POINTS = 3


class MovingPointRejection:
    """Moving points of :class:`~estimators.odometry.local_map.LocalMapOdometry`, a mixin: it
    reads the front end's settings (``reject_dynamic``, ``dynamic_margin``, ``min_range``,
    ``n_keyframes``) and state (``setup``, ``_keyframes``, ``_clock``), rebuilds the map
    (``_build_reference``) when it loses stale points, and keeps the filter (``_moving``:
    None when off, or on a world-aligned setup)."""

    reject_dynamic: bool
    dynamic_margin: float
    min_range: float
    n_keyframes: int
    setup: SensorSetup | None
    _keyframes: deque[tuple[FloatArray, FloatArray]]
    _clock: ScanClock
    _build_reference: Callable[[], None]

    def _reset_moving_filter(self) -> None:
        """A new filter, or None (called by ``_reset_state``)."""
        assert self.setup is not None
        dynamic = self.reject_dynamic and not self.setup.world_aligned
        self._moving = (MovingPointFilter(self.setup, self.dynamic_margin, min_range=self.min_range)
                        if dynamic else None)

    def _static_points(self, points: FloatArray, guess: FloatArray, scans: Scans) -> FloatArray:
        """``points`` less those on moving things; the map loses its stale points."""
        assert self._moving is not None
        moving, stale = self._moving.classify(points, guess, scans,
                                              [world for _, world in self._keyframes])
        if sum(np.count_nonzero(mask) for mask in stale) >= MIN_MOVING_POINTS:
            self._keyframes = deque([(key_pose, world[~mask]) for (key_pose, world), mask
                                     in zip(self._keyframes, stale, strict=True)],
                                    maxlen=self.n_keyframes)
            self._build_reference()
        return points[~moving] if np.count_nonzero(~moving) >= 3 else points

    def _remember(self, pose: FloatArray, scans: Scans, points: FloatArray,
                  jump: float = 0.0) -> None:
        """Give the filter the scans and all their ``points`` (car frame), moving or not, at
        ``pose``, which landed ``jump`` from the motion model's guess."""
        if self._moving is not None:
            self._moving.remember(pose, scans, points,
                                  self._clock.median if self._clock.settled else None, jump)
