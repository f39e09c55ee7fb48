"""Speed of ``render_mode="rgb_array"``: frames/s of the readable frame (``render_size`` 800 px,
scale bar, legend) against a plain 640 px frame without overlays, both
measured in this run on the same env state, in CPU seconds of this process.

Run: ``python benchmarks/bench_render.py [--frames 200]``
"""

from __future__ import annotations

import argparse
import platform
import time

import gymnasium as gym
import numpy as np

import lidar_env  # noqa: F401 - registers DualLidar-v0
from lidar_env.rendering.renderer import Renderer


def frames_per_second(renderer: Renderer, env: gym.Env, frames: int) -> float:
    """CPU frames/s of ``renderer`` drawing the env's current state ``frames`` times."""
    unwrapped = env.unwrapped
    arguments = {
        "car_pose": unwrapped.car.pose, "car_size": (unwrapped.config.car_length,
                                                    unwrapped.config.car_width),
        "sensor_poses": unwrapped._sensor_poses, "scans": unwrapped._last_scans,
        "beam_angles": list(unwrapped.lidar.beam_angles),
        "max_range": [lidar.max_range for lidar in unwrapped.config.lidars],
        "trace": unwrapped.trace.waypoints}
    renderer.draw(**arguments)  # warm-up
    start = time.process_time()
    for _ in range(frames):
        renderer.draw(**arguments)
    return frames / (time.process_time() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=200, help="frames drawn per renderer")
    args = parser.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, {platform.system()}")
    for world in ("hallway", "closed_to_open"):
        env = gym.make("DualLidar-v0", world=world, render_mode="rgb_array")
        env.reset(seed=0)
        for _ in range(5):
            env.step(np.array([1.0, 0.0], dtype=np.float32))
        plain = frames_per_second(Renderer(env.unwrapped.world, 640, overlays=False), env,
                                  args.frames)
        readable = Renderer(env.unwrapped.world)
        fps = frames_per_second(readable, env, args.frames)
        print(f"{world:15s} plain 640 px: {plain:7.1f} frames/s   readable "
              f"{max(readable.shape)} px: {fps:7.1f} frames/s   ratio {fps / plain:.2f}")


if __name__ == "__main__":
    main()
