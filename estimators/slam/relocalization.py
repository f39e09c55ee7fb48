"""Finding the place again after the front end lost it: the relocalization of
:class:`~estimators.slam.graph_slam.GraphSlam`.

After a long blind stretch the ``lidar_odometry`` front end may find no placement on its local
map that explains its scan (the car turned towards what its map never saw): it keeps the
motion model's pose and counts the scan in ``Health.lost`` (:mod:`estimators.odometry.
blind_resume`). From there on the front end's poses are where the car can be, not where it
is, relative to everything before. So the odometry edge across the lost scan gets the
information of a place unknown within ``lost_sigma`` [m] and of any heading (and the loop gate
models the front end's error over it the same way), and each new keyframe is searched in the
whole map the graph held before the loss, over all headings: the place-descriptor ranking and
branch-and-bound keyframe match of the global loop closure
(:meth:`~estimators.slam.keyframe_matching.KeyframeMatching._match_globally`), its query built
from the keyframes since the loss only, its old places from keyframes before it only. A match
re-anchors the keyframes since the loss only once a second one, of another query, implies
the same correction (the weak edge then takes the correction); one alone closes nothing.
Until then no other loop is closed: the graph does not know where the old map lies relative
to the new keyframes.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from estimators.health import Health

#: The loop gate's model of an odometry edge's error: noise and drift covariances (3, 3).
Covariances = tuple[NDArray[np.float64], NDArray[np.float64]]


class Relocalization:
    """The relocalization state of :class:`~estimators.slam.graph_slam.GraphSlam`, a mixin.
    It reads the graph slam's ``lost_sigma`` and ``global_submap_keyframes``, its front end's
    and its own ``health``, and calls ``_match_globally``."""

    lost_sigma: float
    global_submap_keyframes: int
    health: Health
    _frontend: object
    _match_globally: Callable[[int, NDArray[np.int64], int, int | None], bool]
    _lost_pending: bool  # the front end lost its place since the last keyframe
    lost_from: int | None  # the first keyframe after the loss while the place is not found

    def _reset_relocalization(self) -> None:
        self._lost_pending, self.lost_from = False, None

    def _lost_scans(self) -> int:
        """Scans the front end has lost its place at so far."""
        health = getattr(self._frontend, "health", None)
        return 0 if health is None else health.lost_scans

    def _note_lost_since(self, lost: int, index: int) -> None:
        """Count observation ``index`` lost where the front end lost its place at it (it had
        lost it at ``lost`` scans before)."""
        if self._lost_scans() > lost:
            self.health.note_lost(index)
            self._lost_pending = True

    def _unless_lost(self, index: int, information: NDArray[np.float64],
                     error: Covariances
                     ) -> tuple[NDArray[np.float64], Covariances]:
        """The odometry edge into keyframe ``index``: its ``information`` (3, 3) and the loop
        gate's ``error`` model (noise and drift covariances), or, where the front end lost its
        place over the step, those of a place unknown within ``lost_sigma`` and any heading
        (and the keyframe starts the search for the place)."""
        if not self._lost_pending:
            return information, error
        self._lost_pending, self.lost_from = False, index
        unknown = np.diag([self.lost_sigma**2, self.lost_sigma**2, np.pi**2])
        return np.linalg.inv(unknown), (error[0], unknown)

    def _relocalize(self, index: int) -> None:
        """Search keyframe ``index`` and those since the loss in the map before it; the
        search ends once a confirmed match re-anchored them."""
        assert self.lost_from is not None
        query = min(self.global_submap_keyframes, index - self.lost_from)
        last = self.lost_from - 1
        if self._match_globally(index, np.arange(last + 1), query, last):
            self.lost_from = None
