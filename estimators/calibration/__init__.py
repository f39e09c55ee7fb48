"""Extrinsic self-calibration: the mounts of Lidars 2..K relative to Lidar 1 from a drive, with
no ground truth and no odometry (``self_calibration``), from the SE(2) hand-eye solution
(``hand_eye``) refined by aligning overlapping scans (``alignment``); ``python -m
estimators.calibration`` calibrates an env drive or a ROS bag and prints the mounts. It imports
``estimators.base``, ``estimators.registry``, ``estimators.matching``, ``estimators.datasets``,
``estimators.leaderboard`` (only its drive recorder, in the command line) and ``lidar_env``.
"""

from estimators.calibration.hand_eye import HandEyeSolution, solve_hand_eye
from estimators.calibration.self_calibration import (
    Calibration,
    InconsistentMotionWarning,
    MountEstimate,
    NoOverlapWarning,
    UnobservableMountError,
    calibrate,
)

__all__ = ["Calibration", "HandEyeSolution", "InconsistentMotionWarning", "MountEstimate",
           "NoOverlapWarning", "UnobservableMountError", "calibrate", "solve_hand_eye"]
