"""Scoring a trajectory: metrics (eq. 11 accuracy, ATE, RPE, drift: ``metrics``), the Kümmerle
relations metric (``relations``), TUM trajectory files (``tum``) and the ``ScoreEstimator`` env
wrapper that runs an estimator and its map beside an episode (``scoring``). It imports
``estimators.base``, ``estimators.registry``, ``estimators.mapping`` and ``lidar_env``.
"""

from estimators.evaluation.metrics import TrajectoryMetrics, evaluate
from estimators.evaluation.scoring import ScoreEstimator
from estimators.evaluation.tum import read_tum, write_tum

__all__ = ["ScoreEstimator", "TrajectoryMetrics", "evaluate", "read_tum", "write_tum"]
