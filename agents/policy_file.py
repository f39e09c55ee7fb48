"""Loading a Stable-Baselines3 PPO model zip without running code from it.

An SB3 zip holds ``data`` (JSON whose ``:serialized:`` entries are cloudpickles of the policy
class, the spaces and the schedules) and ``policy.pth`` (the policy's ``state_dict``).
``PPO.load`` unpickles the former, so a crafted file runs any code it likes. By default
:func:`load_policy` never unpickles: it reads the plain JSON settings (the observation and
action shapes, ``policy_kwargs`` made of plain values only), builds SB3's ``ActorCriticPolicy``
(the ``MlpPolicy`` every model of ``agents.imitate`` and ``agents.train`` uses) and loads the
weights with ``torch.load(..., weights_only=True)``, which refuses anything but tensors and
plain containers. A model that needs more (a custom policy class or activation, gSDE) is
refused with a :class:`~lidar_env.core.errors.ConfigError`; pass ``trust_model=True`` (the
command lines' ``--trust-model``) to load it with ``PPO.load``, for files you made yourself.
"""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from lidar_env.core.errors import ConfigError, quoted

#: ``policy_kwargs`` of ``ActorCriticPolicy`` that are plain values (no class to unpickle).
PLAIN_POLICY_KWARGS = frozenset({"net_arch", "log_std_init", "ortho_init",
                                 "share_features_extractor", "squash_output", "full_std",
                                 "use_expln", "normalize_images"})
#: [bytes] largest ``data`` JSON and ``policy.pth`` read from a model zip.
MAX_DATA_BYTES, MAX_WEIGHTS_BYTES = 16 << 20, 1 << 30
#: What to pass to load a model this module refuses.
TRUST_HINT = "pass trust_model=True (--trust-model) to unpickle it, only for a file you trust"


def load_policy(path: Path, trust_model: bool = False) -> Any:
    """The policy of the PPO zip ``path``: an object with ``observation_space`` and
    ``predict(observation, deterministic=...) -> (action, state)`` (SB3's
    ``ActorCriticPolicy``, or with ``trust_model`` the ``PPO`` model ``PPO.load`` returns)."""
    if trust_model:
        from stable_baselines3 import PPO

        return PPO.load(path, device="cpu")
    try:
        with zipfile.ZipFile(path) as archive:
            data = json.loads(_member(archive, path, "data", MAX_DATA_BYTES))
            weights = _member(archive, path, "policy.pth", MAX_WEIGHTS_BYTES)
    except (zipfile.BadZipFile, json.JSONDecodeError, UnicodeDecodeError) as error:
        raise ConfigError(f"model_path: {path}: expected a Stable-Baselines3 PPO zip, got "
                          f"{type(error).__name__}: {str(error)[:100]}") from error
    if not isinstance(data, dict):
        raise ConfigError(f"model_path: {path}: expected a JSON object in 'data', got "
                          f"{type(data).__name__}")
    return _policy_from(path, data, weights)


def _member(archive: zipfile.ZipFile, path: Path, name: str, limit: int) -> bytes:
    try:
        info = archive.getinfo(name)
    except KeyError:
        raise ConfigError(f"model_path: {path}: expected a Stable-Baselines3 PPO zip with "
                          f"'{name}', got members {quoted(archive.namelist())}") from None
    if info.file_size > limit:
        raise ConfigError(f"model_path: {path}: expected '{name}' of at most {limit} bytes, "
                          f"got {info.file_size}")
    return archive.read(info)


def _shape(path: Path, data: dict[str, Any], key: str) -> tuple[int, ...]:
    space = data.get(key)
    shape = space.get("_shape") if isinstance(space, dict) else None
    if not (isinstance(space, dict) and "Box" in str(space.get(":type:"))
            and isinstance(shape, list) and len(shape) == 1
            and isinstance(shape[0], int) and 0 < shape[0] < 1 << 20):
        raise ConfigError(f"model_path: {path}: expected a 1-D Box {key} in 'data', got "
                          f"{quoted(None if not isinstance(space, dict) else space.get(':type:'))}"
                          f" of shape {quoted(shape)}; {TRUST_HINT}")
    return (shape[0],)


def _policy_from(path: Path, data: dict[str, Any], weights: bytes) -> Any:
    import gymnasium as gym
    import torch
    from stable_baselines3.common.policies import ActorCriticPolicy

    kwargs = data.get("policy_kwargs") or {}
    if not isinstance(kwargs, dict) or ":serialized:" in kwargs:
        raise ConfigError(f"model_path: {path}: policy_kwargs are pickled; {TRUST_HINT}")
    unknown = sorted(set(kwargs) - PLAIN_POLICY_KWARGS)
    if unknown:
        raise ConfigError(f"model_path: {path}: policy_kwargs {quoted(unknown)} need classes "
                          f"unpickled (plain ones: {', '.join(sorted(PLAIN_POLICY_KWARGS))}); "
                          f"{TRUST_HINT}")
    if data.get("use_sde"):
        raise ConfigError(f"model_path: {path}: a gSDE policy (use_sde) is not read weights-only;"
                          f" {TRUST_HINT}")
    observations = gym.spaces.Box(-1.0, 1.0, _shape(path, data, "observation_space"), np.float32)
    actions = gym.spaces.Box(-1.0, 1.0, _shape(path, data, "action_space"), np.float32)
    try:
        policy = ActorCriticPolicy(observations, actions, lambda _: 0.0, **kwargs)
        state = torch.load(io.BytesIO(weights), map_location="cpu", weights_only=True)
        policy.load_state_dict(state)
    except Exception as error:  # noqa: BLE001 - torch and SB3 raise many kinds for a bad file
        raise ConfigError(f"model_path: {path}: expected the weights of an MlpPolicy with "
                          f"policy_kwargs {quoted(kwargs)}, got {type(error).__name__}: "
                          f"{str(error)[:160]}; {TRUST_HINT}") from error
    policy.set_training_mode(False)
    return policy
