"""A driver backed by a Stable-Baselines3 PPO policy (needs the ``agents`` extra and torch)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from agents.observation import TraceFollowingObservation
from agents.policy_file import load_policy
from lidar_env.core import ConfigError, ResetNeededError

#: The policy shipped with the package (trained by ``python -m agents.imitate``: it imitates
#: the scan-aware driver and gives way to pedestrians; ``ppo_driver.json`` beside it records
#: the run).
SHIPPED_MODEL = Path(__file__).with_name("models") / "ppo_driver.zip"


class SB3Driver:
    """Drive the env's active trace with a trained PPO policy.

    ``reset(env)`` then ``act(observation, info) -> action`` like every driver; the raw env
    observation and ``info`` are turned into the policy's input by the same
    :class:`~agents.observation.TraceFollowingObservation` logic used in training, with sector
    deltas when the model's input has room for them (models trained before them have not).

    The model is read weights-only (:func:`agents.policy_file.load_policy`): nothing in the
    file is unpickled, so a crafted zip cannot run code. ``trust_model=True`` loads it with
    ``PPO.load`` instead (unpickling its settings), for a model with a custom policy class
    that you made yourself.
    """

    def __init__(self, model_path: str | Path = SHIPPED_MODEL, deterministic: bool = True,
                 trust_model: bool = False) -> None:
        try:
            import stable_baselines3  # noqa: F401
        except ImportError as error:  # pragma: no cover - depends on the install
            raise gym.error.DependencyNotInstalled(
                'the SB3 driver needs stable-baselines3 and torch: pip install torch==2.13.0 '
                '"duallidar[agents]"'
            ) from error
        path = Path(model_path)
        if not path.is_file():
            raise FileNotFoundError(
                f"no trained model at {path}: train one with python -m agents.train"
            )
        self.model = load_policy(path, trust_model=bool(trust_model))
        self.deterministic = deterministic
        self.model_path = path
        self._view: TraceFollowingObservation | None = None

    def reset(self, env: gym.Env) -> None:
        plain = TraceFollowingObservation(env.unwrapped)
        if self.model.observation_space.shape == plain.observation_space.shape:
            self._view = plain
        else:
            self._view = TraceFollowingObservation(env.unwrapped, sector_deltas=True)
        if self.model.observation_space.shape != self._view.observation_space.shape:
            raise ConfigError(
                f"model_path: {self.model_path} takes observations of shape "
                f"{self.model.observation_space.shape}, expected "
                f"{plain.observation_space.shape} or {self._view.observation_space.shape}")

    def act(self, observation: dict[str, Any], info: dict[str, Any]) -> NDArray[np.float32]:
        if self._view is None:
            raise ResetNeededError("call reset(env) before act()")
        features = self._view.observe(observation, info)
        action, _ = self.model.predict(features, deterministic=self.deterministic)
        self._view.last_action = np.clip(np.asarray(action, np.float32), -1.0, 1.0)
        return self._view.last_action
