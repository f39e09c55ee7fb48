"""Scans far apart: ``lidar_odometry`` on a simulated drive thinned to 1 Hz stays within
0.2 m per step; an ordinary 10 Hz drive never needs the far-apart search; a scan with no
overlap, or no returns, is flagged rather than passed off as a pose; the search windows."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import lidar_env  # noqa: F401  (registers DualLidar-v0)
from agents.scripted import PurePursuitDriver
from estimators import SensorSetup
from estimators.matching.icp import ICPParams
from estimators.matching.point_to_line import PointToLineReference
from estimators.odometry.far_scans import (
    GlobalSearch,
    SearchWindow,
    fallback_match,
    far_apart,
    far_match,
    one_turn_start,
    reach_window,
)
from estimators.odometry.local_map import LocalMapOdometry
from estimators.odometry.moving_points import MovingPointFilter
from lidar_env import lidars_with_noise
from lidar_env.core.se2 import relative, wrap_angle
from lidar_env.sensors.lidar import cast_rays
from lidar_env.world.world import World


def drive(world: str, trace: str, seed: int, speed: float, steps: int):
    """Scans, times and true poses of a pure-pursuit drive at 10 Hz (1 cm noise)."""
    env = gym.make("DualLidar-v0", world=world, trace=trace,
                   config={"scan_frame": "sensor",
                           "lidars": lidars_with_noise(range_noise_std=0.01)})
    driver = PurePursuitDriver(speed=speed)
    observation, info = env.reset(seed=seed)
    driver.reset(env)
    observations, times, truth = [observation], [info["time"]], [info["pose"]]
    for _ in range(steps):
        observation, _, terminated, truncated, info = env.step(driver.act(observation, info))
        observations.append(observation)
        times.append(info["time"])
        truth.append(info["pose"])
        if terminated or truncated:
            break
    setup = SensorSetup.from_env(env)
    env.close()
    return setup, observations, np.array(times), np.array(truth)


def step_errors(estimated: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Translation error [m] of each step's relative pose."""
    return np.array([
        np.hypot(*(relative(estimated[k], estimated[k + 1])[:2]
                   - relative(truth[k], truth[k + 1])[:2]))
        for k in range(len(truth) - 1)
    ])


def run(setup, observations, times, start) -> LocalMapOdometry:
    estimator = LocalMapOdometry()
    estimator.reset(setup, start)
    for observation, t in zip(observations, times, strict=True):
        estimator.update(observation, float(t))
    return estimator


def test_a_drive_thinned_to_1_hz_stays_within_0_2_m_per_step() -> None:
    setup, observations, times, truth = drive("closed_to_open", "zigzag", 0, 1.5, 200)
    keep = slice(0, None, 10)  # 1 Hz: steps of ~1.5 m, turns of up to ~50 deg
    estimator = run(setup, observations[keep], times[keep], truth[0])
    steps = np.diff(truth[keep][:, :2], axis=0)
    turns = np.abs(np.diff(np.unwrap(truth[keep][:, 2])))
    assert np.max(np.hypot(*steps.T)) > 1.4 and np.max(turns) > np.radians(40)
    errors = step_errors(estimator.trajectory, truth[keep])
    assert np.max(errors) < 0.2
    assert estimator.far_searches >= len(errors) - 1 and not estimator.poor_matches
    # the same drive, without the far-apart search (windows too small to reach), loses it
    blind = LocalMapOdometry(max_speed=0.1)
    blind.reset(setup, truth[0])
    for observation, t in zip(observations[keep], times[keep], strict=True):
        blind.update(observation, float(t))
    assert np.max(step_errors(blind.trajectory, truth[keep])) > 0.2


def test_an_ordinary_10_hz_drive_never_searches_far() -> None:
    setup, observations, times, truth = drive("open_cylinders", "right_turn", 0, 1.0, 60)
    estimator = run(setup, observations, times, truth[0])
    assert estimator.far_searches == 0 and estimator.fallbacks == 0
    assert not estimator.poor_matches
    assert np.max(step_errors(estimator.trajectory, truth)) < 0.02


def test_a_scan_with_no_overlap_or_no_returns_is_flagged() -> None:
    setup, observations, times, truth = drive("open_cylinders", "right_turn", 0, 1.0, 3)
    _, elsewhere, _, _ = drive("hallway", "zigzag", 1, 1.0, 0)  # another world entirely
    blank = {key: np.full_like(observations[0][key], setup.sensors[k].max_range)
             for k, key in enumerate(setup.keys)}
    estimator = LocalMapOdometry()
    estimator.reset(setup, truth[0])
    for observation, t in zip([*observations[:3], elsewhere[0], blank], np.arange(5) * 0.1,
                              strict=True):
        pose = estimator.update(observation, float(t))
        assert np.all(np.isfinite(pose))
    assert estimator.poor_matches == [3]
    assert estimator.health.skipped == [4]  # no returns: skipped before matching, counted


def test_the_search_window_covers_the_reach_of_the_car() -> None:
    assert reach_window(1.5, 1.5, 1.0, 1.0) == SearchWindow(1.5, 1.5)
    # a glitching stamp (0.01 s after a 1 s clock) must not shrink the window
    assert reach_window(1.5, 1.5, 0.01, 1.0) == SearchWindow(1.5, 1.5)
    assert reach_window(1.5, 1.5, float("nan"), 0.5).linear == pytest.approx(0.75)
    assert reach_window(1.5, 1.5, 4.0, 1.0).angular == pytest.approx(np.pi)
    assert far_apart(np.array([0.3, 0.0, 0.0]), 0.25, np.radians(30))
    assert far_apart(np.array([0.0, 0.0, np.radians(-32)]), 0.25, np.radians(30))
    assert not far_apart(np.array([0.15, 0.02, np.radians(20)]), 0.25, np.radians(30))


def test_speed_limits_must_be_positive() -> None:
    with pytest.raises(ValueError, match="max_speed: expected a positive value"):
        LocalMapOdometry(max_speed=0.0)
    with pytest.raises(ValueError, match="max_turn_rate: expected a positive value"):
        LocalMapOdometry(max_turn_rate=-1.0)


def test_after_a_gap_the_one_turn_start_keeps_the_speed_and_takes_one_turn() -> None:
    # ten intervals at 0.1 m and 0.1 rad each: the constant-velocity guess turns the car by
    # 1 rad, the start by 0.1 rad, 1 m along the chord of that one turn
    start = one_turn_start(np.array([2.0, 1.0, 0.5]), np.array([0.1, 0.0, 0.1]), 10.0)
    np.testing.assert_allclose(start[2], 0.6)
    np.testing.assert_allclose(np.hypot(start[0] - 2.0, start[1] - 1.0), 1.0)
    np.testing.assert_allclose(np.arctan2(start[1] - 1.0, start[0] - 2.0), 0.55)


def test_a_scan_placed_in_space_the_last_scan_saw_free_is_counted() -> None:
    angles = 2 * np.pi * np.arange(360) / 360
    setup = SensorSetup([[0.0, 0.0, 0.0]], angles, 10.0)
    moving_filter = MovingPointFilter(setup)
    room = cast_rays(World(segments=[[-5, -5, 5, -5], [5, -5, 5, 5], [5, 5, -5, 5],
                                     [-5, 5, -5, -5]]), np.zeros((1, 3)), angles, 10.0)[0]
    points = np.column_stack([room * np.cos(angles), room * np.sin(angles)])
    assert moving_filter.seen_free_share(points, np.zeros(3)) == 0.0  # nothing remembered
    moving_filter.remember(np.zeros(3), {"lidar_1": room}, points)
    assert moving_filter.seen_free_share(points, np.zeros(3)) == 0.0  # on the walls
    # moved 1 m along x, the wall at x = -5 lands at x = -4, inside the room seen free (but
    # for its ends, within the margin of the side walls); the other walls stay on or behind
    # walls
    share = moving_filter.seen_free_share(points, np.array([1.0, 0.0, 0.0]))
    on_left_wall = np.mean(np.isclose(points[:, 0], -5.0, atol=1e-6))
    assert 0.9 * on_left_wall < share <= on_left_wall


def test_a_corridor_seen_turned_round_is_not_taken_after_3_s_of_blind_scans() -> None:
    """Down a zigzag corridor after 3 s of blind scans, the corridor seen turned round
    explains the whole scan on the local map, the true pose only the part the map covers:
    taken by its share alone, the car turned round (final error 30 m)."""
    setup, observations, times, truth = drive("hallway", "zigzag", 0, 1.0, 400)
    blind = {key: np.full_like(np.asarray(observations[0][key], dtype=np.float64),
                               setup.max_range) for key in setup.keys}
    blinded = (np.arange(len(observations)) % 90 >= 30) & (np.arange(len(observations)) % 90
                                                            < 60) & (np.arange(len(times)) > 200)
    faulted = [blind if dark else observation
               for dark, observation in zip(blinded, observations, strict=True)]
    estimator = run(setup, faulted, times, truth[0])
    assert estimator.health.blind_stretches == 2
    headings = (estimator.trajectory[:, 2] - truth[:, 2])[~blinded]  # (the guess when blind)
    assert np.all(np.abs(np.angle(np.exp(1j * headings))) < np.radians(5))
    # Turned round, the car ends 30 m off. Along the bare corridor's axis, where it came back
    # after 3 s is the match's guess (0.4-1.8 m off, as small changes elsewhere move it).
    assert np.hypot(*(estimator.trajectory[-1, :2] - truth[-1, :2])) < 2.5


def test_the_fallback_turns_the_car_only_as_far_as_it_can_turn() -> None:
    # ten posts around the origin; the scan was taken turned 150 degrees from the guess: only
    # a search over headings that far out finds it
    centres = np.random.default_rng(3).uniform(-4.0, 4.0, (10, 2))
    around = np.linspace(0.0, 2.0 * np.pi, 12, endpoint=False)
    world_points = (centres[:, None, :] + 0.15 * np.stack([np.cos(around), np.sin(around)],
                                                          axis=1)[None]).reshape(-1, 2)
    true_pose = np.array([0.0, 0.0, np.radians(150.0)])
    c, s = np.cos(true_pose[2]), np.sin(true_pose[2])
    scan = world_points @ np.array([[c, -s], [s, c]])  # world -> car frame (R^T p)
    reference = PointToLineReference(world_points)
    search = GlobalSearch(world_points, 0.05)
    near = SearchWindow(0.5, np.radians(30.0))
    guess = np.zeros(3)
    kept = fallback_match(search, reference, scan, guess, near, 0.6, None, ICPParams(), 0.5)
    assert kept.quality < 0.5  # no heading within reach explains the scan: a poor match
    found = fallback_match(search, reference, scan, guess, near, np.pi, None, ICPParams(), 0.5)
    assert found.quality > 0.9
    assert abs(wrap_angle(found.pose[2] - true_pose[2])) < np.radians(1.0)


def test_a_far_match_no_pose_explains_keeps_the_guess() -> None:
    # a map of one wall and three returns 10 m beyond it (a 3.5 m Lidar back from a blind
    # stretch among far pillars): every pose of the 7 m window explains none of them, and the
    # search's best pose is any; the guess is kept, not a placement metres away
    world_points = np.column_stack([np.linspace(-2.0, 2.0, 41), np.full(41, 2.0)])
    reference = PointToLineReference(world_points)
    search = GlobalSearch(world_points, 0.05)
    scan = np.array([[12.0, -1.0], [12.2, -1.1], [12.4, -0.9]])
    guess = np.array([0.5, 0.2, 0.1])
    window = SearchWindow(7.0, np.pi)
    result = far_match(search, reference, scan, guess, window, ICPParams(), np.zeros(3))
    assert result.quality == 0.0
    np.testing.assert_allclose(result.pose, guess, atol=1e-9)


def test_searches_of_one_map_find_what_searches_of_fresh_ones_find() -> None:
    # the whole window, its near half (the same box: its grid is kept), then another guess
    centres = np.random.default_rng(5).uniform(-4.0, 4.0, (10, 2))
    around = np.linspace(0.0, 2.0 * np.pi, 12, endpoint=False)
    world_points = (centres[:, None, :] + 0.15 * np.stack([np.cos(around), np.sin(around)],
                                                          axis=1)[None]).reshape(-1, 2)
    c, s = np.cos(0.4), np.sin(0.4)
    scan = (world_points - [0.3, -0.2]) @ np.array([[c, -s], [s, c]])
    kept = GlobalSearch(world_points, 0.05)
    for guess, window in [(np.zeros(3), SearchWindow(1.0, 0.6)),
                          (np.zeros(3), SearchWindow(1.0, 0.3)),
                          (np.array([1.0, 0.5, 0.2]), SearchWindow(1.0, 0.6))]:
        found = kept.search(scan, guess, window)
        fresh = GlobalSearch(world_points, 0.05).search(scan, guess, window)
        assert np.array_equal(found.pose, fresh.pose)
        assert (found.score, found.found, found.nodes) == (fresh.score, fresh.found, fresh.nodes)
