"""Self-calibration on simulated drives: the mount of Lidar 2 relative to Lidar 1 from a guess
0.3 m and 20 degrees off, to <= 1 cm and <= 0.2 degrees (the truth is the env's configured
mount, never shown to the calibration); bad input gives readable errors and warnings."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.base import Sensor, SensorSetup
from estimators.calibration import (
    InconsistentMotionWarning,
    NoOverlapWarning,
    UnobservableMountError,
    calibrate,
)
from estimators.calibration.__main__ import main
from estimators.datasets import Recording
from estimators.leaderboard.recording import record
from estimators.leaderboard.records import Scenario
from lidar_env.config import EnvConfig
from lidar_env.core.errors import EstimatorInputError
from lidar_env.core.se2 import relative, wrap_angle

CORNER_270 = {"lidars": [
    {"mount": [0.35, 0.2, np.pi / 4], "fov": 1.5 * np.pi, "n_beams": 270},
    {"mount": [-0.35, -0.2, -0.75 * np.pi], "fov": 1.5 * np.pi, "n_beams": 270}]}


def truth_and_guess(dataset, direction: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """The true pose of Lidar 2 in Lidar 1 and a guess 0.3 m and 20 degrees off."""
    truth = relative(dataset.setup.mounts[0], dataset.setup.mounts[1])
    off = np.array([0.3 * np.cos(direction), 0.3 * np.sin(direction), np.radians(20.0)])
    return truth, truth + off


def assert_mount_within_targets(dataset) -> None:
    truth, guess = truth_and_guess(dataset)
    estimate = calibrate(dataset, guess=[guess]).mounts[0]
    error = estimate.known() - truth
    assert np.hypot(error[0], error[1]) <= 0.01, estimate.describe()
    assert abs(np.degrees(wrap_angle(error[2]))) <= 0.2, estimate.describe()
    assert estimate.hand_eye.unobservable == ()


def test_two_360_lidars_on_a_zigzag() -> None:
    assert_mount_within_targets(record(Scenario("hallway", "zigzag", 0)))


@pytest.mark.slow
@pytest.mark.parametrize("world", ["closed_to_open", "random"])
def test_two_360_lidars_on_a_loop(world: str) -> None:
    assert_mount_within_targets(record(Scenario(world, "loop", 1)))


@pytest.mark.slow
@pytest.mark.skipif("lidars" not in EnvConfig.keys(), reason="env without per-Lidar fov")
@pytest.mark.parametrize("trace", ["zigzag", "loop"])
def test_two_270_corner_lidars(trace: str) -> None:
    assert_mount_within_targets(record(Scenario("open_cylinders", trace, 2, config=CORNER_270)))


def test_calibrated_mounts_build_a_setup_with_lidar_1_as_configured() -> None:
    dataset = record(Scenario("hallway", "zigzag", 4, config={"max_episode_time": 15.0}))
    calibration = calibrate(dataset, guess=[truth_and_guess(dataset)[1]])
    setup = calibration.setup(dataset.setup)
    np.testing.assert_array_equal(setup.mounts[0], dataset.setup.mounts[0])
    np.testing.assert_allclose(setup.mounts[1], dataset.setup.mounts[1], atol=0.01)
    assert set(calibration.odometry) == {"lidar_1", "lidar_2"}


def test_a_drive_without_rotation_reports_the_lever_arm_unobservable() -> None:
    dataset = record(Scenario("hallway", "straight", 0, config={"max_episode_time": 12.0}))
    truth, guess = truth_and_guess(dataset)
    estimate = calibrate(dataset, guess=[guess], refine=False).mounts[0]
    assert estimate.unobservable == ("x", "y")
    assert "x unobservable, y unobservable" in estimate.describe()
    assert abs(wrap_angle(estimate.value[2] - truth[2])) < np.radians(0.2)  # heading is seen
    with pytest.raises(UnobservableMountError, match="lidar_2: the drive does not determine x, "
                                                     "y of the mount"):
        estimate.known()
    with pytest.raises(UnobservableMountError):
        calibrate(dataset, guess=[guess], refine=False).setup(dataset.setup)


def test_fewer_than_two_lidars_is_refused() -> None:
    dataset = record(Scenario("hallway", "zigzag", 0, config={"max_episode_time": 5.0}))
    one = Recording("one", SensorSetup(dataset.setup.mounts[:1], dataset.setup.beam_angles, 10.0),
                    dataset.times, {"lidar_1": dataset.scans["lidar_1"]}, ("/a",), ("a",))
    with pytest.raises(EstimatorInputError, match="at least 2 Lidars.*got 1 \\(lidar_1\\)"):
        calibrate(one)
    with pytest.raises(EstimatorInputError, match="guess: expected 1 finite rows"):
        calibrate(dataset, guess=[[0.0, 0.0, np.nan]])


# 120-degree views of a hallway make poor odometry: the motion check rightly warns too.
@pytest.mark.filterwarnings("ignore::estimators.calibration.InconsistentMotionWarning")
def test_scans_without_overlap_warn_and_fall_back_to_motion() -> None:
    """Lidar 1 keeps its 120 forward degrees, Lidar 2 its 120 rearward ones: no shared view."""
    dataset = record(Scenario("hallway", "zigzag", 0))
    angles = dataset.setup.beam_angles
    front = np.flatnonzero(np.abs(wrap_angle(angles)) < np.radians(60))
    rear = np.flatnonzero(np.abs(wrap_angle(angles - np.pi)) < np.radians(60))
    setup = SensorSetup(sensors=[Sensor(m, angles[keep], 10.0) for m, keep in
                                 zip(dataset.setup.mounts, (front, rear), strict=True)])
    scans = {"lidar_1": dataset.scans["lidar_1"][:, front],
             "lidar_2": dataset.scans["lidar_2"][:, rear]}
    blind = Recording("blind", setup, dataset.times, scans, ("/a", "/b"), ("a", "b"))
    with pytest.warns(NoOverlapWarning, match="lidar_2: its scans overlap too little"):
        estimate = calibrate(blind, guess=[truth_and_guess(dataset)[1]]).mounts[0]
    assert estimate.source == "hand-eye"


def test_the_command_line_prints_the_mounts(capsys) -> None:
    code = main(["--world", "hallway", "--trace", "zigzag", "--config",
                 '{"max_episode_time": 15.0}', "--guess", "-0.2", "0.3", "20"])
    out = capsys.readouterr().out
    assert code == 0
    assert "lidar_2 in lidar_1: x -0.50" in out and "[scan alignment]" in out
    assert main(["--bag", "/nonexistent/drive.bag"]) == 2
    assert "ROS bag not found" in capsys.readouterr().err


def test_unsynchronised_lidars_warn_that_the_motions_disagree() -> None:
    """Lidar 2's scans 0.5 s late: the two odometries no longer turn together."""
    dataset = record(Scenario("hallway", "zigzag", 0, config={"max_episode_time": 25.0}))
    late = {"lidar_1": dataset.scans["lidar_1"][5:], "lidar_2": dataset.scans["lidar_2"][:-5]}
    shifted = Recording("late", dataset.setup, dataset.times[5:], late, ("/a", "/b"), ("a", "b"))
    with pytest.warns(InconsistentMotionWarning, match="lidar_2: its own odometry turns unlike"):
        calibrate(shifted, refine=False)


@pytest.mark.slow
def test_three_lidars_from_a_bag(tmp_path) -> None:
    """K = 3 through an mcap bag: each of Lidars 2 and 3 within the targets, guess 0.28 m and
    17 degrees off."""
    from estimators.datasets import load_bag, write_bag

    config = {"lidars": [{"mount": [0.3, 0.0, 0.0]}, {"mount": [-0.3, 0.1, np.pi]},
                         {"mount": [0.0, -0.2, -np.pi / 2]}]}
    dataset = record(Scenario("closed_to_open", "loop", 0, config=config))
    bag = write_bag(tmp_path / "three", dataset.setup, dataset.times, dataset.scans,
                    storage="mcap")
    truths = [relative(dataset.setup.mounts[0], m) for m in dataset.setup.mounts[1:]]
    calibration = calibrate(load_bag(bag), guess=[t + [0.2, -0.2, 0.3] for t in truths])
    for estimate, truth in zip(calibration.mounts, truths, strict=True):
        error = estimate.known() - truth
        assert np.hypot(error[0], error[1]) <= 0.01, estimate.describe()
        assert abs(np.degrees(wrap_angle(error[2]))) <= 0.2, estimate.describe()
    assert [m.key for m in calibration.mounts] == ["lidar_2", "lidar_3"]
