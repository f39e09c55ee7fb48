"""Short-range Lidars in big spaces: a TurtleBot3 whose 3.5 m LDS-01 sees a few pillars or shelves.

A 360-beam, 1-degree, 3.5 m Lidar at 5 Hz in a hall 20-30 m across sees none of the walls
from the middle, only the posts within 3.5 m: often two or three pillars of 0.2-0.3 m (a
handful of returns each), sometimes one. This benchmark builds such halls from a seed and
drives them with the TurtleBot3 presets (``lidar_env.vehicle.presets``, ``docs/robots.md``)
along waypoint routes with 90-degree corners, then replays each drive through each
estimator, ``icp`` (scan-to-previous-scan) being the reference measured in the same run:

* **halls** (``hall_*``): four walls, structural pillars (radius 0.1-0.15 m) on a grid of
  ``spacing`` [m], each moved up to 0.3 m and one in ten left out, four 2.4 x 0.6 m shelf
  units and six 0.1 m posts placed at random away from the route, all from the seed; the route
  runs along the aisles midway between pillar rows, serpentine, so every leg is ``spacing / 2``
  from the nearest row. At 3.5 m spacing two or more pillars are in range everywhere; at 4.5 m
  stretches see one.
* **depots** (``depot_*``): rows of solid 4 m x 1 m shelf units end to end (0-10 cm apart),
  2.5 m aisles between them: down an aisle the Lidar sees two long, nearly featureless faces.
* **drivers**: pure pursuit at the robot's top speed (``PurePursuitDriver``), or
  turn-in-place at corners (:class:`TurnInPlaceDriver`: it stops 0.3 m before each corner and
  turns on the spot at 1 rad/s onto the next leg, as a ROS navigation stack's rotation shim
  does), so the speed drops to zero at each corner.

Per drive and estimator: ATE [m] (RMSE of position, the estimate starting at the true start
pose), drift [% of the path] (final position error over the distance driven), the share of
relations ~1 s apart (each scan paired with the first at least 1 s later) off by more than
0.2 m, and the CPU time per scan; the ratios of ATE and drift to ``icp``'s. Per drive: the
scans' median number of returns and the share with fewer than
``estimators.health.MIN_RETURNS`` (which an estimator skips as unusable). Target (issue 40):
``lidar_odometry`` drift <= 1 %.

    python benchmarks/bench_sparse_halls.py [--drives hall_20x15_burger ...]
        [--estimators icp lidar_odometry slam] [--quick] [--maps DIR] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

import estimators
import lidar_env  # noqa: F401  (registers DualLidar-v0)
from agents.scripted import PurePursuitDriver
from estimators.base import SensorSetup
from estimators.evaluation.metrics import evaluate
from estimators.evaluation.relations import match_times, relations_from_trajectory
from estimators.health import MIN_RETURNS
from lidar_env.core.se2 import relative
from lidar_env.world import World, save_ros_map

REFERENCE = "icp"
FAILURE = 0.2  # [m] a relation off by more than this is a failure
WINDOW = 1.0  # [s] relations pair each scan with the first this much later
ROUTE_CLEARANCE = 0.6  # [m] shelves and loose posts keep this far from the route
MAP_RESOLUTION = 0.05  # [m/px] of the ROS maps --maps writes


@dataclass(frozen=True)
class Drive:
    """One drive: a ``layout`` ("hall" or "depot") of ``width`` x ``height`` [m] from ``seed``,
    pillars ``spacing`` [m] apart (halls), the TurtleBot3 ``robot`` preset, turning in place
    at corners when ``turn_in_place``."""

    layout: str
    width: float
    height: float
    seed: int
    robot: str
    spacing: float = 4.0
    turn_in_place: bool = False


DRIVES: dict[str, Drive] = {
    "hall_20x15_burger": Drive("hall", 20.0, 15.0, 0, "turtlebot3_burger", 3.5),
    "hall_20x15_waffle_turns": Drive("hall", 20.0, 15.0, 1, "turtlebot3_waffle_pi", 3.5,
                                     turn_in_place=True),
    "hall_30x20_burger_turns": Drive("hall", 30.0, 20.0, 0, "turtlebot3_burger", 4.5,
                                     turn_in_place=True),
    "hall_30x20_waffle": Drive("hall", 30.0, 20.0, 1, "turtlebot3_waffle_pi", 4.5),
    "depot_30x15_burger_turns": Drive("depot", 30.0, 15.0, 0, "turtlebot3_burger",
                                      turn_in_place=True),
    "depot_30x15_waffle": Drive("depot", 30.0, 15.0, 1, "turtlebot3_waffle_pi"),
}
#: One small hall, for a smoke run (``--quick``) and the test.
QUICK = {"hall_12x9_burger_turns": Drive("hall", 12.0, 9.0, 0, "turtlebot3_burger", 3.0,
                                           turn_in_place=True)}


def distance_to_route(point: NDArray[np.float64], route: NDArray[np.float64]) -> float:
    """Distance [m] from ``point`` (2,) to the polyline ``route`` (K, 2)."""
    starts, ends = route[:-1], route[1:]
    along = ends - starts
    share = np.clip(np.einsum("ij,ij->i", point - starts, along)
                    / np.einsum("ij,ij->i", along, along), 0.0, 1.0)
    return float(np.min(np.hypot(*(starts + share[:, None] * along - point).T)))


def box(centre: NDArray[np.float64], length: float, depth: float) -> NDArray[np.float64]:
    """The (4, 2) corners of a ``length`` x ``depth`` [m] box along x around ``centre``."""
    return centre + 0.5 * np.array([[-length, -depth], [length, -depth], [length, depth],
                                    [-length, depth]])


def outline(corners: NDArray[np.float64], per_side: int = 12) -> NDArray[np.float64]:
    """Points along a polygon's sides, for clearance checks."""
    return np.concatenate([np.linspace(corners[k], corners[(k + 1) % len(corners)], per_side)
                           for k in range(len(corners))])


def serpentine(xs: NDArray[np.float64], ys: NDArray[np.float64]) -> NDArray[np.float64]:
    """Waypoints along the rows ``ys`` from ``xs[0]`` to ``xs[-1]``, alternating direction:
    every corner 90 degrees."""
    route = []
    for row, y in enumerate(ys):
        ends = (xs[0], xs[-1]) if row % 2 == 0 else (xs[-1], xs[0])
        route += [[ends[0], y], [ends[1], y]]
    return np.array(route)


def walls(width: float, height: float) -> list[list[float]]:
    return [[0, 0, width, 0], [width, 0, width, height], [width, height, 0, height],
            [0, height, 0, 0]]


def hall_layout(drive: Drive) -> tuple[World, NDArray[np.float64]]:
    """A hall of pillars on a grid, a few shelf units and loose posts, and its route."""
    rng = np.random.default_rng(drive.seed)
    s = drive.spacing
    columns, rows = int(drive.width // s), int(drive.height // s)
    xs = (drive.width - (columns - 1) * s) / 2 + s * np.arange(columns)
    ys = (drive.height - (rows - 1) * s) / 2 + s * np.arange(rows)
    route = serpentine((xs[:-1] + xs[1:]) / 2, (ys[:-1] + ys[1:]) / 2)
    circles = [[x + rng.uniform(-0.3, 0.3), y + rng.uniform(-0.3, 0.3), rng.uniform(0.1, 0.15)]
               for x in xs for y in ys if rng.random() >= 0.1]
    pillars = np.array(circles)
    shelves: list[NDArray[np.float64]] = []
    posts: list[list[float]] = []
    for _ in range(2000):
        if len(shelves) < 4:
            length, depth = (2.4, 0.6) if rng.random() < 0.5 else (0.6, 2.4)
            corners = box(rng.uniform([1.0, 1.0], [drive.width - 1, drive.height - 1]),
                          length, depth)
            edge = outline(corners)
            apart = np.hypot(edge[:, None, 0] - pillars[None, :, 0],
                             edge[:, None, 1] - pillars[None, :, 1]) - pillars[None, :, 2]
            if min(distance_to_route(p, route) for p in edge) > ROUTE_CLEARANCE and (
                    apart.min() > 0.5):
                shelves.append(corners)
        elif len(posts) < 6:
            centre = rng.uniform([0.5, 0.5], [drive.width - 0.5, drive.height - 0.5])
            if distance_to_route(centre, route) > ROUTE_CLEARANCE:
                posts.append([*centre, 0.05])
        else:
            break
    world = World(circles=circles + posts, segments=walls(drive.width, drive.height),
                  polygons=shelves, name=f"hall {drive.width:g} x {drive.height:g} m",
                  bounds=(0.0, 0.0, drive.width, drive.height))
    return world, route


def depot_layout(drive: Drive, unit: float = 4.0, depth: float = 1.0,
                 aisle: float = 2.5) -> tuple[World, NDArray[np.float64]]:
    """Rows of solid ``unit`` x ``depth`` [m] shelf units end to end along x, ``aisle`` [m]
    apart, a 3 m cross aisle at each end; the route down the first three aisles."""
    rng = np.random.default_rng(drive.seed)
    units = int((drive.width - 6.0) // unit)
    x0 = (drive.width - units * unit) / 2
    shelves, row_starts = [], []
    y = aisle
    while y + depth + aisle <= drive.height:
        row_starts.append(y)
        for k in range(units):
            gap = rng.uniform(0.0, 0.05)
            left, right = x0 + k * unit + gap, x0 + (k + 1) * unit - gap
            shelves.append(np.array([[left, y], [right, y], [right, y + depth],
                                     [left, y + depth]]))
        y += depth + aisle
    aisles = np.array([start - aisle / 2 for start in row_starts]
                      + [row_starts[-1] + depth + aisle / 2])
    route = serpentine(np.array([x0 / 2 + 0.25, drive.width - x0 / 2 - 0.25]), aisles[:3])
    world = World(segments=walls(drive.width, drive.height), polygons=shelves,
                  name=f"depot {drive.width:g} x {drive.height:g} m",
                  bounds=(0.0, 0.0, drive.width, drive.height))
    return world, route


def layout(drive: Drive) -> tuple[World, NDArray[np.float64]]:
    return hall_layout(drive) if drive.layout == "hall" else depot_layout(drive)


class TurnInPlaceDriver(PurePursuitDriver):
    """Pure pursuit of a waypoint route that stops within ``reach`` [m] of each corner and
    turns on the spot at ``turn_rate`` [rad/s] until it heads within ``aligned`` [rad] along
    the next leg: the speed drops from cruise to zero at each corner and back."""

    def __init__(self, route: NDArray[np.float64], speed: float, lookahead: float,
                 turn_rate: float = 1.0, reach: float = 0.3,
                 aligned: float = math.radians(2.0)) -> None:
        super().__init__(speed=speed, lookahead=lookahead)
        self.route = np.asarray(route, dtype=np.float64)
        legs = np.diff(self.route, axis=0)
        self.leg_headings = np.arctan2(legs[:, 1], legs[:, 0])
        self.turn_rate, self.reach, self.aligned = turn_rate, reach, aligned
        self.leg, self.turning, self._period = 0, False, 0.2

    def reset(self, env: gym.Env) -> None:
        """Follow the route from its first leg (the env reset to it)."""
        super().reset(env)
        self.leg, self.turning = 0, False
        self._period = float(env.unwrapped.config.control_dt)

    def act(self, observation: Any, info: Any) -> NDArray[np.float32]:
        action = super().act(observation, info)  # also moves the pursuit point on
        x, y, heading = (float(v) for v in info["pose"])
        corner = self.leg + 1
        if not self.turning and corner < len(self.leg_headings) and math.hypot(
                *(self.route[corner] - (x, y))) < self.reach:
            self.turning, self.leg = True, corner
        if not self.turning:
            return action
        off = math.remainder(self.leg_headings[self.leg] - heading, math.tau)
        if abs(off) < self.aligned:
            self.turning = False
            return action
        rate = math.copysign(min(self.turn_rate, abs(off) / self._period, self._max_yaw_rate), off)
        return np.array([0.0, rate / self._max_yaw_rate], dtype=np.float32)


@dataclass
class Recording:
    """One drive's setup, observations, times [s] and true poses (N, 3)."""

    world: World
    setup: SensorSetup
    observations: list[dict]
    times: NDArray[np.float64]
    poses: NDArray[np.float64]


def record(drive: Drive) -> Recording:
    """Drive ``drive``'s route at the robot's top speed; raises if it does not finish."""
    world, route = layout(drive)
    config = {"robot": drive.robot, "scan_frame": "sensor", "max_episode_time": 3600.0}
    env = gym.make("DualLidar-v0", world=world, trace=route.tolist(), config=config)
    # speed: capped at the preset's max_speed
    driver = (TurnInPlaceDriver(route, speed=10.0, lookahead=0.3) if drive.turn_in_place
              else PurePursuitDriver(speed=10.0, lookahead=0.3))
    observation, info = env.reset(seed=drive.seed)
    driver.reset(env)
    observations, times, poses = [observation], [float(info["time"])], [info["pose"]]
    terminated = truncated = False
    while not (terminated or truncated):
        observation, _, terminated, truncated, info = env.step(driver.act(observation, info))
        observations.append(observation)
        times.append(float(info["time"]))
        poses.append(info["pose"])
    setup = SensorSetup.from_env(env)
    env.close()
    if not terminated or info.get("collision"):
        raise RuntimeError(f"{drive}: the drive did not reach the route's end cleanly")
    return Recording(world, setup, observations, np.array(times),
                     np.array(poses, dtype=np.float64))


def returns_per_scan(recording: Recording) -> NDArray[np.int64]:
    """Readings in (0, max_range) per observation, over all Lidars."""
    counts = np.zeros(len(recording.observations), dtype=np.int64)
    for sensor, key in zip(recording.setup.sensors, recording.setup.keys, strict=True):
        ranges = np.array([observation[key] for observation in recording.observations])
        counts += np.count_nonzero((ranges > 0) & (ranges < sensor.max_range), axis=1)
    return counts


def replay(recording: Recording, name: str) -> tuple[NDArray[np.float64], float]:
    """Estimator ``name``'s trajectory (N, 3) over ``recording`` and its CPU s per scan."""
    estimator = estimators.make(name)
    start = time.process_time()
    estimator.reset(recording.setup, recording.poses[0])
    for observation, t in zip(recording.observations, recording.times, strict=True):
        estimator.update(observation, t)
    cpu = (time.process_time() - start) / len(recording.times)
    return np.asarray(estimator.trajectory, dtype=np.float64), cpu


def score(recording: Recording, poses: NDArray[np.float64]) -> dict[str, float]:
    """ATE [m], drift [%], share of ~1 s relations off by more than ``FAILURE``."""
    metrics = evaluate(poses, recording.poses)
    relations = relations_from_trajectory(recording.times, recording.poses, WINDOW)
    first = match_times(recording.times, relations.t1, 1e-6)
    second = match_times(recording.times, relations.t2, 1e-6)
    error = relative(relations.poses, relative(poses[first], poses[second]))
    return {"ate_m": metrics.ate_rmse_m, "drift_percent": metrics.drift_percent,
            "fail_share": float(np.mean(np.hypot(error[:, 0], error[:, 1]) > FAILURE)),
            "distance_m": metrics.distance_m}


def save_map(world: World, folder: Path, name: str) -> Path:
    """``world`` as a ROS map_server map ``folder/name.yaml`` (+ PGM), origin at its corner."""
    folder.mkdir(parents=True, exist_ok=True)
    occupied = world.to_image(MAP_RESOLUTION) / 255.0
    xmin, ymin, _, _ = world.bounds
    return save_ros_map(folder / f"{name}.yaml", occupied, MAP_RESOLUTION,
                        origin=(xmin, ymin, 0.0))[0]


def main(argv: list[str] | None = None) -> dict[str, dict[str, Any]]:
    parser = argparse.ArgumentParser(
        description=__doc__.splitlines()[0],
        formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--drives", nargs="+", default=list(DRIVES),
                        choices=list(DRIVES) + list(QUICK), help="drives to run")
    parser.add_argument("--estimators", nargs="+", default=[REFERENCE, "lidar_odometry", "slam"],
                        choices=estimators.names(), help=f"estimators ({REFERENCE} always runs)")
    parser.add_argument("--quick", action="store_true",
                        help=f"only the small {', '.join(QUICK)} (a smoke run)")
    parser.add_argument("--maps", type=Path, default=None,
                        help="also write each drive's world as a ROS map into this folder")
    parser.add_argument("--json", type=Path, default=None, help="write the results here")
    args = parser.parse_args(argv)
    names = [REFERENCE] + [n for n in args.estimators if n != REFERENCE]
    drives = QUICK if args.quick else {name: ({**DRIVES, **QUICK})[name] for name in args.drives}
    print(f"machine: {platform.processor() or platform.machine()}, python "
          f"{platform.python_version()}; relations {WINDOW:g} s apart > {FAILURE} m fail; "
          f"ratios to {REFERENCE}")
    results: dict[str, dict[str, Any]] = {}
    for label, drive in drives.items():
        recording = record(drive)
        counts = returns_per_scan(recording)
        if args.maps is not None:
            save_map(recording.world, args.maps, label)
        results[label] = {"drive": {
            "scans": len(counts), "median_returns": float(np.median(counts)),
            "share_below_min_returns": float(np.mean(counts < MIN_RETURNS))}}
        print(f"{label}: {recording.world.name}, {drive.robot}, {len(counts)} scans, "
              f"median {np.median(counts):.0f} returns, "
              f"{100 * np.mean(counts < MIN_RETURNS):.1f} % of scans < {MIN_RETURNS}")
        for name in names:
            trajectory, cpu = replay(recording, name)
            row = score(recording, trajectory) | {"cpu_ms_per_scan": 1e3 * cpu}
            results[label][name] = row
            reference = results[label][REFERENCE]
            print(f"  {name:15s} ATE {row['ate_m']:7.3f} m "
                  f"({row['ate_m'] / max(reference['ate_m'], 1e-9):5.2f}x)  drift "
                  f"{row['drift_percent']:6.2f} % "
                  f"({row['drift_percent'] / max(reference['drift_percent'], 1e-9):5.2f}x) "
                  f" 1 s > {FAILURE} m: {100 * row['fail_share']:5.2f} %  "
                  f"{row['cpu_ms_per_scan']:5.1f} ms/scan  ({row['distance_m']:.0f} m)")
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=1))
    return results


if __name__ == "__main__":
    main()
