"""``icp`` and ``pc_fusion`` over clock gaps: after scans lost while the car turned on the
spot the next matches start from the turn rate it held (``icp``: not from the gap's turn
spread over the few intervals its creep bears out; ``pc_fusion``: also, where neither guess's
match explains the scans); a gap after stamps a microsecond apart (Intel's repeated
stamps, run forward) counts scan intervals no shorter than a Lidar's; and the speed after a gap
keeps what it was along a direction the gap's match leaves free."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from estimators import SensorSetup, make
from estimators.datasets.recording import Recording
from estimators.matching.icp_estimator import held_where_free
from lidar_env.core.se2 import compose, relative, wrap_angle
from tests.benchmarks.bench_modules import load
from tests.estimators.matching.test_icp import ANGLES, ray_cast

bench = load("bench_faults")


def scans(recording: Recording, kept: np.ndarray) -> Recording:
    """The observations ``kept`` (indices) of ``recording``."""
    return dataclasses.replace(recording, times=recording.times[kept],
                               scans={key: s[kept] for key, s in recording.scans.items()},
                               truth=recording.truth[kept])


@pytest.mark.skipif(not all(path.exists() for path in bench.log_paths("aces")),
                    reason="ACES or aces-corrected absent")
@pytest.mark.parametrize("name", ["icp", "pc_fusion"])
def test_aces_scans_lost_in_a_turn_on_the_spot_keep_the_estimate_on_the_clean_runs_track(
        name: str) -> None:
    # ACES's scans 6344-6443 (the recording starts on the log's first truth, scan 136), of
    # which 6394-6403 (1.9 s) are lost while the robot turns 73 degrees on the spot, creeping
    # 6 cm; then it turns 0.04-0.25 rad a scan
    recording = bench.log_recording("aces", 0, 6400)
    window = np.arange(6208, 6308)
    lost = (window >= window[50]) & (window < window[60])
    clean = bench.run(name, scans(recording, window), np.zeros(3))[0][~lost]
    faulted, health, _ = bench.run(name, scans(recording, window[~lost]), np.zeros(3))
    assert health["clock_jumps"] == 1
    off = relative(clean[-1], faulted[-1])
    assert np.hypot(off[0], off[1]) < 0.1 and abs(off[2]) < 0.02  # [m], [rad]


def test_a_gap_after_stamps_a_microsecond_apart_is_counted_in_lidar_intervals() -> None:
    # four scans stamped 1 us apart, then 0.6 s: over 1 us intervals the gap would span
    # 600 000 of them and the guess lie 36 km away
    rng = np.random.default_rng(2)
    estimator = make("icp")
    pose = np.array([-3.0, -2.0, 0.6])
    estimator.reset(SensorSetup(np.zeros((1, 3)), ANGLES, 20.0), pose)
    step = np.array([0.06, 0.0, 0.01])
    for t in [0.0, 1e-6, 2e-6, 3e-6, 0.6, 0.7, 0.8]:
        estimator.update({"lidar_1": ray_cast(pose, noise=0.01, rng=rng)}, t)
        error = relative(pose, estimator.pose)
        assert np.hypot(error[0], error[1]) < 0.05 and abs(wrap_angle(error[2])) < 0.01, t
        pose = compose(pose, step)


def test_the_speed_after_a_gap_keeps_its_old_part_along_a_direction_the_match_leaves_free(
) -> None:
    # down a corridor along x the match pins y (40 points) and leaves x free (0.5 points)
    information = np.diag([0.5, 40.0])
    held = held_where_free(np.array([0.08, 0.02]), np.array([0.1, 0.0]), information, 2.0)
    np.testing.assert_allclose(held, [0.1, 0.02])
    np.testing.assert_array_equal(held_where_free(np.array([0.08, 0.02]), np.array([0.1, 0.0]),
                                                  information * 100.0, 2.0), [0.08, 0.02])
