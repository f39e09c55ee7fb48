"""How far the front end can have drifted over one keyframe step, from its own scan matches.

A scan-to-map front end (``lidar_odometry``, :class:`~estimators.odometry.local_map.
LocalMapOdometry`) places each scan on its local map with the information ``J^T W J`` of the
match's inlier pairs (``scan_information``: one point squarely facing a direction adds 1). A
scan it matched on hundreds of returns of walls or shelves is pinned to millimetres and
fractions of a degree; one that saw three posts is not. Its drift is what its map keyframes
inherit: each new map keyframe carries its scan's match error, ``point_sigma^2 (J^T W J)^-1``
with ``point_sigma`` the front end's point noise. Errors of keyframes matched against the same
local map are correlated (they share its walls), those of keyframes a map's length apart are not.

:class:`FrontEndDrift` sums the front end's scan information over the scans of a keyframe
step and turns it into the step's drift covariance: the mean scan's error per map keyframe the
front end laid over the step, times the keyframes one of its maps spans (the Cauchy-Schwarz bound
``Cov(sum of m) <= m sum Cov`` for errors correlated within a map, independent between maps).
The covariance is in the step's end frame (the pose graph's residual coordinates, x, y [m],
heading [rad]).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

#: Information floor [1 / m^2, 1 / rad^2 per point noise]: a scan matched to nothing still
#: leaves an invertible covariance (0.1 m, 0.1 rad per point-noise unit).
INFORMATION_FLOOR = 1e-2


class FrontEndDrift:
    """The drift covariance of a keyframe step from the front end's scan matches.

    ``frontend`` is read for ``scan_information`` after each scan (:meth:`add`) and for its
    ``noise_sigma`` [m], ``keyframe_distance`` [m], ``keyframe_angle`` [rad] and
    ``n_keyframes`` (its map's length); a front end without ``scan_information`` gives no
    measured drift (:meth:`take` returns None). ``keyframe_distance`` [m] is the pose graph's
    keyframe spacing: one front-end map spans its length over this many graph keyframes."""

    def __init__(self, frontend: Any, keyframe_distance: float) -> None:
        self._frontend, self._keyframe_distance = frontend, keyframe_distance
        self._measured = hasattr(frontend, "scan_information")
        self.clear()

    def clear(self) -> None:
        """Start a new step: forget the scans summed so far."""
        self._sum, self._scans = np.zeros((3, 3)), 0

    def add(self, heading: float) -> None:
        """Sum the front end's last scan information, its pose's heading ``heading`` [rad]
        turning it from the world frame into the car's."""
        if not self._measured:
            return
        c, s = np.cos(heading), np.sin(heading)
        to_world = np.eye(3)
        to_world[:2, :2] = [[c, -s], [s, c]]
        self._sum += to_world.T @ self._frontend.scan_information @ to_world
        self._scans += 1

    def take(self, step: NDArray[np.float64] | None) -> NDArray[np.float64] | None:
        """``(3, 3)`` drift covariance of the keyframe ``step`` (3,) that ends at the last scan
        added (None without scans or step: the first keyframe), and :meth:`clear`."""
        total, scans, frontend = self._sum, self._scans, self._frontend
        self.clear()
        if scans == 0 or step is None:
            return None
        mean = total / scans + INFORMATION_FLOOR * np.eye(3)
        map_keyframes = max(np.hypot(step[0], step[1]) / frontend.keyframe_distance,
                            abs(step[2]) / frontend.keyframe_angle, 1.0)
        span = max(frontend.n_keyframes * frontend.keyframe_distance / self._keyframe_distance,
                   1.0)
        return frontend.noise_sigma**2 * map_keyframes * span * np.linalg.inv(mean)
