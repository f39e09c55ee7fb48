"""Drive every trace seed through every built-in world with the scripted driver.

For each (world, trace) episode it prints the trace length, the simulated time, steps, final
progress, the worst and mean cross-track error, whether the car collided, the return and the
wall-clock speed; then it writes one picture of every episode (a PNG and an SVG copy; rows:
worlds, columns: trace seeds): obstacles, the trace, the driven path, the car's last pose and
both Lidars' hits from there, with a 5 m scale bar in every panel. Needs matplotlib
(``pip install 'duallidar[plots]'``).

Run: ``python examples/drive_traces.py --out drive_traces.png``
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import lidar_env  # noqa: F401 - registers DualLidar-v0
from agents import PurePursuitDriver
from estimators.base import SensorSetup
from lidar_env.routes.traces import TRACE_NAMES
from lidar_env.world.built_in import WORLD_NAMES

#: Length of the scale bar in every panel [m].
SCALE_BAR = 5.0


def lidar_hits(observation: dict[str, Any], setup: SensorSetup,
               lidar_poses: np.ndarray) -> np.ndarray:
    """World-frame points [m] (P, 2) of every beam of every Lidar that hit something."""
    points = []
    for key, (x, y, heading) in zip(setup.keys, np.asarray(lidar_poses), strict=True):
        ranges = np.asarray(observation[key], dtype=np.float64)
        hit = ranges < setup.max_range
        angles = heading + setup.beam_angles[hit]
        points.append(np.stack([x + ranges[hit] * np.cos(angles),
                                y + ranges[hit] * np.sin(angles)], axis=1))
    return np.concatenate(points)


def drive_episode(world: str, trace: str, seed: int) -> tuple[dict[str, float], dict[str, Any]]:
    """One scripted episode: its figures and what the picture shows of it (the world, the
    trace's waypoints, the driven poses and the last Lidar hits, world frame [m])."""
    env = gym.make("DualLidar-v0", world=world, trace=trace)
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
    drawn = {"world": env.unwrapped.world, "waypoints": env.unwrapped.trace.waypoints,
             "poses": np.array(poses),
             "hits": lidar_hits(observation, SensorSetup.from_env(env), info["lidar_poses"])}
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
    return figures, drawn


def draw_episodes(episodes: dict[tuple[str, str], dict[str, Any]], worlds: list[str],
                  path: Path) -> None:
    """The picture: one panel per episode, rows = worlds, columns = trace seeds; PNG at 200
    dpi and an SVG beside it."""
    from matplotlib.figure import Figure
    from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

    from estimators.leaderboard.style import figure_title, save_figure
    from estimators.leaderboard.trace_drawing import draw_obstacles

    figure = Figure(figsize=(3.2 * len(TRACE_NAMES) + 1.5, 3.0 * len(worlds) + 0.8),
                    layout="constrained")
    grid = figure.subplots(len(worlds), len(TRACE_NAMES), squeeze=False)
    for row, world in enumerate(worlds):
        for column, trace in enumerate(TRACE_NAMES):
            axes, drawn = grid[row][column], episodes[(world, trace)]
            draw_obstacles(axes, drawn["world"])
            axes.plot(*drawn["hits"].T, ".", color="#d62728", markersize=1.5,
                      label="last scans' hits (both Lidars)")
            axes.plot(*drawn["waypoints"].T, "--", color="#7f7f7f", linewidth=1.0,
                      label="trace")
            axes.plot(*drawn["poses"][:, :2].T, "-", color="#1f77b4", linewidth=1.4,
                      label="driven path")
            axes.plot(*drawn["poses"][-1, :2], "o", color="black", markersize=4,
                      label="car at the end")
            axes.add_artist(AnchoredSizeBar(axes.transData, SCALE_BAR, f"{SCALE_BAR:g} m",
                                            "lower right", frameon=True, size_vertical=0.15))
            axes.set(aspect="equal", xticks=[], yticks=[])
            if row == 0:
                axes.set_title(f"trace seed: {trace}", fontsize="medium")
            if column == 0:
                axes.set_ylabel(f"world: {world}", fontsize="medium")
    handles, labels = grid[0][0].get_legend_handles_labels()
    figure.legend(handles, labels, loc="outside lower center", ncols=len(labels),
                  markerscale=4)
    figure_title(figure, "Every trace seed driven by the scripted pure-pursuit driver in every "
                         "world (light fill: obstacles)")
    save_figure(figure, path)


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
    episodes, failures = {}, 0
    for world in args.worlds:
        for trace in TRACE_NAMES:
            figures, episodes[(world, trace)] = drive_episode(world, trace, args.seed)
            failures += bool(figures["collision"]) or figures["progress"] < 0.98
            print(f"{world:<15}{trace:<13}{figures['length_m']:>9.2f}{figures['time_s']:>8.1f}"
                  f"{figures['steps']:>6d}{figures['progress']:>9.3f}{figures['max_cte_m']:>10.3f}"
                  f"{figures['mean_cte_m']:>11.4f}{figures['collision']!s:>10}"
                  f"{figures['return']:>8.2f}{figures['steps_per_s']:>9.0f}")
    draw_episodes(episodes, args.worlds, args.out)
    print(f"wrote {args.out} and its .svg (rows: {', '.join(args.worlds)}; columns: "
          f"{', '.join(TRACE_NAMES)})")
    if failures:
        raise SystemExit(f"{failures} episode(s) collided or stopped short of the trace's end")


if __name__ == "__main__":
    main()
