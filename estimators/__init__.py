"""Lidar-only motion estimators, their metrics and the pipeline that scores them.

``base`` (the ``Estimator`` interface, ``SensorSetup``) and ``registry`` (``make``/``names``)
are what every subpackage builds on; the subpackages, one per concern, import only those below
them: ``paper`` and ``matching`` at the bottom, then ``odometry``, ``slam``, ``mapping``,
``evaluation``, ``datasets``, and ``leaderboard`` at the top. ``estimators.metrics`` is
``estimators.evaluation.metrics``.
"""

from estimators import evaluation
from estimators.base import LIDAR_KEYS, Estimator, SensorSetup
from estimators.evaluation import ScoreEstimator, metrics
from estimators.paths import PROJECT_ROOT
from estimators.registry import make, names
from lidar_env import __version__
from lidar_env.core.kernel_cache import drop_stale_caches

# The estimators' kernels compile lidar_env's SE(2) and geometry kernels in.
drop_stale_caches(PROJECT_ROOT, "estimators", ("estimators", "lidar_env"))

__all__ = [
    "LIDAR_KEYS",
    "Estimator",
    "ScoreEstimator",
    "SensorSetup",
    "evaluation",
    "make",
    "metrics",
    "names",
    "__version__",
]
