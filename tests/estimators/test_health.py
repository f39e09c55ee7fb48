"""Estimators under sensor faults (``estimators.health``, ``Estimator.update``'s screen):
unusable scans skipped and counted, frozen sensors and clock jumps reported, memory and time
bounded whatever the clock does (issue 43, items 1-6)."""

from __future__ import annotations

import tracemalloc

import gymnasium as gym
import numpy as np
import pytest

import estimators
import lidar_env  # noqa: F401  (registers DualLidar-v0)
from agents import PurePursuitDriver
from estimators import SensorSetup
from estimators.base import Sensor
from estimators.health import (
    CLOCK_HISTORY,
    CLOCK_JUMP_FACTOR,
    MIN_RETURNS,
    Health,
    Observations,
    ScanScreen,
    SortedWindow,
    evident_time_step,
    evident_turn_time,
    intervals_since_used,
)
from estimators.odometry.far_scans import GlobalSearch, SearchWindow
from lidar_env.faults import Blind, ClockJump, FrozenLidar, apply_faults
from lidar_env.faults.frames import Frame


@pytest.fixture(scope="module")
def drive():
    """60 scans of a pure-pursuit closed_to_open zigzag: setup, observations, times, poses."""
    env = gym.make("DualLidar-v0", world="closed_to_open", trace="zigzag")
    observation, info = env.reset(seed=0)
    driver = PurePursuitDriver()
    driver.reset(env)
    rows = [(observation, info["time"], info["pose"])]
    for _ in range(60):
        observation, _, _, _, info = env.step(driver.act(observation, info))
        rows.append((observation, info["time"], info["pose"]))
    return SensorSetup.from_env(env), rows


def faulted(setup, rows, faults):
    frames = [Frame(o, t, k) for k, (o, t, _) in enumerate(rows)]
    max_ranges = {key: s.max_range for key, s in zip(setup.keys, setup.sensors, strict=True)}
    return [(f.scans, f.time, rows[f.step][2]) for f in apply_faults(frames, faults, 0,
                                                                       max_ranges)]


def run(name, setup, rows):
    estimator = estimators.make(name)
    estimator.reset(setup, rows[0][2])
    for observation, t, _ in rows:
        estimator.update(observation, t)
    return estimator


def step_errors(estimator, rows):
    truth = np.array([p for _, _, p in rows])
    return np.linalg.norm(np.diff(estimator.trajectory[:, :2], axis=0)
                          - np.diff(truth[:, :2], axis=0), axis=1)


@pytest.mark.parametrize("name", ["lidar_odometry", "pc_fusion", "icp"])
def test_every_other_scan_blind_is_skipped_not_a_jump(drive, name):
    """Item 1: lidar_odometry and slam jumped 5 m in one step, pc_fusion ended 17.7 m off."""
    setup, rows = drive
    clean = run(name, setup, rows)
    blind = run(name, setup, faulted(setup, rows, [Blind(every=2)]))
    assert blind.health.skipped_scans == 30
    assert blind.health.skipped == list(range(1, 61, 2))
    assert step_errors(blind, rows).max() <= step_errors(clean, rows).max() + 0.3
    assert len(blind.trajectory) == len(blind.times) == 61


def test_icp_on_a_few_returns_never_jumps_metres(drive):
    """Item 2: icp jumped 9.94 m in one step on every 72nd beam (at most 10 returns)."""
    setup, rows = drive
    keep = np.zeros(360, dtype=bool)
    keep[::72] = True
    sparse = SensorSetup(sensors=[Sensor(s.mount, s.beam_angles[keep], s.max_range)
                                  for s in setup.sensors])
    icp = run("icp", sparse, [({k: o[k][keep] for k in setup.keys}, t, p) for o, t, p in rows])
    steps = np.hypot(*np.diff(icp.trajectory[:, :2], axis=0).T)
    assert steps.max() < 2.0
    assert icp.health.skipped_scans > 0


@pytest.mark.parametrize("name", ["lidar_odometry", "icp", "pc_fusion"])
def test_a_frozen_lidar_is_detected_and_reported(drive, name):
    """Item 3: a frozen second Lidar cost metres with no warning."""
    setup, rows = drive
    frozen = run(name, setup, faulted(setup, rows, [FrozenLidar(keys=("lidar_2",))]))
    assert frozen.health.frozen_scans == 60
    assert frozen.health.skipped_scans == 0  # the first Lidar carries on
    final = np.hypot(*(frozen.trajectory[-1, :2] - rows[-1][2][:2]))
    clean = run(name, setup, rows)
    assert final <= 2 * np.hypot(*(clean.trajectory[-1, :2] - rows[-1][2][:2])) + 0.1


@pytest.mark.parametrize("name", ["pc_fusion", "pc_rot_icp", "lidar_odometry"])
def test_a_clock_jump_with_continuous_scans_is_not_trusted(drive, name):
    """Item 4: a 3 s jump put pc_fusion 3.2 m and pc_rot_icp 2.9 m off."""
    setup, rows = drive
    jumped = run(name, setup, faulted(setup, rows, [ClockJump(jump=3.0, every=None,
                                                              probability=0.0)]))
    assert jumped.health.clock_jumps == 0
    jumped = run(name, setup, faulted(setup, rows, [ClockJump(jump=3.0, every=100, offset=20)]))
    assert jumped.health.clock_jumps == 1 and jumped.health.jumps == [20]
    clean = run(name, setup, rows)
    assert np.hypot(*(jumped.trajectory[-1, :2] - clean.trajectory[-1, :2])) < 0.1


def test_the_far_search_window_stops_where_the_scan_can_touch_the_map():
    """Item 5: a 300 s gap sized the search by max_speed x gap: a (10, 18001, 18001) array."""
    rng = np.random.default_rng(0)
    angles = rng.uniform(0, 2 * np.pi, 400)
    walls = np.c_[4 * np.cos(angles), 3 * np.sin(angles)]
    search = GlobalSearch(walls, 0.05)
    tracemalloc.start()
    found = search.search(walls[::2] - [0.3, 0.1], np.zeros(3), SearchWindow(450.0, 0.3))
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 200e6  # bytes: the map's extent, not 900 m squared
    assert np.hypot(found.pose[0] - 0.3, found.pose[1] - 0.1) < 0.2


def test_slam_on_random_ranges_starts_no_loop_closure():
    """Item 6: slam on uniformly random ranges ran for minutes in loop-closure searches."""
    setup = SensorSetup(np.array([[0.3, 0, 0], [-0.3, 0, np.pi]]),
                        2 * np.pi * np.arange(360) / 360, 10.0)
    rng = np.random.default_rng(0)
    slam = estimators.make("slam")
    slam.reset(setup, np.zeros(3))
    for k in range(8):
        slam.update({key: rng.uniform(0, 10, 360) for key in setup.keys}, 0.1 * k)
    assert slam.loop_attempts == []
    assert np.all(np.isfinite(slam.trajectory))


def test_a_long_blind_stretch_is_flagged(drive):
    setup, rows = drive
    odometry = run("lidar_odometry", setup,
                   faulted(setup, rows, [Blind(every=100, stretch=15, offset=20)]))
    assert odometry.health.blind_stretches == 1
    assert odometry.health.stretches == [(20, 34)]
    # after the fact the stretch lies on the way between the used poses around it
    steps = np.hypot(*np.diff(odometry.trajectory[19:36, :2], axis=0).T)
    np.testing.assert_allclose(steps, steps[0], rtol=1e-3)


def test_the_screen_tells_frozen_from_standing_still():
    screen = ScanScreen([10.0, 10.0], [0, 1])
    a, b = np.full(36, 2.0), np.full(36, 3.0)
    screen.screen([a, b], moving=False)
    screened, usable = screen.screen([a.copy(), b.copy()], moving=False)  # standing still
    assert usable and screen.health.frozen_scans == 0
    screened, usable = screen.screen([a.copy(), b + 0.01], moving=False)  # only one repeats
    assert usable and screen.health.frozen_scans == 1 and np.all(screened[0] == 0.0)
    screened, usable = screen.screen([a.copy(), b + 0.01], moving=True)  # both repeat, moving
    assert not usable and screen.health.frozen_scans == 3  # skipped: the car drives on
    assert np.all(screened[0] == 0.0) and np.all(screened[1] == 0.0) and screen.all_frozen
    screened, usable = screen.screen([a.copy(), b + 0.01], moving=False)  # both repeat, standing
    assert usable and screen.health.frozen_scans == 3 and np.all(screened[0] == a)
    assert not screen.all_frozen
    blank = np.full(36, 10.0)
    screen.screen([blank, blank], moving=True)
    screen.screen([blank, blank], moving=True)  # a blank scan repeating is not frozen
    assert screen.health.frozen_scans == 3


def test_few_returns_are_unusable_and_stretches_counted():
    screen = ScanScreen([10.0], [0])
    scan = np.full(36, 10.0)
    scan[: MIN_RETURNS - 1] = 2.0
    assert not screen.screen([scan], moving=False)[1]
    scan[MIN_RETURNS - 1] = 2.0
    assert screen.screen([scan + 0.1], moving=False)[1]
    for index in range(1, 13):
        screen.skip(index)
    assert screen.used_one() == 12
    assert screen.health.counts() == {"skipped_scans": 12, "frozen_scans": 0,
                                      "clock_jumps": 0, "blind_stretches": 1}
    assert screen.health.stretches == [(1, 12)] and not screen.health.ok
    assert Health().ok


def test_the_evident_time_step_follows_the_scans_over_a_jump():
    assert evident_time_step(0.1, 1.0, 0.1, 0.1) == 0.1  # no jump: the stamp
    assert evident_time_step(0.1, 1.0, 3.1, 0.1) == pytest.approx(0.1)  # scans ran on
    assert evident_time_step(1.0, 1.0, 3.1, 0.1) == pytest.approx(1.0)  # a real gap
    assert evident_time_step(0.0, 0.0, 3.1, 0.1) == 0.1  # standing: the typical step


def test_intervals_count_skipped_scans_and_clock_gaps() -> None:
    assert intervals_since_used(0, False, 0.1, 0.1) == 1.0
    assert intervals_since_used(30, False, 3.1, 0.1) == 31.0
    assert intervals_since_used(0, True, 1.1, 0.1) == pytest.approx(11.0)
    assert intervals_since_used(2, True, 0.2, 0.0) == 3.0  # no typical step known yet


def test_a_clock_jump_is_five_times_numpys_median_of_the_last_steps() -> None:
    """A step is a jump exactly when it exceeds ``CLOCK_JUMP_FACTOR`` times the smallest and
    ``np.median`` of the last ``CLOCK_HISTORY`` steps that were not jumps (bursty stamps)."""
    rng = np.random.default_rng(4)
    screen = ScanScreen([10.0], [0])
    kept: list[float] = []
    steps = rng.choice([0.001, 0.01, 0.013, 0.1, 0.1, 0.2, 1.0, 3.0], 600) * rng.uniform(
        0.99, 1.01, 600)
    for index, dt in enumerate(steps.tolist()):
        recent = kept[-CLOCK_HISTORY:]
        expected = len(recent) >= 3 and dt > CLOCK_JUMP_FACTOR * max(
            min(recent), float(np.median(recent)))
        assert screen.watch_clock(index, dt) == expected
        if not expected:
            kept.append(dt)
    assert 0 < screen.health.clock_jumps < len(steps)


def test_a_sorted_window_keeps_its_last_values_and_numpys_median() -> None:
    rng = np.random.default_rng(5)
    window = SortedWindow(6)
    seen: list[float] = []
    for value in rng.choice([0.1, 0.1, 0.2, 0.3, -1.0, 2.5], 200).tolist():
        window.push(value)
        seen.append(value)
        assert list(window) == seen[-6:]
        assert window.ordered == sorted(seen[-6:])
        assert window.median == np.median(seen[-6:])


@pytest.mark.parametrize(("turn", "held", "elapsed", "least", "turn_time"), [
    (-1.2, -0.1, 15.0, 1.0, 12.0),  # at the rate held
    (0.05, 0.1, 15.0, 1.0, 1.0),  # less than one interval's turn: at least ``least``
    (0.05, 0.1, 15.0, 3.0, 3.0),  # never less than the translation's time
    (0.3, 0.0, 15.0, 1.0, 15.0),  # no turn held: over the whole gap
    (3.0, 0.1, 15.0, 1.0, 15.0),  # faster than held: over the whole gap
])
def test_a_gaps_turn_takes_the_time_the_turn_rate_held_needs(
        turn: float, held: float, elapsed: float, least: float, turn_time: float) -> None:
    assert evident_turn_time(turn, held, elapsed, least) == pytest.approx(turn_time)


def test_a_frozen_observation_holds_the_last_pose_where_a_skipped_one_coasts() -> None:
    observations = Observations()
    poses = [np.zeros(3), np.array([0.1, 0.0, 0.05])]
    observations.use(0, 0.0)
    observations.use(1, 0.1)
    np.testing.assert_allclose(observations.skip(poses, 0.2, hold=True), poses[1])
    np.testing.assert_allclose(observations.skip(poses, 0.3, hold=True), poses[1])
    coasted = observations.skip(poses, 0.4)
    assert coasted[0] > poses[1][0] + 0.05
