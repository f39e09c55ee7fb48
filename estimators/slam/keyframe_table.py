"""What :class:`~estimators.slam.graph_slam.GraphSlam` keeps of each keyframe for matching:
its points, descriptor and front-end pose (:class:`Keyframe`), the arrays the loop search
reads over all keyframes (:class:`KeyframeTable`), and how far a keyframe's points move
between two placements (:func:`largest_shift`). Distances [m], angles [rad].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from estimators.slam.growing_rows import GrowingRows


@dataclass
class Keyframe:
    """A graph node's data: its car-frame points (M, 2), place descriptor, the front end's
    pose when it was taken, and the path length [m] driven up to it."""

    points: NDArray[np.float64]
    descriptor: NDArray[np.float64]
    odometry: NDArray[np.float64]
    path_length: float


class KeyframeTable:
    """What the loop search reads of every keyframe, as arrays that grow one row at a time
    (:class:`~estimators.slam.growing_rows.GrowingRows`: read once per keyframe, over all of
    them, they would otherwise be rebuilt from the keyframes each time): path lengths (K,) [m],
    place descriptors (K, B), the front end's error model of the odometry edge into each
    keyframe as two covariances (K, 3, 3) (keyframe 0: zeros): its noise, independent from
    edge to edge, and its drift, which may err the same way all along a stretch, and the
    reach (K,) [m] of each keyframe's points (the farthest one's distance from its
    origin)."""

    def __init__(self) -> None:
        self._path = GrowingRows()
        self._descriptors = GrowingRows(None)
        self._noise = GrowingRows((3, 3))
        self._drift = GrowingRows((3, 3))
        self._reach = GrowingRows()

    def append(self, keyframe: Keyframe, noise: NDArray[np.float64],
               drift: NDArray[np.float64]) -> None:
        """Add the next keyframe's row and its odometry edge's noise and drift covariances
        (3, 3) each."""
        self._path.append(keyframe.path_length)
        self._descriptors.append(keyframe.descriptor)
        self._noise.append(noise)
        self._drift.append(drift)
        points = keyframe.points
        self._reach.append(np.hypot(points[:, 0], points[:, 1]).max() if len(points) else 0.0)

    @property
    def path_lengths(self) -> NDArray[np.float64]:
        """``(K,)`` path length [m] driven up to each keyframe (a view)."""
        return self._path.rows

    @property
    def descriptors(self) -> NDArray[np.float64]:
        """``(K, B)`` place descriptors (a view)."""
        return self._descriptors.rows

    @property
    def noise_covariances(self) -> NDArray[np.float64]:
        """``(K, 3, 3)`` noise covariance of the odometry edge into each keyframe (a view)."""
        return self._noise.rows

    @property
    def drift_covariances(self) -> NDArray[np.float64]:
        """``(K, 3, 3)`` drift covariance of the odometry edge into each keyframe (a view)."""
        return self._drift.rows

    @property
    def reach(self) -> NDArray[np.float64]:
        """``(K,)`` distance [m] of each keyframe's farthest point from its origin (a view)."""
        return self._reach.rows


def largest_shift(before: NDArray[np.float64], after: NDArray[np.float64],
                  reach: NDArray[np.float64]) -> float:
    """The most [m] a point moves between two placements of the same keyframes (poses (n, 3)
    ``before`` and ``after``, each keyframe's points within ``reach`` (n,) [m] of its origin):
    ``|dt| + 2 |sin(dtheta / 2)| reach``, the bound for a point at that distance turned by
    ``dtheta`` and moved by ``dt``."""
    turn = np.abs(np.sin(0.5 * (after[:, 2] - before[:, 2])))
    shift = np.hypot(after[:, 0] - before[:, 0], after[:, 1] - before[:, 1])
    return float(np.max(shift + 2.0 * turn * reach)) if len(reach) else 0.0
