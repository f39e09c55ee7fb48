"""A driver that sees: pure pursuit of the trace, braking and backing off for what its scans show.

:class:`ScanAwareDriver` steers like :class:`~agents.scripted.PurePursuitDriver` (the trace
from the true pose, ``info["pose"]``) but chooses its speed from the scans alone: every
beam's return is put in the car frame (from each Lidar's mount), and of the returns in the
*corridor* the car is about to sweep (the arc of the pure-pursuit command, as wide as the car
plus ``side_margin``) the nearest one ahead of the nose limits the speed to what stops in time:

    speed = min(pure-pursuit speed, (free - stop_gap) / headway), and 0 below ``stop_gap``,

with ``free`` [m] the arc length from the nose to that return. It never reads
``info["moving_obstacles"]``: a pedestrian is a cluster of returns like any other. It is the
expert the learned driver imitates (:mod:`agents.imitate`) and a driver in its own right
(``make_driver("scan_aware")``).

Braking is not enough where pedestrians ignore the car (``config["mover_model"] =
"waypoints"``): a car standing for one is walked into. So it also backs off (``back_off``):
the free arc is compared with the last frame's less the car's own travel, and a return ahead
closing in at over :data:`CLOSING_SPEED` within :data:`THREAT_RANGE` sends the car straight
back at the closing speed + 0.3 m/s while the corridor behind is free. The wide
``side_margin`` (0.4 m; 0.2 m let twice as many crossing pedestrians reach the front corner)
makes it brake for a pedestrian about to cross before it is in the car's way. It never
swerves, and it cannot escape a pedestrian that walks into it from the side or behind.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from agents.scripted import PurePursuitDriver
from lidar_env.core import ConfigError

#: [m/s] a return ahead closing in faster than this (beyond the car's own motion) is a threat.
CLOSING_SPEED = 0.15
#: [m] free arc below which a closing return makes the car back off.
THREAT_RANGE = 2.5


class ScanAwareDriver:
    """Pure pursuit with a speed limit from the scans (see the module docstring).

    Args:
        speed: cruise speed [m/s] of the pure pursuit (capped at the env's ``max_speed``):
            1.5 m/s, the env's top speed, as fast as the PPO trace follower; braking keeps it
            safe (it finished 90 of 90 seeded episodes among yielding pedestrians at 1.5 as
            at 1.0 m/s).
        side_margin: [m] added to the car's half width on each side of the corridor (with
            ``back_off``, a return beside the body, not ahead of the nose, stops the car only
            within the body's own width: stopping would let it walk in).
        stop_gap: [m] free arc length ahead of the nose at which the car stops.
        headway: [s] the speed is at most (free - stop_gap) / headway.
        reach: [m] arc length ahead of the nose the corridor is checked over.
        back_off: back away, straight, from a return ahead that closes in faster than the car
            drives (see :meth:`act`), if the corridor behind is free.
    """

    def __init__(self, speed: float = 1.5, side_margin: float = 0.4, stop_gap: float = 0.3,
                 headway: float = 1.0, reach: float = 3.0, back_off: bool = True) -> None:
        for name, value in (("speed", speed), ("side_margin", side_margin),
                            ("stop_gap", stop_gap), ("headway", headway), ("reach", reach)):
            if not math.isfinite(value) or value <= 0:
                raise ConfigError(f"{name}: expected a positive number, got {value!r}")
        self.pursuit = PurePursuitDriver(speed=speed)
        self.side_margin = side_margin
        self.stop_gap = stop_gap
        self.headway = headway
        self.reach = reach
        self.back_off = back_off
        self._previous_free = math.inf
        self._previous_speed = 0.0
        self._closing = 0.0  # [m/s] smoothed closing speed of the nearest return ahead
        self._dt = 0.1
        self._keys: tuple[str, ...] = ()
        self._directions: list[NDArray[np.float64]] = []  # per Lidar, (n, 2) unit beams
        self._mounts: list[NDArray[np.float64]] = []
        self._max_ranges: list[float] = []
        self._world_frame = False
        self._half_length = 0.4
        self._half_width = 0.25
        self._max_speed = 1.0
        self._max_yaw_rate = 1.0
        self.last_free = math.inf  # [m] free arc ahead of the nose at the last act()

    def reset(self, env: gym.Env) -> None:
        """Follow the trace ``env`` was just reset to, with its Lidars' geometry."""
        self.pursuit.reset(env)
        config = env.unwrapped.config
        self._keys = tuple(env.unwrapped.lidar_keys)
        self._world_frame = config.scan_frame == "world"
        self._mounts = [np.asarray(lidar.mount, np.float64) for lidar in config.lidars]
        self._directions = []
        for lidar in config.lidars:
            angles = np.asarray(lidar.beam_angles, np.float64)
            self._directions.append(np.column_stack([np.cos(angles), np.sin(angles)]))
        self._max_ranges = [float(lidar.max_range) for lidar in config.lidars]
        self._half_length = 0.5 * float(config.car_length)
        self._half_width = 0.5 * float(config.car_width)
        self._max_speed = float(config.max_speed)
        self._max_yaw_rate = float(config.max_yaw_rate)
        self._dt = float(config.control_dt)
        self.last_free = math.inf
        self._previous_free = math.inf
        self._previous_speed = 0.0
        self._closing = 0.0

    def scan_points(self, observation: Mapping[str, Any], heading: float) -> NDArray[np.float64]:
        """``(N, 2)`` [m] every return (not the no-hit reading ``max_range``), car frame."""
        parts = []
        for key, directions, mount, max_range in zip(
                self._keys, self._directions, self._mounts, self._max_ranges, strict=True):
            ranges = np.asarray(observation[key], np.float64)
            hit = ranges < max_range
            turn = -heading if self._world_frame else mount[2]
            c, s = math.cos(turn), math.sin(turn)
            d = directions[hit]
            r = ranges[hit, None]
            parts.append(mount[:2] + r * np.column_stack([c * d[:, 0] - s * d[:, 1],
                                                          s * d[:, 0] + c * d[:, 1]]))
        return np.concatenate(parts) if parts else np.zeros((0, 2))

    def free_arc(self, points: NDArray[np.float64], curvature: float) -> float:
        """[m] arc length from the nose to the nearest of ``points`` (car frame) in the
        corridor of the arc of ``curvature`` [1/m] (``reach`` + ``stop_gap`` if none)."""
        width = self._half_width + self.side_margin
        if abs(curvature) < 1e-6:
            along, lateral = points[:, 0], points[:, 1]
        else:
            radius = 1.0 / curvature
            dx, dy = points[:, 0], points[:, 1] - radius  # from the turn's centre
            rho = np.hypot(dx, dy)
            lateral = np.sign(radius) * (abs(radius) - rho)
            swept = np.arctan2(dx, -dy * np.sign(radius))  # [rad] turned from the car
            along = abs(radius) * np.where(swept < -0.5 * math.pi, swept + 2 * math.pi, swept)
        ahead = along - self._half_length
        # in the corridor and ahead of the nose; beside the body too, but when backing off
        # only within the body's width (stopping for a return just beside the car lets it in)
        beside = ahead > -self._half_length
        if self.back_off:
            beside &= np.abs(lateral) <= self._half_width
        blocking = (np.abs(lateral) <= width) & ((ahead > 0.0) | beside) & (ahead < self.reach)
        if not blocking.any():
            return self.reach + self.stop_gap
        return float(max(ahead[blocking].min(), 0.0))

    def act(self, observation: Mapping[str, Any], info: Mapping[str, Any]) -> NDArray[np.float32]:
        """The pure-pursuit action with its speed capped by the free arc ahead; with
        ``back_off``, a reverse away from a return ahead closing in at over
        :data:`CLOSING_SPEED` (the free arc shrinking faster than the car's own motion explains,
        smoothed over frames) within :data:`THREAT_RANGE`."""
        action = self.pursuit.act(observation, info)
        speed = float(action[0]) * self._max_speed
        if speed <= 0.0:
            return action
        yaw_rate = float(action[1]) * self._max_yaw_rate
        heading = float(np.asarray(info["pose"], np.float64)[2])
        points = self.scan_points(observation, heading)
        self.last_free = free = self.free_arc(points, yaw_rate / speed)
        limit = max(free - self.stop_gap, 0.0) / self.headway
        if limit < speed:  # keep the arc: scale the yaw rate with the speed
            scale = limit / speed
            action = np.array([action[0] * scale, action[1] * scale], dtype=np.float32)
        if self.back_off:
            expected = self._previous_free - self._previous_speed * self._dt
            seen = max(free, self._previous_free) < self.reach  # the same return, twice
            step = (expected - free) / self._dt if seen and abs(expected - free) < 0.3 else 0.0
            self._closing = 0.5 * self._closing + 0.5 * step
            self._previous_free = free
            if free < THREAT_RANGE and self._closing > CLOSING_SPEED:
                behind = self.free_arc(points * np.array([-1.0, 1.0]), 0.0)
                if behind > self.stop_gap + 0.2:
                    back = min(self._closing + 0.3, self._max_speed, 2.0 * (behind - self.stop_gap))
                    action = np.array([-back / self._max_speed, 0.0], dtype=np.float32)
            self._previous_speed = float(action[0]) * self._max_speed
        return action
