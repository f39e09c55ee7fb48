"""Lidar-only motion estimators, their metrics and the pipeline that scores them."""

from estimators.base import LIDAR_KEYS, Estimator, SensorSetup
from estimators.registry import make, names
from estimators.scoring import ScoreEstimator

__all__ = ["LIDAR_KEYS", "Estimator", "ScoreEstimator", "SensorSetup", "make", "names"]
