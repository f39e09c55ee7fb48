"""The sparse-halls benchmark: its halls keep pillars off the route, its turn-in-place driver
stops at corners, and a quick run scores every estimator on a small hall."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from lidar_env.world import World
from tests.benchmarks.bench_modules import load

bench = load("bench_sparse_halls")


@pytest.mark.parametrize("name", list(bench.DRIVES))
def test_layouts_leave_the_route_clear_and_turn_by_right_angles(name: str) -> None:
    drive = bench.DRIVES[name]
    world, route = bench.layout(drive)
    dense = np.concatenate([np.linspace(a, b, 200)
                            for a, b in zip(route[:-1], route[1:], strict=True)])
    assert world.clearance(dense).min() > 0.5  # the robot's half-diagonal and margin: < 0.25 m
    headings = np.arctan2(*np.diff(route, axis=0)[:, ::-1].T)
    turns = np.abs(np.remainder(np.diff(headings) + math.pi, 2 * math.pi) - math.pi)
    np.testing.assert_allclose(turns, math.pi / 2, atol=1e-9)
    same = bench.layout(drive)[0]
    np.testing.assert_array_equal(world.circles, same.circles)  # placed from the seed


def test_halls_are_sparse_for_a_3p5_m_lidar() -> None:
    world, route = bench.layout(bench.DRIVES["hall_30x20_burger_turns"])
    assert world.clearance(route).min() > 1.5  # midway between pillar rows
    in_range = np.hypot(*(world.circles[:, None, :2] - route[None, :, :]).T) < 3.5
    assert in_range.sum(axis=1).max() <= 6  # a few posts within the Lidar's reach


def test_quick_run_scores_each_estimator(tmp_path: Path) -> None:
    out = tmp_path / "halls.json"
    results = bench.main(["--quick", "--estimators", "icp", "lidar_odometry",
                          "--maps", str(tmp_path), "--json", str(out)])
    assert json.loads(out.read_text()) == json.loads(json.dumps(results))
    (label, rows), = results.items()
    assert rows["drive"]["scans"] > 100
    for name in ("icp", "lidar_odometry"):
        assert rows[name]["distance_m"] > 10
        assert 0 <= rows[name]["fail_share"] <= 1
        assert rows[name]["ate_m"] >= 0
    assert rows["lidar_odometry"]["drift_percent"] < 2.0
    hall = World.from_ros_map(tmp_path / f"{label}.yaml")
    assert hall.bounds == pytest.approx((0.0, 0.0, 12.0, 9.0))


def test_turn_in_place_driver_stops_to_turn() -> None:
    drive = bench.QUICK["hall_12x9_burger_turns"]
    recording = bench.record(drive)
    steps = bench.relative(recording.poses[:-1], recording.poses[1:])
    on_the_spot = (np.abs(steps[:, 2]) > 0.19) & (np.hypot(steps[:, 0], steps[:, 1]) < 1e-3)
    corners = np.flatnonzero(np.diff(on_the_spot.astype(int)) == 1)  # [rad] 1 rad/s for 0.2 s
    assert len(corners) == len(bench.layout(drive)[1]) - 2  # one turn on the spot a corner


def test_the_seed_sweep_scores_a_drive_kind_rebuilt_from_another_seed() -> None:
    sweep = load("bench_sparse_hall_seeds")
    results = sweep.main(["--seeds", "10", "--drives", "hall_20x15_burger",
                          "--estimators", "icp", "zero"])
    row = results["hall_20x15_burger"]
    assert row["failed_seeds"] == [] and len(row["icp"]["drift_percent"]) == 1
    rebuilt = bench.record(dataclasses.replace(bench.DRIVES["hall_20x15_burger"], seed=10))
    scores = bench.score(rebuilt, bench.replay(rebuilt, "icp")[0])
    assert row["icp"]["drift_percent"] == [scores["drift_percent"]]
    assert row["icp"]["ate_m"] == [scores["ate_m"]]
    # an estimator that never moves ends worse than icp on the seed, by both measures
    assert row["worse_than_first"] == {"zero": {"drift_percent": 1, "ate_m": 1}}
