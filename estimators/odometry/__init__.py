"""Odometry front ends, which chain scan matches into car poses: scan-to-local-map odometry
(``local_map``: ``lidar_odometry``, with ``far_scans`` for scans far apart and ``free_space``
for moving points), two-Lidar least-squares fusion (``fusion``: ``pc_fusion``)
and the constant-velocity motion prior both share (``motion_prior``). It imports
``estimators.base``, ``estimators.matching``, ``estimators.paper`` and ``lidar_env``.
"""

from estimators.odometry.fusion import FusionEstimator
from estimators.odometry.local_map import LocalMapOdometry

__all__ = ["FusionEstimator", "LocalMapOdometry"]
