"""Drivers steering by an estimator's poses instead of the env's ground truth."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import lidar_env  # noqa: F401 - registers DualLidar-v0
from agents.driver import make_driver
from agents.evaluate import drive_episode
from agents.pose_source import EstimatedPoseDriver
from agents.scripted import PurePursuitDriver
from lidar_env.core.errors import ArgumentTypeError, ConfigError


class _Recorder(PurePursuitDriver):
    """Pure pursuit that keeps the ``info`` it is given."""

    def __init__(self) -> None:
        super().__init__()
        self.seen: list[dict[str, Any]] = []

    def act(self, observation: Mapping[str, Any], info: Mapping[str, Any]) -> np.ndarray:
        self.seen.append(dict(info))
        return super().act(observation, info)


def test_a_pose_source_naming_no_estimator_lists_the_valid_ones() -> None:
    with pytest.raises(ConfigError, match=r"pose_source: expected one of true, .*lidar_odometry"):
        make_driver("scripted", pose_source="gps")


def test_the_driver_sees_the_estimate_and_no_ground_truth() -> None:
    env = gym.make("DualLidar-v0", world="hallway", trace="straight",
                   config={"max_episode_time": 3.0})
    inner = _Recorder()
    driver = EstimatedPoseDriver(inner, "lidar_odometry")
    observation, info = env.reset(seed=3)
    driver.reset(env)
    truths = []
    for _ in range(20):
        action = driver.act(observation, info)
        truths.append(info["pose"])
        observation, _, terminated, truncated, info = env.step(action)
        assert not (terminated or truncated)
    assert all(set(seen) == {"pose", "time"} for seen in inner.seen)
    estimates = np.array([seen["pose"] for seen in inner.seen])
    np.testing.assert_array_equal(estimates[0], env.unwrapped.trace.start_pose)
    assert not np.array_equal(estimates[1:], np.array(truths)[1:])  # not the truth, copied
    np.testing.assert_allclose(estimates[:, :2], np.array(truths)[:, :2], atol=0.05)


@pytest.mark.slow
@pytest.mark.parametrize("source", ["lidar_odometry", "slam"])
def test_the_scripted_driver_finishes_a_paper_trace_on_estimated_poses(source: str) -> None:
    env = gym.make("DualLidar-v0", world="open_cylinders", trace="right_turn")
    episode = drive_episode(env, make_driver("scripted", pose_source=source), seed=1)
    assert episode.success and not episode.collided
    assert episode.cross_track_error < 0.05
    assert 0.0 < episode.end_point_error < 0.2


def test_evaluate_drives_the_paper_groups_on_each_pose_source(capsys: pytest.CaptureFixture[str]
                                                              ) -> None:
    from agents.evaluate import PAPER_GROUPS, main

    main(["--drivers", "scripted", "--paper-groups", "--episodes", "1",
          "--pose-sources", "true"])
    lines = capsys.readouterr().out.splitlines()
    header = [cell.strip() for cell in lines[0].strip("|").split("|")]
    rows = [[cell.strip() for cell in line.strip("|").split("|")] for line in lines[2:]]
    assert [(row[2], row[3]) for row in rows] == list(PAPER_GROUPS)
    for row in rows:  # the true pose: every trace finished, no estimate to be off
        assert row[header.index("success")] == "100%"
        assert row[header.index("end-point [m]")] == "0.000"
    with pytest.raises(SystemExit) as exit_info:
        main(["--drivers", "scripted", "--paper-groups", "--episodes", "1",
              "--pose-sources", "gps"])
    assert exit_info.value.code == 2
    assert "--pose-sources: unknown name 'gps': expected one of" in capsys.readouterr().err


def test_pose_params_reach_the_estimator_and_are_refused_where_they_mean_nothing() -> None:
    from estimators import make

    driver = make_driver("scripted", pose_source="lidar_odometry",
                         pose_params={"sideslip_sigma": 6e-4})
    assert isinstance(driver, EstimatedPoseDriver)
    assert driver.estimator.sideslip_sigma == 6e-4
    with pytest.raises(ConfigError, match="pose_params: only with an estimator"):
        make_driver("scripted", pose_params={"sideslip_sigma": 6e-4})
    with pytest.raises(ConfigError, match="lidar_odometry: unknown parameter.*sideslip"):
        make_driver("scripted", pose_source="lidar_odometry", pose_params={"sideslip": 1e-3})
    with pytest.raises(ConfigError, match="params: only with an estimator name"):
        EstimatedPoseDriver(PurePursuitDriver(), make("icp"), {"max_iterations": 3})
    with pytest.raises(ArgumentTypeError, match="params: expected a mapping"):
        make_driver("scripted", pose_source="icp", pose_params=[("max_iterations", 3)])
    with pytest.raises(ConfigError, match="estimator: expected an estimator name, got 'true'"):
        EstimatedPoseDriver(PurePursuitDriver(), "true")


def test_evaluate_refuses_pose_params_for_a_source_it_does_not_drive() -> None:
    from agents.evaluate import main

    for bad in ('{"slam": {}}', '{"true": {}}', "not json", '{"lidar_odometry": 3}'):
        with pytest.raises(SystemExit):
            main(["--drivers", "scripted", "--paper-groups", "--episodes", "1",
                  "--pose-sources", "lidar_odometry", "--pose-params", bad])
