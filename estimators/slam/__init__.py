"""Pose-graph SLAM: SE(2) pose graphs and their solver (``pose_graph``, ``solver``, with its
compiled ``sparse_cholesky``; rows kept in ``growing_rows``), loop closure (place
descriptors, correlative match, verification: ``loop_closure``), g2o files (``g2o``) and the
``slam`` estimator (``graph_slam``: a front end plus loop closure; the place found again
where the front end lost it, ``relocalization``). It imports
``estimators.base``, ``estimators.registry`` (to build its front end), ``estimators.matching``
and ``lidar_env``.
"""

from estimators.slam.g2o import read_g2o, write_g2o
from estimators.slam.graph_slam import GraphSlam
from estimators.slam.pose_graph import PoseGraph
from estimators.slam.solver import optimize

__all__ = ["GraphSlam", "PoseGraph", "optimize", "read_g2o", "write_g2o"]
