"""Odometry front ends, which chain scan matches into car poses.

- scan-to-local-map odometry (``local_map``: ``lidar_odometry``), built from mixins:
  ``velocity_model`` (its constant-velocity guess), ``far_scans`` (scans far apart, and after
  skipped or lost ones; doubtful matches checked against the previous scan by ``scan_check``;
  after a long blind stretch the match placed anew, or the scan flagged lost, by
  ``blind_resume``),
  ``unknown_start`` (an unknown start speed) and ``moving_rejection`` (points on moving
  things left out, by ``moving_points``' filter, which asks ``free_space`` what the beams saw
  free, a dropped return only as far as its neighbours (``dropped_beams``), and keeps its
  recent points in ``thinned_scans``);
- two-Lidar least-squares fusion (``fusion``: ``pc_fusion``, its graph in ``sensor_graph``, a
  disagreeing match solved around in ``edge_consensus``, gaps in ``fusion_recovery``);
- the motion prior both share (``motion_prior``).

It imports ``estimators.base``, ``estimators.matching``, ``estimators.paper`` and
``lidar_env``.
"""

from estimators.odometry.fusion import FusionEstimator
from estimators.odometry.local_map import LocalMapOdometry

__all__ = ["FusionEstimator", "LocalMapOdometry"]
