"""Calibrated mounts as ROS tf (a YAML of base_link -> lidar_k and static_transform_publisher
commands), and the calibration command's named refusals of bad --config and --seed."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.calibration.__main__ import main
from estimators.calibration.tf_output import read_tf_yaml, static_transform_commands, tf_yaml


def test_mounts_round_trip_through_the_tf_yaml(tmp_path) -> None:
    mounts = np.array([[0.25, 0.0, 0.0], [-0.25, 0.05, np.pi]])
    path = tmp_path / "mounts.yaml"
    path.write_text(tf_yaml(mounts, ["lidar_1", "lidar_2"], ["configured", "calibrated"]))
    read, frames = read_tf_yaml(path)
    np.testing.assert_array_equal(read, mounts)
    assert frames == ["lidar_1", "lidar_2"]
    command = static_transform_commands(mounts, ["lidar_1", "lidar_2"])[1]
    assert command == ("ros2 run tf2_ros static_transform_publisher --x -0.250000 --y 0.050000 "
                       "--z 0 --yaw 3.141593 --pitch 0 --roll 0 --frame-id base_link "
                       "--child-frame-id lidar_2")


def test_the_calibration_command_writes_the_mounts_it_finds_as_tf(tmp_path, capsys) -> None:
    path = tmp_path / "mounts.yaml"
    code = main(["--world", "hallway", "--trace", "zigzag", "--config",
                 '{"max_episode_time": 15.0}', "--tf-out", str(path)])
    out = capsys.readouterr().out
    assert code == 0 and f"tf: wrote {path}" in out
    assert out.count("static_transform_publisher") == 2
    mounts, frames = read_tf_yaml(path)
    assert frames == ["lidar_1", "lidar_2"]
    np.testing.assert_allclose(mounts, [[0.25, 0.0, 0.0], [-0.25, 0.0, 0.0]], atol=0.02)


@pytest.mark.parametrize(("arguments", "message"), [
    (["--config", "{not json"], "--config: expected env config overrides as a JSON object"),
    (["--config", "[1, 2]"], "--config: expected a JSON object of env config keys, got a list"),
    (["--seed", "-1"], "--seed: expected an integer >= 0, got -1"),
])
def test_bad_simulation_arguments_are_named(arguments, message, capsys) -> None:
    assert main(["--world", "hallway", *arguments]) == 2
    assert message in capsys.readouterr().err
