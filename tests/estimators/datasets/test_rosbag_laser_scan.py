"""The LaserScan fields through write_bag / load_bag: angle_min, angle_increment, range_min,
range_max and the frame reach each Sensor; scans that lie about them are named errors."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("rosbags")

import lidar_env  # noqa: E402, F401 - registers DualLidar-v0
from estimators.base import Sensor, SensorSetup, default_beam_angles  # noqa: E402
from estimators.datasets import load_bag, write_bag  # noqa: E402
from estimators.datasets.rosbag_writer import BagSink, header, laser_scan  # noqa: E402
from lidar_env.core.errors import LogFormatError  # noqa: E402


def env_drive(robot: str, steps: int = 4) -> tuple[SensorSetup, np.ndarray, dict]:
    env = gym.make("DualLidar-v0", world="hallway", config={"robot": robot})
    observation, info = env.reset(seed=1)
    setup = SensorSetup.from_env(env)
    times, scans = [info["time"]], {key: [observation[key]] for key in setup.keys}
    for _ in range(steps - 1):
        observation, *_, info = env.step(np.array([0.5, 0.1], dtype=np.float32))
        times.append(info["time"])
        for key in setup.keys:
            scans[key].append(observation[key])
    return setup, np.array(times), {key: np.array(rows) for key, rows in scans.items()}


@pytest.mark.parametrize("robot", ["turtlebot3_burger", "f1tenth"])
def test_min_range_and_the_laser_scan_fields_round_trip(tmp_path: Path, robot: str) -> None:
    setup, times, scans = env_drive(robot)
    recording = load_bag(write_bag(tmp_path / "bag", setup, times, scans))
    for written, read in zip(setup.sensors, recording.setup.sensors, strict=True):
        assert written.range_min > 0
        assert read.range_min == pytest.approx(written.range_min, rel=1e-7)
        assert read.range_max == pytest.approx(written.range_max, rel=1e-7)
        assert read.frame == written.frame == "lidar_1"
        assert read.angle_min == pytest.approx(written.angle_min, abs=1e-6)
        assert read.angle_increment == pytest.approx(written.angle_increment, rel=1e-6)
        assert read.n_beams == written.n_beams
    for key in setup.keys:
        np.testing.assert_allclose(recording.scans[key], scans[key], rtol=1e-6)


def test_a_sensor_is_built_from_a_laser_scan_header() -> None:
    sensor = Sensor.from_laser_scan((0.1, 0.0, 0.0), -0.75 * np.pi, np.radians(0.25), 1081,
                                    0.06, 10.0, "laser")
    assert sensor.beam_angles[-1] == pytest.approx(0.75 * np.pi)
    assert (sensor.range_min, sensor.range_max, sensor.frame) == (0.06, 10.0, "laser")
    full = Sensor.from_laser_scan((0, 0, 0), 0.0, np.float32(2 * np.pi / 360), 360, 0.12, 3.5)
    np.testing.assert_array_equal(full.beam_angles, default_beam_angles(360))
    with pytest.raises(ValueError, match="angle_increment: expected a finite angle"):
        Sensor.from_laser_scan((0, 0, 0), 0.0, float("nan"), 360, 0.0, 3.5)
    with pytest.raises(ValueError, match=r"range_min of sensor 0 \(lidar_1\): expected"):
        Sensor((0, 0, 0), default_beam_angles(8), 5.0, range_min=8.0)


def lying_bag(path: Path, **changes) -> Path:
    """Three LaserScans on ``/scan`` with the fields in ``changes`` (a list: one per message)."""
    setup = SensorSetup(np.zeros((1, 3)), default_beam_angles(360), 10.0)
    with BagSink(path, "sqlite3") as sink:
        types = sink.typestore.types
        for step in range(3):
            frames = changes.get("frame_id", ["laser"] * 3)
            message = laser_scan(types, header(types, 0.1 * step, frames[step], step, False),
                                 np.full(360, 2.0), (0.0, 2 * np.pi / 360), setup.sensors[0])
            for key, values in changes.items():
                if key != "frame_id":
                    setattr(message, key, values[step])
            sink.write("/scan", message, 0.1 * step)
    return path


@pytest.mark.parametrize(("changes", "message"), [
    ({"range_min": [8.0] * 3, "range_max": [5.0] * 3}, r"range_min: expected a number in \[0, "
                                                       r"range_max\) = \[0, 5\) \[m\], got 8"),
    ({"frame_id": ["laser", "other", "laser"]}, r"message 1: header.frame_id 'other' differs"),
    ({"angle_increment": [float("nan")] * 3}, r"expected finite angles \[rad\], got "
                                              r"angle_increment nan"),
])
def test_scans_that_lie_about_their_fields_are_named(tmp_path: Path, changes, message) -> None:
    with pytest.raises(LogFormatError, match=message):
        load_bag(lying_bag(tmp_path / "bag", **changes))


def test_bad_mounts_and_a_folder_without_metadata_are_named(tmp_path: Path) -> None:
    bag = lying_bag(tmp_path / "bag")
    for mounts in [(4,), [[0, 0]], "front", [[0.0, np.nan, 0.0]]]:
        with pytest.raises(LogFormatError, match=r"mounts: expected \(1, 3\) finite poses"):
            load_bag(bag, mounts=mounts)
    assert load_bag(bag, mounts=(0.1, 0.0, 0.0)).setup.mounts[0, 0] == 0.1
    (tmp_path / "bag" / "metadata.yaml").unlink()
    with pytest.raises(LogFormatError, match="with its metadata.yaml"):
        load_bag(tmp_path / "bag")


@pytest.mark.parametrize("tolerance", [float("nan"), -0.1, "0.1"])
def test_a_sync_tolerance_that_is_no_number_of_seconds_is_named(tmp_path, tolerance) -> None:
    from estimators.datasets.recording import synchronise

    with pytest.raises(ValueError, match="sync_tolerance: expected a number of seconds >= 0"):
        synchronise([np.arange(3.0), np.arange(3.0)], tolerance)
    with pytest.raises(ValueError, match="sync_tolerance: expected"):
        load_bag(lying_bag(tmp_path / "bag"), sync_tolerance=tolerance)
