"""``lidar_odometry``'s points on moving things left out: its
:class:`~estimators.odometry.moving_points.MovingPointFilter`, its settings
(``dynamic_margin``, ``moving_filter``) and what the filter's verdicts do to the scan and to
the local map.

Why the points are judged at the matched pose and matched again without them: the module
docstring of :mod:`estimators.odometry.local_map`; the measurements behind it are in the
documentation's design page. Distances [m]; points (n, 2).
"""

from __future__ import annotations

import inspect
import numbers
from collections import deque
from collections.abc import Callable, Mapping

import numpy as np
from numpy.typing import NDArray

from estimators.base import SensorSetup
from estimators.odometry.motion_prior import ScanClock
from estimators.odometry.moving_points import MovingPointFilter, split_like
from lidar_env.core import ConfigError
from lidar_env.core.se2 import transform_points

FloatArray = NDArray[np.float64]
Scans = dict[str, FloatArray]

#: Fewer points judged moving (or stale) change nothing: the robust loss bounds what 1-2 pull.
MIN_MOVING_POINTS = 3
#: The filter's parameters lidar_odometry's own settings give it (besides the sensor setup).
OWN_PARAMETERS = {"margin": "dynamic_margin", "min_range": "min_range"}
#: What ``moving_filter`` may set: the rest of :class:`MovingPointFilter`'s parameters.
MOVING_FILTER_KEYS = tuple(sorted(set(inspect.signature(MovingPointFilter).parameters)
                                  - {"setup", *OWN_PARAMETERS}))
#: Of those, the scan counts (integers).
_COUNTS = ("history", "max_anchor_scans")


class MovingPointRejection:
    """Moving points of :class:`~estimators.odometry.local_map.LocalMapOdometry`, a mixin: it
    reads the front end's settings (``reject_dynamic``, ``dynamic_margin``, ``moving_filter``,
    ``min_range``, ``n_keyframes``) and state (``setup``, ``_keyframes``, ``_clock``),
    rebuilds the map (``_build_reference``) when it loses stale points, and keeps the filter
    (``_moving``: None when off, or on a world-aligned setup)."""

    reject_dynamic: bool
    dynamic_margin: float
    moving_filter: Mapping[str, float] | None
    min_range: float
    n_keyframes: int
    setup: SensorSetup | None
    _keyframes: deque[tuple[FloatArray, FloatArray]]
    _clock: ScanClock
    _build_reference: Callable[[], None]

    def _check_moving_filter(self) -> None:
        """``moving_filter`` checked at construction rather than at the first reset (called by
        ``__post_init__``, after ``dynamic_margin`` and ``min_range``): known keys, numbers
        (integers for the scan counts), then the filter's own checks."""
        settings = {} if self.moving_filter is None else self.moving_filter
        if not isinstance(settings, Mapping):
            raise ConfigError(f"moving_filter: expected a mapping of "
                              f"{', '.join(MOVING_FILTER_KEYS)} to numbers, or None, "
                              f"got {settings!r}")
        for key, value in settings.items():
            if key in OWN_PARAMETERS:
                raise ConfigError(f"moving_filter: {key!r} is set by lidar_odometry's "
                                  f"{OWN_PARAMETERS[key]}, not here")
            if key not in MOVING_FILTER_KEYS:
                raise ConfigError(f"moving_filter: unknown key {key!r}: expected one of "
                                  f"{', '.join(MOVING_FILTER_KEYS)}")
            count = key in _COUNTS
            if isinstance(value, bool) or not isinstance(
                    value, numbers.Integral if count else numbers.Real):
                raise ConfigError(f"moving_filter: {key}: expected "
                                  f"{'an integer' if count else 'a number'}, got {value!r}")
        self._moving_settings = dict(settings)  # as checked, whatever becomes of the mapping
        if settings:  # the filter's own checks, on a three-beam setup
            try:
                self._new_moving_filter(SensorSetup([[0.0, 0.0, 0.0]], [0.0, 2.0, 4.0], 1.0))
            except ConfigError as error:
                raise ConfigError(f"moving_filter: {error}") from error

    def _new_moving_filter(self, setup: SensorSetup) -> MovingPointFilter:
        """A filter for ``setup`` with the estimator's margin, min_range and settings."""
        return MovingPointFilter(setup, self.dynamic_margin, min_range=self.min_range,
                                 **self._moving_settings)

    def _reset_moving_filter(self) -> None:
        """A new filter, or None (called by ``_reset_state``)."""
        assert self.setup is not None
        dynamic = self.reject_dynamic and not self.setup.world_aligned
        self._moving = self._new_moving_filter(self.setup) if dynamic else None
        self._moving_mask = np.zeros(0, dtype=np.bool_)  # the last verdict on the scan

    def _static_points(self, points: FloatArray, guess: FloatArray, scans: Scans) -> FloatArray:
        """``points`` less those on moving things; the map loses its stale points."""
        assert self._moving is not None
        maps = [world for _, world in self._keyframes]
        moving, stale = self._moving.classify_stacked(points, guess, scans, maps)
        if np.count_nonzero(stale) >= MIN_MOVING_POINTS:
            self._keyframes = deque([(key_pose, world[kept]) for (key_pose, world), kept
                                     in zip(self._keyframes, split_like(~stale, maps),
                                            strict=True)],
                                    maxlen=self.n_keyframes)
            self._build_reference()
        self._moving_mask = moving
        static = ~moving
        return points[static] if np.count_nonzero(static) >= 3 else points

    def _map_points(self, pose: FloatArray, seen: FloatArray,
                    registered: FloatArray) -> FloatArray:
        """What a keyframe at ``pose`` keeps of the scan's points ``seen`` (car frame), of
        which ``registered`` matched: those the filter's last verdict on them leaves fit for
        the map (:meth:`MovingPointFilter.mappable`), if three are; without the filter,
        ``registered``."""
        if self._moving is None or len(self._moving_mask) != len(seen):
            return registered
        world = np.ascontiguousarray(transform_points(pose, seen), dtype=np.float64)
        keep = self._moving.mappable(world, self._moving_mask,
                                     [known for _, known in self._keyframes])
        return seen[keep] if np.count_nonzero(keep) >= 3 else registered

    def _remember(self, pose: FloatArray, scans: Scans, points: FloatArray,
                  jump: float = 0.0) -> None:
        """Give the filter the scans and all their ``points`` (car frame), moving or not, at
        ``pose``, which landed ``jump`` from the motion model's guess."""
        if self._moving is not None:
            self._moving.remember(pose, scans, points,
                                  self._clock.median if self._clock.settled else None, jump)
