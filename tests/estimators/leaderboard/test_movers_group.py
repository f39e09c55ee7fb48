"""The leaderboard's moving-obstacle groups: tracker scores per trace, recovered by driving
the scenario again, and the maps table shows them only where movers walked."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from estimators.leaderboard.headline import map_markdown
from estimators.leaderboard.matrix import MOVER_GROUPS, table_one_scenarios
from estimators.leaderboard.recording import mover_truth, record
from estimators.leaderboard.records import Scenario
from estimators.leaderboard.tasks import EstimatorSpec, ScenarioTask, run_scenario_task
from lidar_env.core.errors import DatabaseError

#: 5 s of the hallway with 10 pedestrians, seed 1: some walk past the car.
SCENARIO = Scenario("hallway", "straight", 1, {"moving_obstacles": 10, "max_episode_time": 5.0})


def test_a_movers_scenario_scores_the_tracker_for_every_estimator() -> None:
    outcome = run_scenario_task(ScenarioTask(SCENARIO, (EstimatorSpec("lidar_odometry"),)))
    assert outcome.failures == {}
    ((trace, metrics),) = outcome.traces
    assert metrics["mover_recall"] > 0.9 and metrics["mover_position_error_m"] < 0.05
    assert {"mover_velocity_error_mps", "mover_id_switches",
            "moving_label_precision"} <= set(metrics)
    static = run_scenario_task(ScenarioTask(dataclasses.replace(SCENARIO, config={
        "max_episode_time": 5.0}), (EstimatorSpec("lidar_odometry"),)))
    assert not any(key.startswith("mover_") for key in static.traces[0][1])


def test_the_movers_come_back_only_for_the_same_drive() -> None:
    dataset = record(SCENARIO)
    movers = mover_truth(SCENARIO, dataset)
    assert movers.shape == (len(dataset), 10, 5) and np.all(np.isfinite(movers))
    other = dataclasses.replace(SCENARIO, seed=SCENARIO.seed + 1)
    with pytest.raises(DatabaseError, match="did not reproduce the stored scans"):
        mover_truth(other, dataset)


def test_mover_groups_are_not_table_one_cases() -> None:
    scenarios = {g.name: [Scenario(g.world, g.trace, 0, dict(g.config))] for g in MOVER_GROUPS}
    runs = table_one_scenarios(MOVER_GROUPS, scenarios, [EstimatorSpec("pc_pg")])
    assert runs["sensor"] == {} and runs["world"] == {}


def test_the_maps_table_shows_tracker_columns_only_when_a_run_has_them() -> None:
    row = {"rank": "1", "estimator": "icp", "map_iou": 0.9, "mover_recall": math.nan}
    assert "mover recall" not in map_markdown([row])
    assert "mover recall" in map_markdown([{**row, "mover_recall": 0.95}])
