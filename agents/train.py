"""Train a PPO trace-following driver from scratch (reinforcement learning).

    python -m agents.train --seed 0                  # -> runs/ppo_driver.zip
    duallidar train --seed 0                         # the same

The shipped model (``agents/models/ppo_driver.zip``) does not come from here: it is imitated
from the scan-aware driver by :mod:`agents.imitate` and gives way to pedestrians, which PPO
from scratch does not learn within this budget. This script trains a trace follower (no
movers) for reinforcement-learning experiments.

The default output is ``runs/ppo_driver.zip``, never the shipped model; an existing file is
only replaced with ``--overwrite``. A progress bar (steps, steps/s, time left) is printed to
stderr while it trains. Hyperparameters come from ``agents/ppo_driver.yaml`` (rl-zoo3
layout); ``--timesteps`` and ``--n-envs`` override it. Every episode draws its world (the
built-in ones and ``random``) and trace seed, so the policy is not fitted to one scenario; the
evaluation callback scores it on a fixed, seeded set of episodes and keeps the best model.

The training envs are stepped batched (``--vectorization batched``: the batched
``DualLidar-v0`` through :class:`agents.vec_adapter.TraceFollowingVecEnv`) or one by one
(``single``: SB3's ``DummyVecEnv`` over wrapped single envs); both give the same observations
and rewards, so the same seed trains the same model. The default, ``auto``, steps them batched
(moving obstacles included) unless the env config holds something the batched env does not
simulate yet (a self-occluded Lidar).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import yaml

import lidar_env  # noqa: F401 - registers DualLidar-v0
from agents.observation import TraceFollowingObservation
from agents.sb3_driver import SHIPPED_MODEL
from estimators.arguments import positive_int, seed
from lidar_env.core import ConfigError

HYPERPARAMETERS = Path(__file__).with_name("ppo_driver.yaml")
DEFAULT_OUT = Path("runs/ppo_driver.zip")

#: How the training envs are stepped: the batched env, one single env after another, or the
#: batched env whenever it can run the config.
VECTORIZATIONS: tuple[str, ...] = ("auto", "batched", "single")


class TrainingExistsError(FileExistsError):
    """``--out`` names a model that exists and ``overwrite`` was not given."""


def new_model_path(out: str | Path, overwrite: bool) -> Path:
    """``out`` as a path, or :class:`TrainingExistsError` if a model is there and ``overwrite``
    is False: checked before any work, so a run never replaces a model (the shipped one) by
    accident."""
    out = Path(out)
    if out.exists() and not overwrite:
        raise TrainingExistsError(
            f"out: {out} exists; pass overwrite=True (--overwrite) to replace it"
        )
    return out


def load_hyperparameters(path: Path = HYPERPARAMETERS) -> dict[str, Any]:
    """The ``DualLidar-v0`` entry of an rl-zoo3-style YAML file; :class:`ConfigError` for a
    file that is not YAML or holds no such mapping."""
    with open(path) as handle:
        try:
            document = yaml.safe_load(handle)
        except yaml.YAMLError as error:
            raise ConfigError(f"{path}: not valid YAML ({str(error).splitlines()[0]})") from None
    entry = document.get("DualLidar-v0") if isinstance(document, dict) else None
    if not isinstance(entry, dict):
        raise ConfigError(f"{path}: expected a mapping with a 'DualLidar-v0' entry of "
                          "hyperparameters (rl-zoo3 layout)")
    return dict(entry)


def make_training_env(
    config: dict[str, Any] | None = None, wrapper: dict[str, Any] | None = None
) -> gym.Env:
    """One randomised, wrapped ``DualLidar-v0`` as the policy sees it."""
    env = gym.make("DualLidar-v0", config=config or {})
    return TraceFollowingObservation(env, randomize=True, **(wrapper or {}))


def make_training_vec_env(
    n_envs: int,
    seed: int,
    config: dict[str, Any] | None = None,
    wrapper: dict[str, Any] | None = None,
    vectorization: str = "auto",
) -> Any:
    """``n_envs`` randomised, wrapped ``DualLidar-v0`` as an SB3 ``VecEnv`` with episode
    statistics, seeded ``seed``, ``seed + 1``, ...: batched, or SB3's ``DummyVecEnv`` of
    single envs (the same observations and rewards)."""
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import VecMonitor

    if vectorization not in VECTORIZATIONS:
        raise ConfigError(f"vectorization: expected one of {', '.join(VECTORIZATIONS)}, got "
                         f"{vectorization!r}")
    if vectorization == "auto":
        from lidar_env.config import EnvConfig
        from lidar_env.vector import not_batched

        batchable = not_batched(EnvConfig.from_dict(config)) is None
        vectorization = "batched" if batchable else "single"
    if vectorization == "single":
        return make_vec_env(make_training_env, n_envs, seed=seed,
                            env_kwargs={"config": config, "wrapper": wrapper})
    from agents.vec_adapter import TraceFollowingVecEnv

    venv = gym.make_vec("DualLidar-v0", n_envs, vectorization_mode="vector_entry_point",
                        config=config or {})
    vec_env = VecMonitor(TraceFollowingVecEnv(venv, randomize=True, **(wrapper or {})))
    vec_env.seed(seed)
    return vec_env


def train(
    timesteps: int | None = None,
    seed: int = 0,
    out: Path = DEFAULT_OUT,
    n_envs: int | None = None,
    tensorboard: Path | None = None,
    eval_episodes: int = 12,
    torch_threads: int = 1,
    hyperparameters: Path = HYPERPARAMETERS,
    overwrite: bool = False,
    progress: bool = True,
    vectorization: str = "auto",
) -> Path:
    """Train PPO and save the best evaluated model to ``out`` (a .zip); return its path.

    Raises :class:`TrainingExistsError` before any training when ``out`` exists and
    ``overwrite`` is False, so a run never replaces the shipped model by accident.
    """
    for name, value in (("timesteps", timesteps), ("n_envs", n_envs)):
        if value is not None and value < 1:
            raise ConfigError(f"{name}: expected an integer >= 1 or None, got {value}")
    out = new_model_path(out, overwrite)
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import EvalCallback
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.logger import Logger
    from stable_baselines3.common.vec_env import DummyVecEnv, VecMonitor, VecNormalize

    torch.set_num_threads(torch_threads)  # small MLP: more threads only add contention
    params = load_hyperparameters(hyperparameters)
    total = int(timesteps or params.pop("n_timesteps"))
    params.pop("n_timesteps", None)
    env_config = params.pop("env_kwargs", {})
    wrapper_kwargs = params.pop("wrapper_kwargs", {})
    normalize = params.pop("normalize", False)
    n_envs = int(n_envs or params.pop("n_envs"))
    params.pop("n_envs", None)
    policy = params.pop("policy")

    env_kwargs = {"config": env_config, "wrapper": wrapper_kwargs}
    vec_env = make_training_vec_env(n_envs, seed, env_config, wrapper_kwargs, vectorization)
    if isinstance(vec_env, VecMonitor):  # the type EvalCallback expects, with the statistics
        eval_env = VecMonitor(DummyVecEnv([lambda: make_training_env(**env_kwargs)]))
        eval_env.seed(seed + 10_000)
    else:
        eval_env = make_vec_env(make_training_env, 1, seed=seed + 10_000, env_kwargs=env_kwargs)
    if normalize:
        vec_env = VecNormalize(vec_env)
        eval_env = VecNormalize(eval_env, training=False, norm_reward=False)
    out.parent.mkdir(parents=True, exist_ok=True)
    best_dir = out.parent / f"{out.stem}_best"
    callback = EvalCallback(
        eval_env,
        n_eval_episodes=eval_episodes,
        eval_freq=max(20_000 // n_envs, 1),
        best_model_save_path=str(best_dir),
        deterministic=True,
        verbose=0,
    )
    model = PPO(
        policy, vec_env, seed=seed, device="cpu", verbose=0,
        tensorboard_log=str(tensorboard) if tensorboard else None, **params,
    )
    if not tensorboard:  # SB3's default logger makes an empty folder in /tmp per run
        model.set_logger(Logger(folder=None, output_formats=[]))
    start = time.perf_counter()
    callbacks = [callback, _progress_callback(total)] if progress else [callback]
    model.learn(total_timesteps=total, callback=callbacks, progress_bar=False)
    elapsed = time.perf_counter() - start
    best = best_dir / "best_model.zip"
    final = PPO.load(best, device="cpu") if best.is_file() else model
    final.save(out)
    if normalize:
        vec_env.save(str(out.with_suffix(".vecnormalize.pkl")))
    print(f"trained {total} steps in {elapsed / 60:.1f} min ({elapsed:.1f} s); saved {out}")
    return out


def _progress_callback(total: int) -> Any:
    """An SB3 callback drawing a tqdm bar over ``total`` env steps, built here because SB3 is
    an optional import (SB3's own ``progress_bar=True`` needs rich, which we do not install)."""
    from stable_baselines3.common.callbacks import BaseCallback
    from tqdm import tqdm

    class ProgressBar(BaseCallback):
        def _on_training_start(self) -> None:
            self.bar = tqdm(total=total, unit="step", desc="training", smoothing=0.05)

        def _on_step(self) -> bool:
            self.bar.n = min(self.num_timesteps, total)
            self.bar.refresh()
            return True

        def _on_training_end(self) -> None:
            self.bar.close()

    return ProgressBar()


def build_parser(prog: str = "python -m agents.train") -> argparse.ArgumentParser:
    """The command line's parser (``duallidar train`` is the same command)."""
    parser = argparse.ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--timesteps", type=positive_int, default=None,
                        help="env steps to train; None: n_timesteps of --hyperparameters")
    parser.add_argument("--n-envs", type=positive_int, default=None,
                        help="envs stepped together; None: n_envs of --hyperparameters")
    parser.add_argument("--seed", type=seed, default=0, help="seed of the envs and PPO")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT,
                        help=f"model .zip (the shipped one is {SHIPPED_MODEL})")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--vectorization", choices=VECTORIZATIONS, default="auto",
                        help="step the training envs batched or one by one (auto: batched "
                             "when the env config allows)")
    parser.add_argument("--tensorboard", type=Path, default=None,
                        help="TensorBoard log dir; None: no log")
    parser.add_argument("--hyperparameters", type=Path, default=HYPERPARAMETERS,
                        help="rl-zoo3-style YAML with a DualLidar-v0 entry")
    return parser


def main(argv: list[str] | None = None, prog: str = "python -m agents.train") -> int:
    """Train from the command line; returns the exit status (2 for bad input)."""
    parser = build_parser(prog)
    args = parser.parse_args(argv)
    try:
        new_model_path(args.out, args.overwrite)
        params = load_hyperparameters(args.hyperparameters)
        for key in ("n_timesteps", "n_envs", "policy"):
            if key not in params:
                raise ConfigError(f"{args.hyperparameters}: expected the DualLidar-v0 entry to "
                                  f"hold {key!r}")
    except TrainingExistsError as error:
        parser.error(f"--out: {error}")
    except (ConfigError, OSError) as error:
        parser.error(f"--hyperparameters: {error}")
    train(args.timesteps, args.seed, args.out, args.n_envs, args.tensorboard,
          hyperparameters=args.hyperparameters, overwrite=args.overwrite,
          progress=not args.no_progress, vectorization=args.vectorization)
    return 0


if __name__ == "__main__":
    sys.exit(main())
