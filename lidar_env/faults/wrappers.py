"""The Gymnasium wrapper that injects sensor faults into an env with Lidar observations."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np

from lidar_env.core import ConfigError
from lidar_env.faults.frames import Fault, Frame, spawn_generators


class FaultInjection(gym.Wrapper):
    """Applies ``faults`` (in order) to every observation's Lidar scans and to
    ``info["time"]``.

    Observations keep their keys, shapes and dtype; faults act on the keys ``lidar_1`` ..
    of the observation. ``info["time"]`` [s] is the faulty stamp, ``info["true_time"]`` the
    env's own. A lost scan (:class:`~lidar_env.faults.ScanLoss`) is never returned: the
    wrapper steps the env again with the same action and returns the next one that arrives
    (rewards summed, the episode's end passed on at once). Each fault draws from its own
    generator spawned at every ``reset`` from the env's ``np_random``, which that draw
    leaves as it is: same seed, same faults, and the same world, noise and movers as without
    the wrapper. Wrappers nest (``FaultInjection(FaultInjection(env, a), b)``: ``a`` first).

    Args:
        env: an env whose observations are dicts of ``lidar_k`` scans (``DualLidar-v0``).
        faults: :mod:`lidar_env.faults` objects (:class:`~lidar_env.faults.Blind`, ...).
    """

    def __init__(self, env: gym.Env, *faults: Fault) -> None:
        super().__init__(env)
        if not faults:
            raise ConfigError("faults: expected at least one Fault, got none")
        for fault in faults:
            if not isinstance(fault, Fault):
                raise ConfigError(f"faults: expected Fault objects, got {type(fault).__name__}")
        self.faults: Sequence[Fault] = faults
        self._step = 0

    def _max_ranges(self) -> dict[str, float]:
        inner = self.env.unwrapped
        return {key: float(lidar.max_range)
                for key, lidar in zip(inner.lidar_keys, inner.config.lidars, strict=True)}

    def _fault(self, observation: dict[str, Any], info: dict[str, Any]) -> Frame | None:
        frame: Frame | None = Frame(
            {key: value for key, value in observation.items() if key.startswith("lidar_")},
            float(info["time"]), self._step)
        self._step += 1
        for fault in self.faults:
            if frame is None:
                break
            frame = fault.apply(frame)
        return frame

    def _deliver(self, observation: dict[str, Any], info: dict[str, Any],
                 frame: Frame) -> tuple[dict[str, Any], dict[str, Any]]:
        observation = dict(observation)
        for key, scan in frame.scans.items():
            observation[key] = np.asarray(scan, dtype=observation[key].dtype)
        info = dict(info)
        info["true_time"] = info["time"]
        info["time"] = frame.time
        return observation, info

    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        observation, info = self.env.reset(seed=seed, options=options)
        generators = spawn_generators(self.env.unwrapped.np_random, len(self.faults))
        for fault, rng in zip(self.faults, generators, strict=True):
            fault.reset(rng, self._max_ranges())
        self._step = 0
        frame = self._fault(observation, info)
        if frame is None:  # faults never lose the first scan; stay safe if one does
            frame = Frame(observation, float(info["time"]), 0)
        return self._deliver(observation, info, frame)

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        total = 0.0
        while True:
            observation, reward, terminated, truncated, info = self.env.step(action)
            total += float(reward)
            frame = self._fault(observation, info)
            if frame is not None:
                observation, info = self._deliver(observation, info, frame)
                return observation, total, terminated, truncated, info
            if terminated or truncated:  # the last scan was lost: hand on the true one
                info = dict(info, true_time=info["time"], scan_lost=True)
                return observation, total, terminated, truncated, info
