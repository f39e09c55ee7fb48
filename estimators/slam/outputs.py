"""What a :class:`~estimators.slam.graph_slam.GraphSlam` run hands out besides its trajectory:
the scan each keyframe was taken from, the front end's own poses, the corrected map, the
keyframe graph as g2o, and a picture (a mixin)."""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from estimators.slam.figure import save_slam_figure
from estimators.slam.g2o import write_g2o
from estimators.slam.pose_graph import PoseGraph
from lidar_env.core.se2 import transform_points


class SlamOutputs:
    """The outputs of a SLAM run; reads ``graph``, ``keyframes`` (each with ``points``, car
    frame) and ``_dirty``, and calls ``optimize`` first when the graph changed since."""

    graph: PoseGraph
    keyframes: list[Any]
    _dirty: bool
    _scan_keyframe: list[int]
    _scan_odometry: list[NDArray[np.float64]]
    optimize: Callable[[], None]

    @property
    def keyframe_scans(self) -> NDArray[np.int64]:
        """``(K,)`` index of the observation each keyframe was taken from."""
        # every keyframe is taken from a scan, the first that hangs from it
        return np.searchsorted(self._scan_keyframe, np.arange(len(self.keyframes))).astype(
            np.int64)

    @property
    def odometry_trajectory(self) -> NDArray[np.float64]:
        """``(N, 3)`` the front end's own poses, without loop closure."""
        return np.array(self._scan_odometry).reshape(-1, 3)

    def corrected_map(self) -> NDArray[np.float64]:
        """``(M, 2)`` every keyframe's points in the world frame at its optimised pose [m]."""
        if self._dirty:
            self.optimize()
        return np.concatenate([transform_points(pose, k.points)
                               for pose, k in zip(self.graph.poses, self.keyframes, strict=True)])

    def save_g2o(self, path: str | os.PathLike[str]) -> None:
        """Write the keyframe graph (optimised poses, odometry and loop edges) as g2o."""
        if self._dirty:
            self.optimize()
        write_g2o(self.graph, path)

    def render(self, path: str | os.PathLike[str], truth: NDArray[np.float64] | None = None,
               ) -> None:
        """Save a picture of the corrected map (grey points), the front end's path (dotted),
        the smoothed path, odometry edges and loop edges (red), and ``truth`` (N, 3) poses
        if given. Needs matplotlib (``pip install duallidar[plots]``)."""
        save_slam_figure(self, path, truth)
