"""CARMEN log loader: message layouts, compression by magic bytes, beam geometry, errors."""

from __future__ import annotations

import bz2
import gzip
from pathlib import Path

import numpy as np
import pytest

from estimators.datasets.carmen import CarmenFormatError, flaser_beam_angles, load_log
from estimators.paths import SHARED_DATA

DATA = SHARED_DATA / "radish"

FLASER = "FLASER 4 1.0 2.0 3.0 4.5 0.1 0.2 0.3 1.1 1.2 1.3 100.5 host 0.5"
ROBOTLASER = (
    "ROBOTLASER1 0 -1.5 3.0 1.0 20.0 0.01 0 4 1.0 2.0 3.0 4.0 2 7 8 "
    "1.2 2.0 0.5 1.0 2.0 0.5 0.3 0.1 0.5 0.5 0.0 200.25 host 1.25"
)
ODOM = "ODOM 1.0 2.0 0.5 0.3 0.1 0.0 100.4 host 0.4"
LOG_TEXT = "\n".join(
    [
        "# a comment",
        "PARAM robot_frontlaser_offset 0.2 nohost 0",
        ODOM,
        FLASER,
        "",
        "NEFF 15",
        "SYNC tag 1 host 2",
        ROBOTLASER,
        "NEFF 12",
    ]
) + "\n"


def _write(tmp_path: Path, text: str, compression: str = "plain") -> Path:
    # The name lies on purpose: the loader must go by the magic bytes, not the extension.
    path = tmp_path / "log.txt"
    data = text.encode("ascii")
    if compression == "gz":
        data = gzip.compress(data)
    elif compression == "bz2":
        data = bz2.compress(data)
    path.write_bytes(data)
    return path


@pytest.mark.parametrize("compression", ["plain", "gz", "bz2"])
def test_reads_every_message_type_whatever_the_compression(tmp_path: Path, compression: str):
    log = load_log(_write(tmp_path, LOG_TEXT, compression))
    assert [s.message for s in log.scans] == ["FLASER", "ROBOTLASER1"]
    assert len(log.odometry) == 1
    assert log.params["robot_frontlaser_offset"] == "0.2"
    assert dict(log.unknown_messages) == {"NEFF": 2, "SYNC": 1}


def test_flaser_fields(tmp_path: Path):
    scan = load_log(_write(tmp_path, LOG_TEXT)).scans[0]
    np.testing.assert_array_equal(scan.ranges, [1.0, 2.0, 3.0, 4.5])
    np.testing.assert_allclose(scan.angles, np.radians([-90, -45, 0, 45]))
    np.testing.assert_allclose(scan.logged_pose, [0.1, 0.2, 0.3])
    np.testing.assert_allclose(scan.laser_offset, [0.2, 0.0, 0.0])  # from PARAM
    assert scan.timestamp == 100.5 and scan.logger_timestamp == 0.5
    assert scan.line_number == 4
    assert scan.max_range == np.inf


def test_robotlaser_fields_and_mount_from_laser_vs_robot_pose(tmp_path: Path):
    scan = load_log(_write(tmp_path, LOG_TEXT)).scans[1]
    np.testing.assert_array_equal(scan.ranges, [1.0, 2.0, 3.0, 4.0])
    np.testing.assert_allclose(scan.angles, [-1.5, -0.5, 0.5, 1.5])
    assert scan.max_range == 20.0
    # Laser at (1.2, 2.0) and robot at (1.0, 2.0), both heading 0.5 rad: the laser sits
    # 0.2 m from the robot centre along the world x axis, i.e. rotated by -0.5 in the robot.
    np.testing.assert_allclose(
        scan.laser_offset, [0.2 * np.cos(0.5), -0.2 * np.sin(0.5), 0.0], atol=1e-12
    )
    np.testing.assert_allclose(scan.logged_pose, [1.0, 2.0, 0.5])
    assert scan.timestamp == 200.25 and scan.logger_timestamp == 1.25


def test_odometry_fields(tmp_path: Path):
    odom = load_log(_write(tmp_path, LOG_TEXT)).odometry[0]
    np.testing.assert_allclose(odom.pose, [1.0, 2.0, 0.5])
    assert (odom.translational_velocity, odom.rotational_velocity) == (0.3, 0.1)
    assert odom.timestamp == 100.4 and odom.logger_timestamp == 0.4


def test_flaser_beam_convention():
    angles = np.degrees(flaser_beam_angles(180))
    np.testing.assert_allclose(angles[[0, 1, -1]], [-90.0, -89.0, 89.0])
    angles = np.degrees(flaser_beam_angles(181))
    np.testing.assert_allclose(angles[[0, 90, -1]], [-90.0, 0.0, 90.0])
    angles = np.degrees(flaser_beam_angles(360))
    np.testing.assert_allclose(angles[[0, 1, -1]], [-90.0, -89.5, 89.5])
    with pytest.raises(ValueError, match="at least 2 beams"):
        flaser_beam_angles(1)


@pytest.mark.parametrize(
    ("line", "reason"),
    [
        (FLASER.rsplit(" ", 3)[0], "truncated or malformed"),
        ("FLASER 4 1.0 2.0 x 4.5 0.1 0.2 0.3 1.1 1.2 1.3 100.5 host 0.5", "expected numbers"),
        ("FLASER four 1.0", "non-negative integer"),
        ("FLASER", "missing the beam count"),
        (ROBOTLASER.rsplit(" ", 5)[0], "truncated or malformed"),
        ("ROBOTLASER1 0 -1.5 3.0", "truncated header"),
        ("ODOM 1.0 2.0 0.5 0.3 0.1 0.0 100.4 host", "truncated or malformed"),
        ("ODOM 1.0 2.0 nan 0.3 0.1 0.0 100.4 host 0.4", "finite"),
        ("PARAM lonely", "a name and a value"),
    ],
)
def test_malformed_line_names_its_number(tmp_path: Path, line: str, reason: str):
    path = _write(tmp_path, f"{ODOM}\n# comment\n{line}\n{ODOM}\n")
    with pytest.raises(CarmenFormatError, match=reason) as caught:
        load_log(path)
    assert caught.value.line_number == 3
    assert "line 3" in str(caught.value)


def test_missing_file_is_a_readable_error(tmp_path: Path):
    with pytest.raises(FileNotFoundError, match="expected a file"):
        load_log(tmp_path / "absent.clf")


def test_unknown_clock_lists_the_valid_ones(tmp_path: Path):
    with pytest.raises(ValueError, match="expected one of ipc, logger"):
        load_log(_write(tmp_path, LOG_TEXT)).scan_times("gps")


@pytest.mark.skipif(not DATA.is_dir(), reason=f"real logs absent: expected them in {DATA}")
def test_aces_counts_match_its_documentation():
    log = load_log(DATA / "aces.clf.bz2")
    # SOURCE.md: 7,374 FLASER scans of 180 beams and 7,375 ODOM records.
    assert len(log.scans) == 7374
    assert len(log.odometry) == 7375
    assert {len(s.ranges) for s in log.scans} == {180}
    assert not log.unknown_messages
    assert np.all(np.diff(log.scan_times("ipc")) > 0)
