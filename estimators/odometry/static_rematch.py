"""``lidar_odometry``'s scan matched again without its points on moving things: judged at the
matched pose (:meth:`~estimators.odometry.moving_rejection.MovingPointRejection.
_static_points`), then registered anew, twice (why: the module docstring of
:mod:`estimators.odometry.local_map`). Each registration starts its pair searches from the
nearest map points the last one found for the same points
(:meth:`~estimators.matching.point_to_line.PointToLineReference.neighbours_for`), which
answer most of them with no search: the same pairs, bit for bit. Points (n, 2), car frame [m].
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from estimators.matching.icp import ICPParams, register
from estimators.matching.match_result import MatchResult
from estimators.matching.point_to_line import PointToLineReference
from estimators.odometry.moving_points import MovingPointFilter
from estimators.odometry.moving_rejection import MIN_MOVING_POINTS

FloatArray = NDArray[np.float64]
Scans = dict[str, FloatArray]


class StaticRematch:
    """The rematch of :class:`~estimators.odometry.local_map.LocalMapOdometry`, a mixin: it
    reads the front end's ``params``, ``match_information`` (the prior the scan's match was
    held by), ``_reference``, ``_moving`` and ``_moving_mask`` (the filter's last verdict on
    the scan) and calls ``_static_points``."""

    params: ICPParams
    match_information: FloatArray
    _reference: PointToLineReference | None
    _moving: MovingPointFilter | None
    _moving_mask: NDArray[np.bool_]
    _static_points: Callable[[FloatArray, FloatArray, Scans], FloatArray]

    def _matched_without_moving(self, result: MatchResult, seen: FloatArray, guess: FloatArray,
                                scans: Scans) -> tuple[MatchResult, FloatArray]:
        """``result``, the match of the scan's points ``seen`` near ``guess`` (3,), matched
        again without those on moving things while at least :data:`MIN_MOVING_POINTS` of
        them are (at most twice), and the points it is the match of."""
        points, reference = seen, self._reference
        if self._moving is None:
            return result, points
        assert reference is not None
        kept, near = reference.neighbours_for(seen)  # as the match of seen left them
        for _ in range(2):
            static = self._static_points(seen, result.pose, scans)
            if len(points) - len(static) < MIN_MOVING_POINTS or self._reference is None:
                break
            if self._reference is not reference:  # the map lost stale points: new neighbours
                reference = self._reference
                kept, near = reference.neighbours_for(seen)
            rows = np.flatnonzero(~self._moving_mask) if len(static) < len(seen) else (
                np.arange(len(seen)))
            neighbours = kept[rows], near[rows]
            points = static
            result = register(reference, points, result.pose, self.params, guess,
                              self.match_information, neighbours=neighbours)
            kept[rows], near[rows] = neighbours
        return result, points
