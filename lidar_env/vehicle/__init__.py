"""The car: a box-shaped body with unicycle kinematics and exact collision checks
(:mod:`.car`), and the env's action, ``(speed, yaw rate)`` as fractions of their limits
(:mod:`.actions`).

It imports only :mod:`lidar_env.core`.
"""

from lidar_env.vehicle.actions import checked_action
from lidar_env.vehicle.car import Car

__all__ = ["Car", "checked_action"]
