"""SHA-256 fingerprints of what a refactor must not change: the observations and rewards of three
default drives (one among walkers), 40 steps of the batched env, and every registered estimator's
trajectory on those drives (the phase-correlation family on the hallway drive only).

    python scripts/fingerprint.py before.json      # on the old code
    python scripts/fingerprint.py after.json       # on the new code; the two files must agree
"""

from __future__ import annotations

import hashlib
import json
import sys

import gymnasium as gym
import numpy as np

import estimators
import lidar_env  # noqa: F401  (registers DualLidar-v0)
from agents import PurePursuitDriver

DRIVES = (("hallway", "zigzag", 1, {"moving_obstacles": 3}),
          ("open_cylinders", "right_turn", 0, {}),
          ("closed_to_open", "straight", 0, {}))


def digest(*arrays: object) -> str:
    """The first 16 hex digits of the SHA-256 of ``arrays`` as float64 bytes."""
    sha = hashlib.sha256()
    for array in arrays:
        sha.update(np.ascontiguousarray(np.asarray(array, dtype=np.float64)).tobytes())
    return sha.hexdigest()[:16]


def main(out: str) -> None:
    found, drives = {}, {}
    for world, trace, seed, config in DRIVES:
        env = gym.make("DualLidar-v0", world=world, trace=trace, config=config or None)
        observation, info = env.reset(seed=seed)
        driver = PurePursuitDriver()
        driver.reset(env)
        setup = estimators.SensorSetup.from_env(env)
        steps, rewards, done = [(observation, info["time"], info["pose"])], [], False
        while not done:
            observation, reward, terminated, truncated, info = env.step(
                driver.act(observation, info))
            rewards.append(reward)
            steps.append((observation, info["time"], info["pose"]))
            done = terminated or truncated
        key = f"{world}/{trace}/s{seed}"
        found[f"{key}/obs"] = digest(*[o[k] for o, _, _ in steps for k in sorted(o)])
        found[f"{key}/rewards"] = digest(rewards)
        drives[key] = (setup, steps)
        env.close()
    vector = gym.make_vec("DualLidar-v0", num_envs=3, vectorization_mode="vector_entry_point",
                          world="hallway", trace="zigzag")
    observations, _ = vector.reset(seed=5)
    seen = [observations[k] for k in sorted(observations)]
    for _ in range(40):
        observations, rewards_, *_ = vector.step(np.tile([[0.5, 0.1]], (3, 1)).astype(np.float32))
        seen += [observations[k] for k in sorted(observations)] + [rewards_]
    found["vector"] = digest(*seen)
    for name in estimators.names():
        for key, (setup, steps) in drives.items():
            if name.startswith("pc") and key != "hallway/zigzag/s1":
                continue
            estimator = estimators.make(name)
            estimator.reset(setup, initial_pose=steps[0][2])
            for observation, t, _ in steps:
                estimator.update(observation, t)
            found[f"{name}@{key}"] = digest(estimator.trajectory)
    with open(out, "w") as file:
        json.dump(found, file, indent=1, sort_keys=True)
    print(json.dumps(found, indent=1, sort_keys=True))


if __name__ == "__main__":
    if len(sys.argv) != 2:
        raise SystemExit(__doc__)
    main(sys.argv[1])
