"""The env's action: ``(speed, yaw rate)`` as fractions of ``max_speed`` [m/s] and
``max_yaw_rate`` [rad/s], a float ``Box(-1, 1, (2,))``; values outside [-1, 1] are clipped by the
env, anything that is not two finite numbers is refused here by name."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from lidar_env.core.errors import ConfigError


def checked_action(action: ArrayLike) -> tuple[float, float]:
    """(throttle, steer) of an action, or a :class:`ConfigError` naming what was wrong."""
    try:
        a = np.asarray(action, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise ConfigError(
            f"action: expected 2 numbers (speed, yaw rate) in [-1, 1], got {action!r:.60}"
        ) from error
    if a.shape != (2,):
        raise ConfigError(
            f"action: expected shape (2,) (speed, yaw rate) in [-1, 1], got shape {a.shape}"
        )
    throttle, steer = float(a[0]), float(a[1])
    if not (math.isfinite(throttle) and math.isfinite(steer)):
        raise ConfigError(f"action: expected finite values in [-1, 1], got {a.tolist()}")
    return throttle, steer
