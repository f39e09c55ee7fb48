"""Truth that covers only some scans: each truth pose goes to the nearest scan within the
tolerance, the closest one wins a scan, the rest are left out and counted."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from estimators.datasets.truth import default_tolerance, match_truth, read_truth_file
from estimators.evaluation.tum import write_tum
from lidar_env.core import ConfigError, EstimatorInputError

SCANS = np.arange(100) * 0.1  # 10 Hz


def poses_at(times: np.ndarray) -> np.ndarray:
    return np.column_stack([times, 2 * times, np.sin(times)])


def test_keyframes_match_their_scans_and_the_count_is_reported() -> None:
    truth_times = SCANS[::10] + 0.004  # keyframes, stamped 4 ms after their scan
    match = match_truth(SCANS, truth_times, poses_at(truth_times))
    np.testing.assert_array_equal(match.rows, np.arange(0, 100, 10))
    np.testing.assert_allclose(match.offsets, 0.004)
    assert (match.given, match.matched, match.left_out) == (10, 10, 0)
    assert match.tolerance == pytest.approx(0.05)
    assert "10 of 10 truth poses matched" in match.describe()
    full = match.on_scans(len(SCANS))
    assert np.isnan(full[1]).all() and np.array_equal(full[10], match.poses[1])


def test_truth_far_from_every_scan_or_beaten_to_its_scan_is_left_out() -> None:
    truth_times = np.array([0.05, 0.2, 0.21, 20.0, -3.0])  # between two, two on one, outside
    match = match_truth(SCANS, truth_times, poses_at(truth_times), tolerance=0.02)
    np.testing.assert_array_equal(match.rows, [2])
    np.testing.assert_allclose(match.poses, poses_at(np.array([0.2])))
    assert match.left_out == 4


def test_a_faster_truth_stream_gives_each_scan_its_nearest_pose() -> None:
    mocap = np.arange(0, 10, 0.01) + 0.003  # 100 Hz on its own clock
    match = match_truth(SCANS, mocap, poses_at(mocap))
    assert match.matched == 100
    assert np.max(np.abs(match.offsets)) <= 0.005 + 1e-12


def test_unsorted_stamps_are_matched_by_time() -> None:
    scans = SCANS.copy()
    scans[[40, 41]] = scans[[41, 40]]  # a logger stamp that runs back
    truth_times = np.array([4.0, 4.1])
    match = match_truth(scans, truth_times, poses_at(truth_times))
    np.testing.assert_array_equal(match.rows, [40, 41])
    np.testing.assert_allclose(match.poses, poses_at(np.array([4.1, 4.0])))


def test_bad_inputs_are_named() -> None:
    with pytest.raises(EstimatorInputError, match="truth_poses"):
        match_truth(SCANS, [0.0, 1.0], np.zeros((3, 3)))
    with pytest.raises(ConfigError, match="tolerance"):
        match_truth(SCANS, [0.0], np.zeros((1, 3)), tolerance=-1.0)
    assert default_tolerance([1.0]) == np.inf


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(0, 50, allow_nan=False), min_size=1, max_size=40, unique=True),
       st.lists(st.floats(-5, 55, allow_nan=False), min_size=0, max_size=40),
       st.floats(0, 2))
# three scans equally near the pose at 0.5 (0.0 and 1e-284 round alike): it takes one of them
@example(scans=[0.0, 1.0, 2.3960844349208838e-284], truth=[0.5, -1.0], tolerance=1.0)
def test_every_match_is_within_tolerance_and_the_closest_for_its_scan(
        scans: list[float], truth: list[float], tolerance: float) -> None:
    scan_times, truth_times = np.array(scans), np.array(truth)
    match = match_truth(scan_times, truth_times, poses_at(truth_times), tolerance)
    assert len(set(match.rows.tolist())) == match.matched <= len(truth_times)
    assert np.all(np.abs(match.offsets) <= tolerance)
    gaps = np.abs(truth_times[:, None] - scan_times[None, :])  # (truth, scan)
    nearest = gaps.min(axis=1) if len(truth_times) else np.zeros(0)
    for row, offset in zip(match.rows, match.offsets, strict=True):
        # no truth pose whose one nearest scan is this one lies closer to it (a pose with
        # several scans equally near takes one of them)
        only = np.sum(gaps == nearest[:, None], axis=1) == 1
        claims = (gaps[:, row] == nearest) & (nearest <= tolerance) & only
        if not np.any(claims):
            continue
        assert abs(offset) <= gaps[claims, row].min() + 1e-12
    # every truth pose within the tolerance of a scan gave some scan a pose
    assert match.matched >= (1 if np.any(nearest <= tolerance) else 0)


def test_truth_files_read_as_tum_or_corrected_carmen(tmp_path: Path) -> None:
    times = np.array([1.0, 2.0, 3.0])
    write_tum(tmp_path / "truth.tum", times, poses_at(times))
    read_times, poses, clock = read_truth_file(tmp_path / "truth.tum")
    np.testing.assert_allclose(read_times, times)
    np.testing.assert_allclose(poses, poses_at(times), atol=1e-8)
    assert clock == "tum"
    log = tmp_path / "robot-corrected.log"
    log.write_text("FLASER 2 1.0 2.0 0.5 0.25 0.1 0 0 0 10.5 host 7.25\n")
    read_times, poses, clock = read_truth_file(log)
    np.testing.assert_allclose(poses, [[0.5, 0.25, 0.1]])
    assert clock == "logger" and read_times.tolist() == [7.25]
    with pytest.raises(FileNotFoundError, match="truth file not found"):
        read_truth_file(tmp_path / "missing.tum")
