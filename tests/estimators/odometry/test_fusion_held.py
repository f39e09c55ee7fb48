"""``pc_fusion``'s keyframes with beams lost at random take them back from the scans held
around them, where the world holds them; a keyframe that lost few beams stays as measured."""

from __future__ import annotations

import numpy as np
import pytest

import estimators
from estimators.base import SensorSetup
from estimators.matching.rotation_pc import PreparedScan, ScanMatcher
from estimators.odometry.fusion_held import HeldKeyframeScans, returned
from lidar_env.core import ConfigError
from tests.benchmarks.bench_modules import load

bench = load("bench_faults")

#: One full-turn Lidar of 360 beams at the car's centre in a 10 m square room.
MAX_RANGE, HALF_SIDE = 20.0, 5.0
ANGLES = np.radians(np.arange(360.0)) - np.pi
SETUP = SensorSetup(np.zeros((1, 3)), ANGLES, MAX_RANGE)
MATCHER = ScanMatcher(MAX_RANGE, 200, None, 3)


def room_scan(pose: np.ndarray, lost: np.ndarray) -> tuple[PreparedScan, ...]:
    """The room's walls seen from ``pose`` (3,), the ``lost`` beams (360,) without a return."""
    bearing = ANGLES + pose[2]
    c, s = np.cos(bearing), np.sin(bearing)
    with np.errstate(divide="ignore", invalid="ignore"):  # along an axis: the other pair
        ranges = np.minimum(
            np.where(c != 0, (np.copysign(HALF_SIDE, c) - pose[0]) / c, np.inf),
            np.where(s != 0, (np.copysign(HALF_SIDE, s) - pose[1]) / s, np.inf))
    ranges[lost] = MAX_RANGE
    return (MATCHER.prepare(ranges, ANGLES),)


def on_walls(scan: PreparedScan, pose: np.ndarray) -> np.ndarray:
    """How far [m] each return of ``scan`` taken at ``pose`` lies from the room's walls."""
    hit = returned(scan)
    bearing = scan.beam_angles[hit] + pose[2]
    x = pose[0] + scan.ranges[hit] * np.cos(bearing)
    y = pose[1] + scan.ranges[hit] * np.sin(bearing)
    return np.abs(np.maximum(np.abs(x), np.abs(y)) - HALF_SIDE)


def poses(count: int) -> list[np.ndarray]:
    """A car driving 5 cm and turning 0.02 rad a scan."""
    return [np.array([0.05 * i, 0.02 * i, 0.02 * i]) for i in range(count)]


def held(count: int, rng: np.random.Generator) -> tuple[HeldKeyframeScans, list[np.ndarray],
                                                          list[tuple[PreparedScan, ...]]]:
    """``count`` scans with half the beams lost at random, each held as it comes."""
    holder = HeldKeyframeScans(SETUP.mounts, [ANGLES], MATCHER)
    path = poses(count)
    scans = [room_scan(pose, rng.random(len(ANGLES)) < 0.5) for pose in path]
    for scan, pose in zip(scans, path, strict=True):
        holder.hold(scan, tuple(pose.tolist()), 1.0)
    return holder, path, scans


def test_a_keyframe_with_half_its_beams_lost_gets_them_back_on_the_walls() -> None:
    holder, path, scans = held(9, np.random.default_rng(0))
    keyframe = holder.keyframe(scans[-1], tuple(path[-1].tolist()))[0]
    assert np.count_nonzero(returned(scans[-1][0])) < 0.6 * len(ANGLES)
    assert np.count_nonzero(returned(keyframe)) >= 0.98 * len(ANGLES)
    assert np.max(on_walls(keyframe, path[-1])) < 1e-9
    # every beam that returned keeps its own return
    own = returned(scans[-1][0])
    assert np.array_equal(keyframe.ranges[own], scans[-1][0].ranges[own])


def test_the_first_keyframe_is_filled_from_the_scans_after_it() -> None:
    holder = HeldKeyframeScans(SETUP.mounts, [ANGLES], MATCHER)
    rng = np.random.default_rng(1)
    path = poses(9)
    first = room_scan(path[0], rng.random(len(ANGLES)) < 0.5)
    holder.hold(first, tuple(path[0].tolist()), 0.0)
    keyframe = first
    for pose in path[1:]:
        holder.hold(room_scan(pose, rng.random(len(ANGLES)) < 0.5), tuple(pose.tolist()), 1.0)
        keyframe = holder.refill(keyframe, tuple(path[0].tolist()))
    assert np.count_nonzero(returned(keyframe[0])) >= 0.98 * len(ANGLES)
    assert np.max(on_walls(keyframe[0], path[0])) < 1e-9


def test_a_keyframe_that_lost_few_beams_stays_as_measured() -> None:
    """Beams turning into the open (a doorway passed) are not a Lidar losing beams."""
    holder, path, _ = held(9, np.random.default_rng(2))
    door = np.zeros(len(ANGLES), dtype=bool)
    door[100:130] = True
    scan = room_scan(path[-1], door)
    assert holder.keyframe(scan, tuple(path[-1].tolist()))[0] is scan[0]


def test_held_scans_is_a_whole_number_of_scans() -> None:
    with pytest.raises(ConfigError, match="whole number of scans"):
        estimators.make("pc_fusion", held_scans=-1)


def log_window(name: str, first: int) -> object:
    """``pytest.param`` of the log window ``name`` from scan ``first``, skipped without it."""
    absent = not all(path.exists() for path in bench.log_paths(name))
    return pytest.param(name, first, id=f"{name}:{first}", marks=pytest.mark.skipif(
        absent, reason=f"needs the {name} Radish log and its corrected poses"))


# Intel's logger stamps its ~5 Hz scans in bunches (median interval 0.06 s, mean 0.2 s): its
# windows also need the steps timed at the mean interval (estimators/odometry/fusion_motion.py)
@pytest.mark.parametrize(("name", "first"), [log_window("aces", 0), log_window("aces", 3000),
                                             log_window("intel", 3000),
                                             log_window("intel", 6000)])
def test_log_windows_with_half_the_beams_dropped_meet_the_fault_targets(name: str,
                                                                         first: int) -> None:
    recording = bench.log_recording(name, first, 600)
    clean, _, _ = bench.run("pc_fusion", recording, bench.start_of(recording.truth))
    clean_jump, clean_final = bench.score(clean, clean, recording.truth)
    run = bench.faulted_score("pc_fusion", recording, "dropout_half", clean)
    assert bench.verdict(run, clean_jump, clean_final)
