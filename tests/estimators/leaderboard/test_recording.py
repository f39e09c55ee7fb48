"""Record a scenario once, store it, replay it: the metrics equal online scoring."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from agents.driver import make_driver
from agents.scripted import PurePursuitDriver
from estimators.evaluation.scoring import ScoreEstimator
from estimators.leaderboard.database import ExperimentDatabase
from estimators.leaderboard.recording import (
    make_env,
    map_reference,
    record,
    replay,
    score,
    score_map,
    world_from_geometry,
)
from estimators.leaderboard.records import Scenario
from estimators.mapping.run_maps import car_frame_obstacles
from lidar_env import lidars_with_noise
from lidar_env.core.se2 import compose

# 6 s of driving keeps the test short; the env truncates the episode there.
SCENARIO = Scenario("open_cylinders", "right_turn", 7,
                    {"lidars": lidars_with_noise(range_noise_std=0.01), "max_episode_time": 6.0})


def online_metrics(estimator: str) -> tuple[dict[str, float], np.ndarray]:
    """Score ``estimator`` live on the env with the project's online wrapper (the oracle)."""
    env = ScoreEstimator(make_env(SCENARIO), estimator)
    driver = PurePursuitDriver()
    observation, info = env.reset(seed=SCENARIO.seed)
    driver.reset(env)
    done = False
    while not done:
        observation, _, terminated, truncated, info = env.step(driver.act(observation, info))
        done = terminated or truncated
    env.close()
    return info["estimator"], env.estimated_trajectory


@pytest.fixture(scope="module")
def stored(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("recording") / "db.sqlite"
    with ExperimentDatabase(path) as db:
        assert db.save_sensor_dataset(SCENARIO, record(SCENARIO))
    return path


@pytest.mark.parametrize("estimator", ["pc", "pc_pg"])
def test_replay_from_the_database_equals_online_scoring(stored: Path, estimator: str) -> None:
    with ExperimentDatabase(stored) as db:
        dataset = db.load_sensor_dataset(SCENARIO)
    trace = replay(dataset, estimator)
    replayed = score(trace, dataset.poses)
    online, online_trajectory = online_metrics(estimator)
    assert len(dataset) == 61  # the reset observation + 60 steps of 0.1 s
    np.testing.assert_array_equal(trace.poses, online_trajectory)
    timing = {"ms_per_step", "steps"}
    shared = (set(online) & set(replayed)) - timing
    assert {"accuracy_percent", "ate_rmse_m", "drift_percent", "heading_rmse_deg"} <= shared
    assert {key: replayed[key] for key in shared} == {key: online[key] for key in shared}
    assert replayed["ms_per_step"] > 0


def test_recording_is_deterministic_and_keeps_the_truth(stored: Path) -> None:
    with ExperimentDatabase(stored) as db:
        stored_dataset = db.load_sensor_dataset(SCENARIO)
    again = record(SCENARIO)
    for key in again.scans:
        np.testing.assert_array_equal(again.scans[key], stored_dataset.scans[key])
    np.testing.assert_array_equal(again.poses, stored_dataset.poses)
    # the stored sensor poses are the mounts composed onto the stored car poses
    env = gym.make("DualLidar-v0", world=SCENARIO.world, trace=SCENARIO.trace)
    mounts = env.unwrapped.config.mounts_array
    for k in range(2):
        expected = compose(stored_dataset.poses, np.broadcast_to(mounts[k], (len(again), 3)))
        np.testing.assert_allclose(stored_dataset.lidar_poses[:, k], expected, atol=1e-9)
    assert stored_dataset.env_config["max_episode_time"] == 6.0
    # the stored map rasterises exactly like the env's own world
    env.reset(seed=SCENARIO.seed)
    np.testing.assert_array_equal(world_from_geometry(stored_dataset.world).to_image(0.1),
                                  env.unwrapped.world.to_image(0.1))
    env.close()


def test_bad_names_are_readable_errors() -> None:
    with pytest.raises(ValueError, match="unknown driver 'autopilot': expected one of"):
        make_driver("autopilot")
    with pytest.raises(ValueError, match="real"):
        make_env(Scenario("aces", "log", 0, kind="real"))
    with pytest.raises(ValueError, match="unknown world 'moon'"):
        record(Scenario("moon", "zigzag", 0))


def test_map_scores_see_true_poses_and_a_shifted_run(stored: Path) -> None:
    """At the true poses the map matches the world; shifted 0.5 m (5 cells, beyond the one-cell
    tolerance), its cells and cylinders miss: the scores rank maps, they are not constants."""
    with ExperimentDatabase(stored) as db:
        dataset = db.load_sensor_dataset(SCENARIO)
    reference = map_reference(dataset)
    assert reference is not None and reference.resolution == 0.1
    assert reference.observable.sum() >= 5  # cylinders seen in the scans the detector gets
    true = score_map(reference, dataset.poses, dataset)
    assert set(true) == {"map_precision", "map_recall", "map_iou", "cylinder_recall",
                         "cylinder_precision", "cylinder_error_m"}
    assert true["map_precision"] > 0.95 and true["map_iou"] > 0.85
    assert true["cylinder_recall"] >= 0.9 and true["cylinder_error_m"] < 0.03
    # a static scene: the mover labels leave nothing out, so the leaderboard may skip them
    assert score_map(reference, dataset.poses, dataset, label_movers=False) == true
    shifted = score_map(reference, dataset.poses + [0.5, 0.0, 0.0], dataset)
    # the obstacles detected once in the car frame and placed at the poses score the same
    car_frame = car_frame_obstacles(list(dataset.observations()), dataset.setup)
    for poses, scores in ((dataset.poses, true), (dataset.poses + [0.5, 0.0, 0.0], shifted)):
        placed = score_map(reference, poses, dataset, label_movers=False, car_frame=car_frame)
        assert placed == pytest.approx(scores, abs=1e-12, nan_ok=True)
    assert shifted["map_iou"] < 0.3 and shifted["map_precision"] < 0.4 * true["map_precision"]
    assert shifted["cylinder_error_m"] > 0.3 or shifted["cylinder_recall"] < 0.5
    with pytest.raises(ValueError, match="obstacle_stride: expected an integer >= 1, got 0"):
        score_map(reference, dataset.poses, dataset, obstacle_stride=0)
