"""Scans placed on optimised keyframes: :func:`blend_on_keyframes`, how
:class:`~estimators.slam.graph_slam.GraphSlam` turns its keyframe graph into one smoothed pose
per scan.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from lidar_env.core.se2 import compose, relative, wrap_angle


def blend_on_keyframes(
    keyframe_poses: NDArray[np.float64],
    keyframe_odometry: NDArray[np.float64],
    odometry: NDArray[np.float64],
    scan_keyframe: NDArray[np.int64],
    weight: float,
) -> NDArray[np.float64]:
    """``(N, 3)`` car poses of every scan placed on the keyframe poses ``(K, 3)``.

    ``keyframe_odometry`` ``(K, 3)`` and ``odometry`` ``(N, 3)``: the front end's poses of the
    keyframes and of the scans; ``scan_keyframe`` ``(N,)``: the keyframe each scan hangs from.
    A scan between keyframes ``k`` and ``k + 1`` is placed on each of their poses by the
    front end's motion relative to it, and the two placements are blended by the share of the
    way driven from ``k`` to ``k + 1``, where progress counts a turn of 1 rad as ``weight`` [m]
    (``keyframe_distance / keyframe_angle``: turning on the spot blends as smoothly as
    driving)."""
    before = np.asarray(scan_keyframe, dtype=np.int64)
    after = np.minimum(before + 1, len(keyframe_poses) - 1)
    from_before = compose(keyframe_poses[before], relative(keyframe_odometry[before], odometry))
    from_after = compose(keyframe_poses[after], relative(keyframe_odometry[after], odometry))

    def progress(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.hypot(*(b[:, :2] - a[:, :2]).T) + weight * np.abs(wrap_angle(b[:, 2]
                                                                              - a[:, 2]))

    driven = progress(keyframe_odometry[before], odometry)
    spacing = progress(keyframe_odometry[before], keyframe_odometry[after])
    share = np.where(spacing > 0, np.clip(driven / np.maximum(spacing, 1e-12), 0, 1), 0.0)
    smoothed = from_before + share[:, None] * (from_after - from_before)
    turn = wrap_angle(from_after[:, 2] - from_before[:, 2])
    smoothed[:, 2] = wrap_angle(from_before[:, 2] + share * turn)
    return smoothed
