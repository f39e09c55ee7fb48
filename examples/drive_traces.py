"""Drive every trace seed through every built-in world with the scripted driver.

For each (world, trace) episode it prints the trace length, the simulated time, steps, final
progress, the worst and mean cross-track error, whether the car collided, the return and the
wall-clock speed; then it writes one PNG with the last frame of every episode (obstacles,
trace, the driven path, the car and both Lidars' hits).

Run: ``python examples/drive_traces.py --out drive_traces.png``
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

import lidar_env  # noqa: F401 - registers DualLidar-v0
from agents import PurePursuitDriver
from lidar_env.rendering import tile_frames, write_png
from lidar_env.traces import TRACE_NAMES
from lidar_env.worlds import WORLD_NAMES


def drive_episode(world: str, trace: str, seed: int) -> tuple[dict[str, float], np.ndarray]:
    """One scripted episode: its figures and its last rendered frame."""
    env = gym.make("DualLidar-v0", world=world, trace=trace, render_mode="rgb_array")
    driver = PurePursuitDriver()
    observation, info = env.reset(seed=seed)
    driver.reset(env)
    poses, errors, total = [info["pose"]], [], 0.0
    started = time.perf_counter()
    while True:
        observation, reward, terminated, truncated, info = env.step(driver.act(observation, info))
        poses.append(info["pose"])
        errors.append(abs(info["cross_track_error"]))
        total += reward
        if terminated or truncated:
            break
    elapsed = time.perf_counter() - started
    env.unwrapped.set_render_trajectories({"driven": np.array(poses)})
    frame = env.render()
    env.close()
    figures = {
        "length_m": env.unwrapped.trace.length,
        "time_s": info["time"],
        "steps": len(errors),
        "progress": info["progress"],
        "max_cte_m": max(errors),
        "mean_cte_m": float(np.mean(errors)),
        "collision": info["collision"],
        "return": total,
        "steps_per_s": len(errors) / elapsed,
    }
    return figures, frame


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("drive_traces.png"),
                        help="PNG to write (default: drive_traces.png)")
    parser.add_argument("--seed", type=int, default=0, help="reset seed (noise, random world)")
    parser.add_argument("--worlds", nargs="+", default=list(WORLD_NAMES), choices=WORLD_NAMES,
                        help="worlds to drive (default: all)")
    args = parser.parse_args()
    print(f"{'world':<15}{'trace':<13}{'length m':>9}{'time s':>8}{'steps':>6}{'progress':>9}"
          f"{'max cte m':>10}{'mean cte m':>11}{'collision':>10}{'return':>8}{'steps/s':>9}")
    frames, failures = [], 0
    for world in args.worlds:
        for trace in TRACE_NAMES:
            figures, frame = drive_episode(world, trace, args.seed)
            frames.append(frame)
            failures += bool(figures["collision"]) or figures["progress"] < 0.98
            print(f"{world:<15}{trace:<13}{figures['length_m']:>9.2f}{figures['time_s']:>8.1f}"
                  f"{figures['steps']:>6d}{figures['progress']:>9.3f}{figures['max_cte_m']:>10.3f}"
                  f"{figures['mean_cte_m']:>11.4f}{figures['collision']!s:>10}"
                  f"{figures['return']:>8.2f}{figures['steps_per_s']:>9.0f}")
    write_png(args.out, tile_frames(frames, columns=len(TRACE_NAMES)))
    print(f"wrote {args.out} (rows: {', '.join(args.worlds)}; columns: {', '.join(TRACE_NAMES)})")
    if failures:
        raise SystemExit(f"{failures} episode(s) collided or stopped short of the trace's end")


if __name__ == "__main__":
    main()
