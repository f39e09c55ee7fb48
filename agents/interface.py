"""The interface every driver of ``DualLidar-v0`` shares (scripted or learned)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Protocol, runtime_checkable

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray


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
