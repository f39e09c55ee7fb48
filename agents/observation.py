"""What the learned driver sees: both scans, pooled, how they changed, and the next waypoints.

:class:`TraceFollowingObservation` wraps ``DualLidar-v0`` and replaces its observation by one
flat float32 vector in ``[-1, 1]`` that an ``MlpPolicy`` can take:

=========================  ===========================================================  =====
slice                      meaning                                                      units
=========================  ===========================================================  =====
``[0, 2 * n_sectors)``     per Lidar, per sector: the nearest return / ``max_range``     [-]
``[.., + 2 * n_points)``   next trace points, every ``point_spacing`` m of arc ahead,   [-]
                           in the car frame (x forward, y left), / ``lookahead_scale``
``[.., + 2)``              signed cross-track error / ``cross_track_scale`` (left +),   [-]
                           heading error to the trace tangent / pi (CCW +), clipped
``[.., + 2)``              the previous action                                          [-]
``[.., + 2 * n_sectors)``  only with ``sector_deltas``: per Lidar, per sector, this     [-]
                           frame's nearest return minus the previous frame's,
                           / ``delta_scale``, clipped (0 on an episode's first frame)
=========================  ===========================================================  =====

Sector ``k`` of a Lidar covers beams ``[k n / n_sectors, (k + 1) n / n_sectors)``, i.e. the
angles ``[2 pi k / n_sectors, 2 pi (k + 1) / n_sectors)`` CCW from that sensor's forward axis.
The sector deltas are how the policy sees motion: one frame of ranges cannot tell a pedestrian
walking into the car's way from a post beside it, the change over the last 0.1 s can (a
closing mover shortens its sector faster than the car's own speed explains). They come last so
that the other slices keep their indices with or without them.
The trace points come from the env's active trace and the true car pose (``info["pose"]``): the
driver is told where to go, like a route planner would; it never feeds an estimator. Nothing
is read from ``info["moving_obstacles"]``: movers are seen through the scans only.

The reward is the env's (metres of progress along the trace, a small cross-track penalty, a
collision penalty of 10) minus ``cross_track_weight * |cross-track error| * dt``, minus
``collision_penalty`` more on a collision: the env's own penalties are sized for a scripted
driver, too weak to teach a policy to hold the line, and a collision that only costs 10 m of
progress is worth risking against the time lost waiting for a pedestrian to pass. With
``randomize=True`` each episode's world and trace seed are drawn from a generator seeded by
``reset(seed=...)``, so one policy learns every seed in every world.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from lidar_env.core import ConfigError, se2


class TraceFollowingObservation(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Flat, normalised observation for a trace-following policy (see the module docstring)."""

    def __init__(
        self,
        env: gym.Env,
        n_sectors: int = 36,
        n_points: int = 5,
        point_spacing: float = 0.5,  # [m] of trace arc between two look-ahead points
        lookahead_scale: float = 3.0,  # [m] a car-frame coordinate of this size maps to 1
        cross_track_scale: float = 0.5,  # [m] a cross-track error of this size maps to 1
        cross_track_weight: float = 1.0,  # [1/(m s)] extra reward penalty per metre off the trace
        collision_penalty: float = 0.0,  # [-] extra reward penalty on a collision (env's: 10)
        sector_deltas: bool = False,  # append each sector's change since the previous frame
        delta_scale: float = 0.3,  # [m] a sector range change of this size per frame maps to 1
        randomize: bool = False,
        worlds: Sequence[str] = ("open_cylinders", "hallway", "closed_to_open", "random"),
        traces: Sequence[str] = ("straight", "right_turn", "zigzag"),
    ) -> None:
        gym.utils.RecordConstructorArgs.__init__(
            self, n_sectors=n_sectors, n_points=n_points, point_spacing=point_spacing,
            lookahead_scale=lookahead_scale, cross_track_scale=cross_track_scale,
            cross_track_weight=cross_track_weight, collision_penalty=collision_penalty,
            sector_deltas=sector_deltas, delta_scale=delta_scale, randomize=randomize,
            worlds=worlds, traces=traces,
        )
        gym.Wrapper.__init__(self, env)
        n_beams = env.unwrapped.config.n_beams
        if n_sectors < 1 or n_beams % n_sectors:
            raise ConfigError(
                f"n_sectors: expected a divisor of n_beams={n_beams}, got {n_sectors}")
        scales = (n_points, point_spacing, lookahead_scale, cross_track_scale, delta_scale)
        if min(scales) <= 0 or min(cross_track_weight, collision_penalty) < 0:
            raise ConfigError(
                "n_points, point_spacing, lookahead_scale, cross_track_scale and delta_scale must "
                "be positive and cross_track_weight, collision_penalty >= 0, got "
                f"{scales} and {cross_track_weight}, {collision_penalty}"
            )
        self.n_sectors = n_sectors
        self.offsets = point_spacing * np.arange(1, n_points + 1)
        self.lookahead_scale = lookahead_scale
        self.cross_track_scale = cross_track_scale
        self.cross_track_weight = cross_track_weight
        self.collision_penalty = collision_penalty
        self.sector_deltas = sector_deltas
        self.delta_scale = delta_scale
        self.randomize = randomize
        self._rng: np.random.Generator | None = None  # draws world and trace when randomizing
        self.worlds = tuple(worlds)
        self.traces = tuple(traces)
        size = 2 * n_sectors + 2 * n_points + 4 + (2 * n_sectors if sector_deltas else 0)
        self.observation_space = gym.spaces.Box(-1.0, 1.0, (size,), np.float32)
        self.last_action = np.zeros(2, np.float32)
        self._arc = 0.0
        self._trace: Any = None
        self._tangents = np.zeros(0)
        self._previous_sectors = np.zeros(2 * n_sectors, np.float32)  # [m] the last frame's

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        options = dict(options or {})
        if self.randomize:
            if seed is not None or self._rng is None:
                self._rng = np.random.default_rng(seed)
            options.setdefault("world", self.worlds[self._rng.integers(len(self.worlds))])
            options.setdefault("trace", self.traces[self._rng.integers(len(self.traces))])
        observation, info = self.env.reset(seed=seed, options=options)
        self.last_action = np.zeros(2, np.float32)
        self._arc = 0.0
        return self.observe(observation, info), info

    def step(
        self, action: NDArray[np.float32]
    ) -> tuple[NDArray[np.float32], float, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, info = self.env.step(action)
        reward = self.shape_reward(float(reward), info)
        self.last_action = np.clip(np.asarray(action, np.float32), -1.0, 1.0)
        return self.observe(observation, info), reward, terminated, truncated, info

    def shape_reward(self, reward: float, info: dict[str, Any]) -> float:
        """The training reward for the env's ``reward`` and ``info`` of one step."""
        dt = self.env.unwrapped.config.control_dt
        reward -= self.cross_track_weight * abs(info["cross_track_error"]) * dt
        if info["collision"]:
            reward -= self.collision_penalty
        return reward

    def observe(self, observation: dict[str, Any], info: dict[str, Any]) -> NDArray[np.float32]:
        """The policy input for one raw env observation and its ``info``."""
        max_range = self.env.unwrapped.config.max_range
        sectors = np.concatenate([
            np.asarray(observation[key], np.float32).reshape(self.n_sectors, -1).min(axis=1)
            for key in ("lidar_1", "lidar_2")
        ])
        if info["time"] == 0.0:  # an episode's first frame: no motion seen yet
            self._previous_sectors = sectors
        deltas, self._previous_sectors = sectors - self._previous_sectors, sectors
        pose = np.asarray(info["pose"], np.float64)
        trace = self.env.unwrapped.trace
        projection = trace.project(pose[:2], near=self._arc)
        self._arc = projection.arc_position
        ahead = trace.points_at(self._arc + self.offsets)
        local = se2.transform_points(se2.inverse(pose), ahead) / self.lookahead_scale
        if trace is not self._trace:  # a new episode's trace: unwrap its headings once
            self._trace, self._tangents = trace, np.unwrap(trace.headings)
        arc = self._arc % trace.length if trace.closed else self._arc  # laps wrap around
        tangent = np.interp(arc, trace.arc, self._tangents)
        errors = [
            projection.cross_track_error / self.cross_track_scale,
            float(se2.wrap_angle(pose[2] - tangent)) / np.pi,
        ]
        parts = [
            sectors / max_range,
            np.clip(local.ravel(), -1.0, 1.0),
            np.clip(errors, -1.0, 1.0),
            self.last_action,
        ]
        if self.sector_deltas:
            parts.append(np.clip(deltas / self.delta_scale, -1.0, 1.0))
        return np.concatenate(parts).astype(np.float32)
