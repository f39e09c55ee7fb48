"""A privileged scripted driver: pure pursuit of the env's active trace.

It reads the true pose from ``info["pose"]`` and the trace from the env, never the scans or
any estimator: it is the reference driver that produces the ground-truth runs estimators are
scored on, not a Lidar-based controller.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from lidar_env.core import ArgumentTypeError, ConfigError, ResetNeededError
from lidar_env.routes import Trace


class PurePursuitDriver:
    """Steers towards the trace point ``lookahead`` metres of arc ahead of the car.

    Pure pursuit (Coulter, 1992): the car drives the circular arc through its own position,
    tangent to its heading, that passes through the target point; its curvature is
    ``2 y / d^2`` for a target at (x, y) in the car frame, ``d^2 = x^2 + y^2``.

    Args:
        speed: cruise speed [m/s] (capped at the env's ``max_speed``). 1 m/s leaves the yaw
            rate headroom to follow arcs down to ``speed / max_yaw_rate`` = 0.67 m radius.
        lookahead: [m] arc distance to the target point. 0.6 m is under half the tightest
            trace corner radius, so corner cutting stays within a few centimetres, well inside
            the 0.3 m margin traces keep beyond the car's half-diagonal.
        window: [m] the car's position on the trace is searched within this arc distance of
            the last one, so it never jumps to a neighbouring zigzag leg.
    """

    def __init__(self, speed: float = 1.0, lookahead: float = 0.6, window: float = 2.0) -> None:
        for name, value in (("speed", speed), ("lookahead", lookahead), ("window", window)):
            if not math.isfinite(value) or value <= 0:
                raise ConfigError(f"{name}: expected a positive number, got {value!r}")
        self.speed = speed
        self.lookahead = lookahead
        self.window = window
        self.trace: Trace | None = None
        self._arc = 0.0
        self._max_speed = 1.0
        self._max_yaw_rate = 1.0

    def reset(self, env: gym.Env) -> None:
        """Follow the trace ``env`` was just reset to."""
        unwrapped = env.unwrapped
        trace = getattr(unwrapped, "trace", None)
        if not isinstance(trace, Trace):
            raise ArgumentTypeError(
                f"env: expected a DualLidar-v0 env reset to a trace, got {type(unwrapped).__name__}"
                f" with trace {trace!r}"
            )
        self.trace = trace
        self._arc = 0.0
        self._max_speed = float(unwrapped.config.max_speed)
        self._max_yaw_rate = float(unwrapped.config.max_yaw_rate)

    def act(self, observation: Mapping[str, Any], info: Mapping[str, Any]) -> NDArray[np.float32]:
        """The (speed, yaw rate) action, as fractions of the env's limits, from ``info["pose"]``."""
        if self.trace is None:
            raise ResetNeededError("call reset(env) before act()")
        x, y, heading = (float(v) for v in np.asarray(info["pose"], dtype=np.float64))
        self._arc = self.trace.project((x, y), self._arc, self.window).arc_position
        target = self.trace.point_at(self._arc + self.lookahead)
        dx, dy = target[0] - x, target[1] - y
        ahead = math.cos(heading) * dx + math.sin(heading) * dy
        left = -math.sin(heading) * dx + math.cos(heading) * dy
        distance2 = ahead * ahead + left * left
        if distance2 < 1e-12:
            return np.zeros(2, dtype=np.float32)
        curvature = 2.0 * left / distance2
        speed = min(self.speed, self._max_speed)
        if abs(curvature) * speed > self._max_yaw_rate:
            speed = self._max_yaw_rate / abs(curvature)  # slow down to make the turn
        yaw_rate = speed * curvature
        return np.array([speed / self._max_speed, yaw_rate / self._max_yaw_rate], dtype=np.float32)
