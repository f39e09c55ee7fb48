"""Matching two scans: scan geometry (points, normals, fitted local curves, likelihood fields:
``scan_matching``), the exhaustive correlative search (``correlative``), point-to-line ICP
(``icp``), the multi-resolution branch-and-bound correlative matcher for scans far apart
(``branch_and_bound``), the heading change from log-polar spectra (``rotation``) and
rotation-aware phase correlation (``rotation_pc``, with the ``pc_rot``/``pc_rot_icp``
estimators). It imports ``estimators.base``, ``estimators.paper`` and ``lidar_env`` only.
"""

from estimators.matching.icp import ICPParams, register
from estimators.matching.point_to_line import PointToLineReference
from estimators.matching.rotation_pc import ScanMatcher
from estimators.matching.scan_matching import LikelihoodField, scans_to_car_points

__all__ = ["ICPParams", "LikelihoodField", "PointToLineReference", "ScanMatcher", "register",
           "scans_to_car_points"]
