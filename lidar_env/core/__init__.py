"""The base layer every package builds on: SE(2) poses as plain arrays (:mod:`.se2`), the
project's exception hierarchy (:mod:`.errors`, every error for bad input derives from
:class:`DualLidarError`, a ``ValueError``) and the checks of a scan's time stamp (:mod:`.clock`).

It imports numpy and nothing else of the project, so ``estimators`` and ``agents`` take these
from here and never from the env's internals.
"""

from lidar_env.core import se2
from lidar_env.core.clock import MAX_TIME, check_time
from lidar_env.core.errors import (
    ArgumentTypeError,
    ConfigError,
    DatabaseError,
    DualLidarError,
    EstimatorInputError,
    LogFormatError,
    MapError,
    ResetNeededError,
    UnknownNameError,
)

__all__ = [
    "MAX_TIME",
    "ArgumentTypeError",
    "ConfigError",
    "DatabaseError",
    "DualLidarError",
    "EstimatorInputError",
    "LogFormatError",
    "MapError",
    "ResetNeededError",
    "UnknownNameError",
    "check_time",
    "se2",
]
