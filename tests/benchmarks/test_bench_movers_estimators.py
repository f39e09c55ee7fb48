"""The movers benchmark's oracle: the scans with every return on a true mover deleted."""

from __future__ import annotations

import numpy as np

from estimators.base import SensorSetup
from estimators.leaderboard.records import SensorDataset
from lidar_env.sensors.lidar import cast_rays
from lidar_env.world.world import World
from tests.benchmarks.bench_modules import load

bench = load("bench_movers_estimators")

ANGLES = 2 * np.pi * np.arange(360) / 360
WALLS = [[-6, -6, 6, -6], [6, -6, 6, 6], [6, 6, -6, 6], [-6, 6, -6, -6]]


def test_the_oracle_deletes_exactly_the_returns_on_a_mover() -> None:
    """A walker 3 m ahead of a Lidar mounted 0.3 m forward on a car turned 90 degrees: its
    beams read max range, every other beam (walls, a post) reads what it read."""
    car = np.array([1.0, 0.5, np.pi / 2])
    sensor = np.array([1.0, 0.8, np.pi / 2])  # the mount (0.3, 0, 0) composed with the car
    walker = np.array([[1.0, 3.8, 0.0, 1.0, 0.25]])  # x, y, vx, vy, radius
    world = World(segments=WALLS, circles=[[-2.0, -2.0, 0.3], walker[0, [0, 1, 4]]])
    static = World(segments=WALLS, circles=[[-2.0, -2.0, 0.3]])
    scan = cast_rays(world, sensor[None], ANGLES, 20.0)[0]
    behind = cast_rays(static, sensor[None], ANGLES, 20.0)[0]
    setup = SensorSetup([[0.3, 0.0, 0.0]], ANGLES, 20.0)
    dataset = SensorDataset(setup=setup, times=np.zeros(1),
                            scans={setup.keys[0]: scan[None].astype(np.float32)},
                            poses=car[None], lidar_poses=sensor[None, None])
    cleaned = bench.without_mover_returns(dataset, [walker]).scans[setup.keys[0]][0]
    on_walker = scan < behind - 1e-6
    assert 5 < on_walker.sum() < 15  # a 0.5 m wide walker 2.75 m out: about 10 beams
    assert np.all(cleaned[on_walker] == 20.0)
    np.testing.assert_array_equal(cleaned[~on_walker], scan[~on_walker].astype(np.float32))
