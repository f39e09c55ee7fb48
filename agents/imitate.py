"""Train the learned driver by imitating the scan-aware expert (DAgger) among pedestrians.

    python -m agents.imitate --seed 0                  # -> runs/imitation_driver.zip
    python -m agents.imitate --seed 0 --out agents/models/ppo_driver.zip --overwrite  # re-ship

The expert is :class:`agents.scan_aware.ScanAwareDriver` (pure pursuit of the trace, braking for
the returns in its corridor); the student is the Stable-Baselines3 PPO ``MlpPolicy`` the
``sb3`` driver loads, fed :class:`agents.observation.TraceFollowingObservation` (both scans
pooled into sectors, the next trace points, the errors, its previous action and, with
``--sector-deltas``, each sector's change since the last frame, which is how a student of the
"backing" expert can see a pedestrian closing in: it sees the pedestrians through the scans
only, never ``info["moving_obstacles"]``). ``--expert`` picks the expert's settings
(:data:`EXPERTS`); the defaults reproduce the shipped model. DAgger (Ross, Gordon
and Bagnell, 2011): iteration 0 drives the expert; every later iteration drives the student as
it now is, and every visited state is labelled with the expert's action, so the student learns
to recover from its own mistakes; after each iteration the policy's mean action is fitted to
all labels so far (mean squared error). PPO's value head is left untrained: the model is a
PPO zip so that ``SB3Driver``, ``PPO.load`` and a later ``python -m agents.train`` fine-tuning
take it as it is.

Episodes cycle through :data:`SCENES` (no movers, and 5, 10 and 15 pedestrians of both mover
models) over the built-in worlds and ``random`` worlds from seeds below 1,000,000 (the
evaluation's ``random`` worlds start there, so they are unseen). Every draw comes from
generators seeded by ``--seed``, and torch runs on one thread, so the same seed gives the same
model on the same machine. A ``.json`` beside the model records the arguments, the time and
each iteration's student statistics.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

import lidar_env  # noqa: F401 - registers DualLidar-v0
from agents.observation import TraceFollowingObservation
from agents.sb3_driver import SHIPPED_MODEL
from agents.scan_aware import ScanAwareDriver
from agents.train import TrainingExistsError, new_model_path
from estimators.arguments import positive_int, seed
from lidar_env.core import ConfigError

DEFAULT_OUT = Path("runs/imitation_driver.zip")
#: (moving_obstacles, mover_model) of the training envs, one env each, stepped in lockstep.
SCENES: tuple[tuple[int, str], ...] = (
    (0, "waypoints"), (5, "yielding"), (10, "yielding"), (15, "yielding"),
    (5, "waypoints"), (10, "waypoints"), (10, "yielding"), (0, "waypoints"))
WORLDS = ("open_cylinders", "hallway", "closed_to_open", "random")
TRACES = ("straight", "right_turn", "zigzag")
#: Settings of the expert by name: "braking" (it only brakes; the shipped model imitates it)
#: and "backing" (:class:`~agents.scan_aware.ScanAwareDriver`'s defaults: it also backs off
#: from a pedestrian closing in; its student needs ``sector_deltas``).
EXPERTS: dict[str, dict[str, Any]] = {
    "braking": {"side_margin": 0.2, "back_off": False},
    "backing": {},
}
#: [s] episode time limit while collecting (the expert waits for pedestrians, but not for ever).
EPISODE_TIME = 60.0


@dataclass(frozen=True)
class IterationStats:
    """What the acting driver did over one iteration's collection."""

    iteration: int
    actor: str  # "expert" or "student"
    steps: int
    episodes: int  # finished (success, collision or time-out) during the collection
    successes: int
    collisions: int
    loss: float  # mean squared error of the student's mean action after the fit
    seconds: float


class _Lane:
    """One env of the lockstep batch: the raw env, the student's view of it and the expert."""

    def __init__(self, moving_obstacles: int, mover_model: str, rng: np.random.Generator,
                 sector_deltas: bool, expert: str = "braking") -> None:
        config = {"moving_obstacles": moving_obstacles, "mover_model": mover_model,
                  "max_episode_time": EPISODE_TIME}
        self.env = gym.make("DualLidar-v0", config=config)
        self.sector_deltas = sector_deltas
        self.view = TraceFollowingObservation(self.env.unwrapped, sector_deltas=sector_deltas)
        self.expert = ScanAwareDriver(**EXPERTS[expert])
        self.rng = rng
        self.features = np.zeros(self.view.observation_space.shape, np.float32)
        self._observation: dict[str, Any] = {}
        self._info: dict[str, Any] = {}

    def reset(self) -> None:
        options = {"world": WORLDS[self.rng.integers(len(WORLDS))],
                   "trace": TRACES[self.rng.integers(len(TRACES))]}
        seed = int(self.rng.integers(1_000_000))
        for _ in range(20):  # a random world too crowded for the movers: draw another seed
            try:
                self._observation, self._info = self.env.reset(seed=seed, options=options)
                break
            except ConfigError:
                seed = int(self.rng.integers(1_000_000))
        self.view = TraceFollowingObservation(  # a fresh view per episode, as SB3Driver's
            self.env.unwrapped, sector_deltas=self.sector_deltas)
        self.expert.reset(self.env)
        self.features = self.view.observe(self._observation, self._info)

    def label(self) -> NDArray[np.float32]:
        """The expert's action for the current state."""
        return self.expert.act(self._observation, self._info)

    def step(self, action: NDArray[np.float32]) -> tuple[bool, bool, bool]:
        """Apply ``action``; (episode over, success, collision), resetting when it is over."""
        self._observation, _, terminated, truncated, self._info = self.env.step(action)
        self.view.last_action = np.clip(np.asarray(action, np.float32), -1.0, 1.0)
        collided = bool(self._info["collision"])
        if terminated or truncated:
            self.reset()
            return True, bool(terminated and not collided), collided
        self.features = self.view.observe(self._observation, self._info)
        return False, False, False


def _student_actions(model: Any, features: NDArray[np.float32]) -> NDArray[np.float32]:
    """The student's deterministic actions (its mean, clipped) for a batch of features."""
    import torch

    with torch.no_grad():
        mean = model.policy.get_distribution(torch.as_tensor(features)).distribution.mean
    return np.clip(mean.numpy(), -1.0, 1.0).astype(np.float32)


def collect(model: Any, lanes: list[_Lane], steps: int, student: bool
            ) -> tuple[NDArray[np.float32], NDArray[np.float32], dict[str, int]]:
    """Step every lane ``steps // len(lanes)`` times with the student (or the expert) acting;
    return the features, the expert's labels and the episode counts."""
    rounds = max(steps // len(lanes), 1)
    features = np.empty((rounds * len(lanes), lanes[0].features.size), np.float32)
    labels = np.empty((rounds * len(lanes), 2), np.float32)
    counts = {"episodes": 0, "successes": 0, "collisions": 0}
    for r in range(rounds):
        batch = np.stack([lane.features for lane in lanes])
        expert = np.stack([lane.label() for lane in lanes])
        actions = _student_actions(model, batch) if student else expert
        features[r * len(lanes):(r + 1) * len(lanes)] = batch
        labels[r * len(lanes):(r + 1) * len(lanes)] = expert
        for lane, action in zip(lanes, actions, strict=True):
            over, success, collided = lane.step(action)
            counts["episodes"] += over
            counts["successes"] += success
            counts["collisions"] += collided
    return features, labels, counts


def fit(model: Any, features: NDArray[np.float32], labels: NDArray[np.float32], epochs: int,
        batch_size: int, learning_rate: float, generator: Any) -> float:
    """Fit the policy's mean action to ``labels`` (MSE, Adam); the last epoch's mean loss."""
    import torch

    policy = model.policy
    parameters = [*policy.mlp_extractor.policy_net.parameters(),
                  *policy.action_net.parameters()]
    if policy.features_extractor is not None:
        parameters += list(policy.features_extractor.parameters())
    optimizer = torch.optim.Adam(parameters, lr=learning_rate)
    x, y = torch.as_tensor(features), torch.as_tensor(labels)
    loss_sum, batches = 0.0, 0
    for _ in range(epochs):
        order = torch.randperm(len(x), generator=generator)
        loss_sum, batches = 0.0, 0
        for start in range(0, len(x), batch_size):
            index = order[start:start + batch_size]
            mean = policy.get_distribution(x[index]).distribution.mean
            loss = torch.mean((mean - y[index]) ** 2)
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            loss_sum, batches = loss_sum + loss.item(), batches + 1
    return loss_sum / max(batches, 1)


def imitate(
    seed: int = 0, out: Path = DEFAULT_OUT, iterations: int = 10, steps: int = 30_000,
    epochs: int = 4, batch_size: int = 256, learning_rate: float = 1e-3,
    net_arch: tuple[int, ...] = (64, 64), log_std: float = -2.0, overwrite: bool = False,
    sector_deltas: bool = False, expert: str = "braking",
) -> Path:
    """Run DAgger (see the module docstring) and save the student as a PPO zip to ``out``.

    Raises :class:`agents.train.TrainingExistsError` before any work when ``out`` exists and
    ``overwrite`` is False.
    """
    out = new_model_path(out, overwrite)
    import torch
    from stable_baselines3 import PPO

    torch.set_num_threads(1)
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    if expert not in EXPERTS:
        raise ConfigError(f"expert: expected one of {', '.join(sorted(EXPERTS))}, got "
                          f"{expert!r}")
    lanes = [_Lane(m, model, np.random.default_rng([seed, k]), sector_deltas, expert)
             for k, (m, model) in enumerate(SCENES)]
    for lane in lanes:
        lane.reset()
    env = TraceFollowingObservation(gym.make("DualLidar-v0"), sector_deltas=sector_deltas)
    model = PPO("MlpPolicy", env, seed=seed, device="cpu",
                policy_kwargs={"net_arch": {"pi": list(net_arch), "vf": [64, 64]}})
    with torch.no_grad():
        model.policy.log_std.fill_(log_std)  # a calm policy if PPO fine-tunes it later
    generator = torch.Generator().manual_seed(int(rng.integers(2**31)))
    features = np.zeros((0, lanes[0].features.size), np.float32)
    labels = np.zeros((0, 2), np.float32)
    history: list[IterationStats] = []
    start = time.perf_counter()
    for iteration in range(iterations):
        began = time.perf_counter()
        student = iteration > 0
        new_features, new_labels, counts = collect(model, lanes, steps, student)
        features = np.concatenate([features, new_features])
        labels = np.concatenate([labels, new_labels])
        loss = fit(model, features, labels, epochs, batch_size, learning_rate, generator)
        stats = IterationStats(iteration, "student" if student else "expert", len(new_labels),
                               loss=loss, seconds=time.perf_counter() - began, **counts)
        history.append(stats)
        print(f"iteration {iteration}: {stats.actor} drove {stats.steps} steps, "
              f"{stats.successes}/{stats.episodes} episodes finished, {stats.collisions} "
              f"collisions; fit on {len(labels)} labels, loss {loss:.4f} "
              f"({stats.seconds:.0f} s)", flush=True)
    elapsed = time.perf_counter() - start
    out.parent.mkdir(parents=True, exist_ok=True)
    model.save(out)
    record = {"command": {"seed": seed, "iterations": iterations, "steps": steps,
                          "epochs": epochs, "batch_size": batch_size,
                          "learning_rate": learning_rate, "net_arch": list(net_arch),
                          "log_std": log_std, "sector_deltas": sector_deltas,
                          "expert": expert},
              "scenes": [list(scene) for scene in SCENES],
              "expert": {key: getattr(lanes[0].expert, key) for key in (
                  "side_margin", "stop_gap", "headway", "reach", "back_off")},
              "wall_seconds": elapsed, "iterations": [asdict(s) for s in history]}
    out.with_suffix(".json").write_text(json.dumps(record, indent=1) + "\n")
    print(f"imitated for {elapsed / 60:.1f} min ({elapsed:.1f} s); saved {out}")
    return out


def build_parser(prog: str = "python -m agents.imitate") -> argparse.ArgumentParser:
    """The command line's parser (``duallidar imitate`` is the same command)."""
    parser = argparse.ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--seed", type=seed, default=0,
                        help="seed of every draw (scenes, worlds, torch)")
    parser.add_argument("--iterations", type=positive_int, default=10, help="DAgger iterations")
    parser.add_argument("--steps", type=positive_int, default=30_000,
                        help="env steps per iteration")
    parser.add_argument("--epochs", type=positive_int, default=4,
                        help="passes over all labels per fit")
    parser.add_argument("--net-arch", type=positive_int, nargs="+", default=[64, 64],
                        metavar="UNITS", help="hidden layers of the policy")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT,
                        help=f"model .zip (the shipped one is {SHIPPED_MODEL})")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    parser.add_argument("--sector-deltas", action="store_true",
                        help="add each sector's change since the last frame to the input")
    parser.add_argument("--expert", choices=sorted(EXPERTS), default="braking",
                        help="the expert's settings (braking: the shipped model's)")
    return parser


def main(argv: list[str] | None = None, prog: str = "python -m agents.imitate") -> int:
    """Imitate from the command line; returns the exit status (2 for bad input)."""
    parser = build_parser(prog)
    args = parser.parse_args(argv)
    try:
        new_model_path(args.out, args.overwrite)
    except TrainingExistsError as error:
        parser.error(f"--out: {error}")
    imitate(args.seed, args.out, args.iterations, args.steps, args.epochs,
            net_arch=tuple(args.net_arch), overwrite=args.overwrite,
            sector_deltas=args.sector_deltas, expert=args.expert)
    return 0


if __name__ == "__main__":
    sys.exit(main())
