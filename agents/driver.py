"""The interface every driver of ``DualLidar-v0`` shares (scripted or learned)."""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from typing import Any, Protocol, runtime_checkable

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from lidar_env.errors import ConfigError


@runtime_checkable
class Driver(Protocol):
    """Chooses actions for ``DualLidar-v0``: ``reset(env)`` once per episode (after
    ``env.reset``), then ``act(observation, info)`` each step.

    ``act`` returns a float32 action of shape (2,) in [-1, 1]: (speed, yaw rate) as fractions
    of the env's ``max_speed`` and ``max_yaw_rate``.
    """

    def reset(self, env: gym.Env) -> None:
        """Prepare for the episode ``env`` has just been reset to."""

    def act(self, observation: Mapping[str, Any], info: Mapping[str, Any]) -> NDArray[np.float32]:
        """The action for this step."""


#: driver name -> "module:Class"; imported on first use (the SB3 driver needs torch).
DRIVERS: dict[str, str] = {
    "scripted": "agents.scripted:PurePursuitDriver",
    "sb3": "agents.sb3_driver:SB3Driver",
}


def make_driver(name: str, pose_source: str = "true") -> Driver:
    """A fresh driver by name: ``scripted`` (pure pursuit) or ``sb3`` (the shipped PPO policy).

    ``pose_source`` is where the driver takes the car's pose from: ``"true"`` (the env's
    ``info["pose"]``) or the name of an estimator (``estimators.registry.names()``) that runs
    online on the scans (:class:`agents.pose_source.EstimatedPoseDriver`).
    """
    if name not in DRIVERS:
        raise ConfigError(
            f"unknown driver {name!r}: expected one of {', '.join(sorted(DRIVERS))}")
    if pose_source != "true":
        from agents.pose_source import check_pose_source

        check_pose_source(pose_source)  # before loading a model
    module_name, class_name = DRIVERS[name].split(":")
    driver = getattr(importlib.import_module(module_name), class_name)()
    if pose_source == "true":
        return driver
    from agents.pose_source import EstimatedPoseDriver

    return EstimatedPoseDriver(driver, pose_source)
