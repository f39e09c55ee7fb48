"""Two Lidars from CARMEN logs: a simulated two-laser drive written as one log (FLASER + RLASER)
or as two logs reads back as the same drive, calibrates from the command line, and bad input
names the file."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from estimators.calibration.__main__ import main as calibrate_main
from estimators.datasets.carmen import load_log
from estimators.datasets.carmen_pairs import carmen_recording
from estimators.leaderboard.recording import record
from estimators.leaderboard.records import Scenario
from lidar_env.core.errors import LogFormatError

#: Two 180-degree lasers (CARMEN's FLASER geometry: 181 beams, -90..+90 degrees) on the
#: front corners, turned 45 degrees outward: their views overlap ahead of the car.
LEFT, RIGHT = (0.3, 0.15, math.pi / 4), (0.3, -0.15, -math.pi / 4)
LASERS = [{"mount": LEFT, "fov": math.pi, "n_beams": 181, "max_range": 10.0},
          {"mount": RIGHT, "fov": math.pi, "n_beams": 181, "max_range": 10.0}]


@pytest.fixture(scope="module")
def drive():
    return record(Scenario("open_cylinders", "zigzag", 2,
                           config={"lidars": LASERS, "max_episode_time": 15.0}))


def laser_line(name: str, ranges: np.ndarray, t: float) -> str:
    values = " ".join(f"{r:.6f}" for r in ranges)
    return f"{name} {len(ranges)} {values} 0 0 0 0 0 0 {t:.6f} sim {t:.6f}"


def write_log(path: Path, drive, keys: tuple[str, ...], names: tuple[str, ...],
              params: dict[str, float], lag: float = 0.002) -> Path:
    """The drive's scans of ``keys`` as CARMEN lines ``names``; Lidar k stamped k * lag late."""
    lines = [f"PARAM {key} {value!r} sim 0" for key, value in params.items()]
    for step, t in enumerate(drive.times):
        lines += [laser_line(name, drive.scans[key][step], 100.0 + t + k * lag)
                  for k, (key, name) in enumerate(zip(keys, names, strict=True))]
    path.write_text("\n".join(lines) + "\n")
    return path


def rear_params(mount: tuple[float, float, float]) -> dict[str, float]:
    return dict(zip(("robot_rearlaser_offset", "robot_rearlaser_side_offset",
                     "robot_rearlaser_angular_offset"), mount, strict=True))


def test_front_and_rear_laser_of_one_log_are_the_drive(drive, tmp_path: Path) -> None:
    path = write_log(tmp_path / "two.log", drive, ("lidar_1", "lidar_2"), ("FLASER", "RLASER"),
                     {"robot_frontlaser_offset": 0.3, **rear_params(RIGHT)})
    recording = carmen_recording([path])
    assert recording.setup.n_lidars == 2 and recording.dropped == 0
    np.testing.assert_allclose(recording.setup.mounts, [(0.3, 0.0, 0.0), RIGHT])
    np.testing.assert_allclose(recording.setup.sensors[1].beam_angles,
                               drive.setup.sensors[1].beam_angles, atol=1e-12)
    for key in ("lidar_1", "lidar_2"):
        np.testing.assert_allclose(recording.scans[key], drive.scans[key], atol=1e-6)
    np.testing.assert_allclose(recording.times, 100.0 + drive.times, atol=1e-6)
    assert recording.topics == ("two.log:front laser", "two.log:rear laser")


def test_a_rear_laser_without_an_angular_offset_faces_backwards(tmp_path: Path) -> None:
    path = tmp_path / "rear.log"
    path.write_text("PARAM robot_rearlaser_offset -0.2 sim 0\n"
                    + laser_line("RLASER", np.ones(180), 1.0) + "\n")
    log = load_log(path)
    assert log.scans == [] and len(log.rear_scans) == 1
    np.testing.assert_allclose(log.rear_scans[0].laser_offset, (-0.2, 0.0, math.pi))
    assert not log.unknown_messages


def test_two_logs_pair_by_stamp_and_calibrate_from_the_command_line(
        drive, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    first = write_log(tmp_path / "a.log", drive, ("lidar_1",), ("FLASER",),
                      {"robot_frontlaser_offset": 0.0})
    second = write_log(tmp_path / "b.log", drive, ("lidar_2",), ("FLASER",),
                       {"robot_frontlaser_offset": 0.0}, lag=0.0)
    recording = carmen_recording([first, second])
    np.testing.assert_allclose(recording.scans["lidar_2"], drive.scans["lidar_2"], atol=1e-6)
    # Lidar 2 in Lidar 1's frame, the truth the calibration must find from a wrong guess
    dx, dy = RIGHT[0] - LEFT[0], RIGHT[1] - LEFT[1]
    c, s = math.cos(LEFT[2]), math.sin(LEFT[2])
    truth = (c * dx + s * dy, -s * dx + c * dy, RIGHT[2] - LEFT[2])
    guess = (truth[0] + 0.2, truth[1] - 0.2, math.degrees(truth[2]) + 15.0)
    assert calibrate_main(["--carmen", str(first), str(second), "--guess",
                           *(f"{v:.6f}" for v in guess)]) == 0
    printed = capsys.readouterr().out
    assert f"{len(recording)} scans of 2 Lidars" in printed
    estimate = next(line for line in printed.splitlines() if line.startswith("lidar_2 in"))
    found = {name: float(value) for name, value in
             re.findall(r"\b(x|y|heading) ([+-][0-9.]+) \+-", estimate)}
    assert abs(found["x"] - truth[0]) < 0.01 and abs(found["y"] - truth[1]) < 0.01, estimate
    assert abs(found["heading"] - math.degrees(truth[2])) < 0.2, estimate


def test_bad_log_sets_name_the_file(drive, tmp_path: Path) -> None:
    front_only = write_log(tmp_path / "front.log", drive, ("lidar_1",), ("FLASER",), {})
    with pytest.raises(LogFormatError, match="front.log: expected RLASER or ROBOTLASER2"):
        carmen_recording([front_only])
    with pytest.raises(LogFormatError, match="expected one CARMEN log"):
        carmen_recording([front_only] * 3)
    late = tmp_path / "late.log"
    late.write_text("".join(laser_line("FLASER", np.ones(180), 500.0 + 0.1 * k) + "\n"
                            for k in range(5)))
    with pytest.raises(LogFormatError, match="no scan of Lidar 1 has a Lidar 2 scan"):
        carmen_recording([front_only, late])
    backwards = tmp_path / "back.log"
    backwards.write_text("".join(laser_line(name, np.ones(180), t) + "\n" for name, t in (
        ("FLASER", 1.0), ("RLASER", 1.0), ("FLASER", 0.5), ("RLASER", 0.5))))
    with pytest.raises(LogFormatError, match="back.log, topic front laser: header stamps"):
        carmen_recording([backwards])


def test_the_calibration_command_names_a_bad_carmen_log(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert calibrate_main(["--carmen", str(tmp_path / "missing.log")]) == 2
    assert "missing.log" in capsys.readouterr().err
    front_only = tmp_path / "front.log"
    front_only.write_text(laser_line("FLASER", np.ones(180), 1.0) + "\n")
    assert calibrate_main(["--carmen", str(front_only)]) == 2
    assert "expected RLASER or ROBOTLASER2" in capsys.readouterr().err
