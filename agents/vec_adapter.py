"""Stable-Baselines3 on a Gymnasium vector env, e.g. the batched ``DualLidar-v0``.

:class:`SB3VecEnv` is a thin SB3 ``VecEnv`` over a ``gymnasium.vector.VectorEnv`` with
Gymnasium's ``NEXT_STEP`` autoreset and ``options["reset_mask"]`` (the batched env,
``SyncVectorEnv``): SB3 wants a finished sub-env reset on the same step, with its last
observation in ``infos[i]["terminal_observation"]``, so the adapter resets finished sub-envs
itself (a masked reset) right after the step that ended them. Rewards come back float32 and
infos as one dict per sub-env with ``"TimeLimit.truncated"``, as ``DummyVecEnv`` gives them::

    venv = gym.make_vec("DualLidar-v0", 16, vectorization_mode="vector_entry_point")
    model = PPO("MultiInputPolicy", SB3VecEnv(venv)).learn(10_000)

:class:`TraceFollowingVecEnv` is the learned driver's view of the same env: each sub-env's
observation, reward and randomised episodes come from
:class:`agents.observation.TraceFollowingObservation`'s own code, so it trains exactly what
``agents.train`` trains on single envs (same seeds, same observations and rewards as a
``DummyVecEnv`` of wrapped single envs), with the env stepped batched.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from numpy.typing import NDArray
from stable_baselines3.common.vec_env import VecEnv

from agents.observation import TraceFollowingObservation
from lidar_env.core import ConfigError


class SB3VecEnv(VecEnv):
    """SB3 ``VecEnv`` over ``venv``, a Gymnasium ``VectorEnv`` with ``NEXT_STEP`` autoreset.

    Subclasses change what the policy sees through :meth:`episode_options` (options of a
    sub-env's next episode) and :meth:`transform` (observations and rewards).
    """

    def __init__(self, venv: gym.vector.VectorEnv,
                 observation_space: gym.Space | None = None) -> None:
        mode = venv.metadata.get("autoreset_mode")
        if mode != AutoresetMode.NEXT_STEP:
            raise ConfigError(f"venv: expected a vector env with autoreset_mode NEXT_STEP, got "
                              f"{mode!r}")
        self.venv = venv  # before VecEnv.__init__, which reads render_mode through get_attr
        super().__init__(venv.num_envs, observation_space or venv.single_observation_space,
                         venv.single_action_space)
        self._actions: NDArray[Any] | None = None

    # ------------------------------------------------------------------ hooks
    def episode_options(self, i: int, seed: int | None) -> dict[str, Any]:
        """Reset options of sub-env ``i``'s next episode (``seed`` given on a seeded reset)."""
        return dict(self._options[i] or {})

    def transform(self, observation: Any, rewards: NDArray[np.float64] | None,
                  infos: dict[str, Any], envs: NDArray[np.int64],
                  actions: NDArray[Any] | None) -> tuple[Any, NDArray[np.float64] | None]:
        """Observation (and rewards) the policy gets from the vector env's, for sub-envs
        ``envs``; ``rewards`` and ``actions`` are None after a reset."""
        return observation, rewards

    # ------------------------------------------------------------------ SB3 API
    def reset(self) -> Any:
        seeds = list(self._seeds)
        options = [self.episode_options(i, seeds[i]) for i in range(self.num_envs)]
        every = np.arange(self.num_envs)
        if all(o == options[0] for o in options):
            observation, info = self.venv.reset(seed=seeds, options=options[0])
            observation, _ = self.transform(observation, None, info, every, None)
        else:
            observation = self._reset_each(every, options, seeds)
        self.reset_infos = [{} for _ in range(self.num_envs)]
        self._reset_seeds()
        self._reset_options()
        return observation

    def _reset_each(self, envs: NDArray[np.int64], options: Sequence[dict[str, Any]],
                    seeds: Sequence[int | None] | None = None) -> Any:
        """Reset sub-envs ``envs`` one masked reset each (their options differ); the batched
        observation with those rows replaced."""
        observation = None
        for i in envs:
            mask = np.zeros(self.num_envs, dtype=np.bool_)
            mask[i] = True
            seed = [seeds[j] if j == i else None for j in range(self.num_envs)] if seeds else None
            fresh, info = self.venv.reset(seed=seed, options={**options[i], "reset_mask": mask})
            fresh, _ = self.transform(fresh, None, info, np.array([i]), None)
            observation = _merge(observation, fresh, mask)
        return observation

    def step_async(self, actions: NDArray[Any]) -> None:
        self._actions = np.asarray(actions)

    def step_wait(self) -> tuple[Any, NDArray[np.float32], NDArray[np.bool_], list[dict]]:
        assert self._actions is not None, "step_async() first"
        observation, rewards, terminated, truncated, info = self.venv.step(self._actions)
        every = np.arange(self.num_envs)
        observation, rewards = self.transform(observation, rewards, info, every, self._actions)
        dones = terminated | truncated
        infos = _unbatch(info, self.num_envs)
        for i in range(self.num_envs):
            infos[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
            if dones[i]:
                infos[i]["terminal_observation"] = _row(observation, i)
        finished = np.flatnonzero(dones)
        if len(finished):
            options = [self.episode_options(int(i), None) if dones[i] else {}
                       for i in range(self.num_envs)]
            if all(options[i] == options[finished[0]] for i in finished):
                fresh, reset_info = self.venv.reset(options={**options[finished[0]],
                                                             "reset_mask": dones.copy()})
                fresh, _ = self.transform(fresh, None, reset_info, finished, None)
            else:
                fresh = self._reset_each(finished, options)
            observation = _merge(observation, fresh, dones)
        return observation, rewards.astype(np.float32), dones, infos

    def close(self) -> None:
        self.venv.close()

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        return [getattr(self.venv.unwrapped, attr_name) for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        setattr(self.venv.unwrapped, attr_name, value)

    def env_method(self, method_name: str, *args: Any, indices: Any = None,
                   **kwargs: Any) -> list[Any]:
        method = getattr(self.venv.unwrapped, method_name)
        return [method(*args, **kwargs) for _ in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]


class _SubEnv(gym.Env):
    """What :class:`TraceFollowingObservation` reads of its env, for sub-env ``i`` of a
    batched ``DualLidar-v0``: its config and current trace."""

    def __init__(self, venv: Any, i: int) -> None:
        self._venv, self._i = venv, i
        self.config = venv.config
        self.observation_space = venv.single_observation_space
        self.action_space = venv.single_action_space

    @property
    def trace(self) -> Any:
        return self._venv.trace_of(self._i)


class TraceFollowingVecEnv(SB3VecEnv):
    """The learned driver's observation and reward (:class:`TraceFollowingObservation` with
    ``wrapper_kwargs``) over the batched ``DualLidar-v0`` ``venv``, one wrapper per sub-env."""

    def __init__(self, venv: gym.vector.VectorEnv, **wrapper_kwargs: Any) -> None:
        batched = venv.unwrapped
        self.views = [TraceFollowingObservation(_SubEnv(batched, i), **wrapper_kwargs)
                      for i in range(venv.num_envs)]
        super().__init__(venv, self.views[0].observation_space)
        self._dt = batched.config.control_dt

    def episode_options(self, i: int, seed: int | None) -> dict[str, Any]:
        # TraceFollowingObservation.reset's draws, in its order
        view, options = self.views[i], super().episode_options(i, seed)
        if view.randomize:
            if seed is not None or view._rng is None:
                view._rng = np.random.default_rng(seed)
            options.setdefault("world", view.worlds[view._rng.integers(len(view.worlds))])
            options.setdefault("trace", view.traces[view._rng.integers(len(view.traces))])
        return options

    def transform(self, observation: Any, rewards: NDArray[np.float64] | None,
                  infos: dict[str, Any], envs: NDArray[np.int64],
                  actions: NDArray[Any] | None) -> tuple[Any, NDArray[np.float64] | None]:
        out = np.zeros((self.num_envs, *self.observation_space.shape), np.float32)
        if rewards is not None:
            rewards = rewards.copy()
        for i in envs:
            view = self.views[i]
            info = {key: value[i] for key, value in infos.items() if not key.startswith("_")}
            if rewards is None:  # TraceFollowingObservation.reset
                view.last_action = np.zeros(2, np.float32)
                view._arc = 0.0
            else:  # TraceFollowingObservation.step
                rewards[i] = self._shaped(view, float(rewards[i]), info)
                view.last_action = np.clip(np.asarray(actions[i], np.float32), -1.0, 1.0)
            out[i] = view.observe({key: value[i] for key, value in observation.items()}, info)
        return out, rewards

    def _shaped(self, view: TraceFollowingObservation, reward: float,
                info: dict[str, Any]) -> float:
        """The wrapper's training reward for one sub-env's step."""
        shape_reward = getattr(view, "shape_reward", None)
        if shape_reward is not None:
            return float(shape_reward(reward, info))
        return reward - view.cross_track_weight * abs(info["cross_track_error"]) * self._dt


def _row(observation: Any, i: int) -> Any:
    if isinstance(observation, dict):
        return {key: value[i].copy() for key, value in observation.items()}
    return observation[i].copy()


def _merge(observation: Any, fresh: Any, mask: NDArray[np.bool_]) -> Any:
    """``observation`` with the ``mask`` rows taken from ``fresh`` (``fresh`` if None)."""
    if observation is None:
        return fresh
    if isinstance(observation, dict):
        for key in observation:
            observation[key][mask] = fresh[key][mask]
        return observation
    observation[mask] = fresh[mask]
    return observation


def _unbatch(info: dict[str, Any], n: int) -> list[dict[str, Any]]:
    """Gymnasium's batched infos (``key`` arrays with ``_key`` masks) as one dict per env."""
    infos: list[dict[str, Any]] = [{} for _ in range(n)]
    for key, value in info.items():
        if key.startswith("_"):
            continue
        present = info.get(f"_{key}", np.ones(n, dtype=np.bool_))
        for i in np.flatnonzero(present):
            infos[i][key] = value[i]
    return infos
