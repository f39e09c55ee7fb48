"""After a long blind stretch: ``lidar_odometry`` finds the place along a corridor's axis that
the scan does not see through and whose points the map explains, and keeps the motion model's
pose (flagged lost) where no placement explains the scan."""

from __future__ import annotations

import numpy as np

from estimators.health import Health
from estimators.matching.icp import MatchResult
from estimators.matching.scan_matching import LikelihoodField
from estimators.odometry.blind_resume import (
    along_least_pinned,
    least_pinned_direction,
    tied_run,
    toward_guess,
)
from estimators.odometry.local_map import LocalMapOdometry
from lidar_env.sensors.lidar import cast_rays
from tests.benchmarks.bench_modules import load
from tests.estimators.corridor_scans import corridor, scan_at

bench = load("bench_faults")


def test_along_the_axis_the_place_the_scan_does_not_see_through_wins() -> None:
    """Scan of a corridor ending 2 m ahead; the map has the corridor end at x = 10 (its walls
    on to x = 10, nothing beyond). Every place short of x = 8 explains the whole scan."""
    scan = scan_at(8.0, 10.0)
    walls = corridor(10.0)
    field = LikelihoodField(walls, resolution=0.05)
    information = np.diag([0.0, 500.0, 1e4])  # y and heading pinned, x free
    match = MatchResult(np.array([5.0, 0.0, 0.0]), 1.0, 0.01, 5, True, information)
    assert np.allclose(least_pinned_direction(information), [1.0, 0.0]) or np.allclose(
        least_pinned_direction(information), [-1.0, 0.0])
    pose = along_least_pinned(field, walls, scan, match, reach=6.0, step=0.1)
    assert abs(pose[0] - 8.0) <= 0.3 and pose[1] == 0.0
    # a match the scan does not contradict stands, though places farther on score as well
    at_end = MatchResult(np.array([8.05, 0.0, 0.0]), 1.0, 0.01, 5, True, information)
    assert np.array_equal(along_least_pinned(field, walls, scan, at_end, 6.0, 0.1), at_end.pose)


def test_past_a_corridor_s_open_end_the_place_lies_between_both_bounds() -> None:
    """The car stands 1.5 m past a corridor's open end (walls to x = 10, faced by a wall
    across its end outside, which the map, made inside, never saw); its Lidar reaches 10 m.
    Placed short of the car the scan sees through the walls' ends, though only from
    ``SEEN_THROUGH_MARGIN`` on; placed past it its points run off them and score less. The
    car lies between the two bounds, not at the nearest place free of contradiction."""
    segments = np.array([[0.0, 2.0, 10.0, 2.0], [0.0, -2.0, 10.0, -2.0],
                         [10.0, 2.0, 10.0, 8.0], [10.0, -2.0, 10.0, -8.0]])
    angles = np.radians(np.arange(0.0, 360.0, 0.5))
    ranges = cast_rays((np.zeros((0, 3)), segments), [11.5, 0.0, 0.0], angles, 10.0)[0]
    hit = ranges < 10.0
    scan = ranges[hit, None] * np.column_stack([np.cos(angles[hit]), np.sin(angles[hit])])
    walls = corridor(10.0)
    field = LikelihoodField(walls, resolution=0.05)
    information = np.diag([0.1, 500.0, 1e4])  # x free: the walls pin y and the heading
    for short in (0.6, 1.0, 2.0):
        match = MatchResult(np.array([11.5 - short, 0.0, 0.0]), 1.0, 0.01, 5, True, information)
        pose = along_least_pinned(field, walls, scan, match, reach=6.0, step=0.1)
        assert abs(pose[0] - 11.5) <= 0.1 and pose[1] == 0.0


def test_along_an_axis_the_scan_does_not_pin_the_guess_places_the_car() -> None:
    """Down a corridor mapped to x = 20, the scan of bare walls from x = 6 fits anywhere
    short of the map's end, and a place nearer its mapped part scores a little higher: the
    match lands at x = 5.6, the motion model guessed x = 6. Where the scan would see through
    more map points at the guess's place (of a wall across the corridor at x = 8, which its
    walls reach past), it is no place for the car."""
    y = np.arange(-6.0, 6.0, 0.05)
    walls = corridor(20.0)
    scan = np.concatenate([corridor(12.0), np.column_stack([np.full_like(y, 12.0), y])]) - [
        6.0, 0.0]
    scan = scan[np.abs(scan[:, 0]) < 5.0]  # the walls within 5 m: no end in sight
    free = np.diag([0.5, 500.0, 1e4])  # under min_information (2 points) along x
    match = MatchResult(np.array([5.6, 0.0, 0.0]), 1.0, 0.01, 5, True, free)
    guess = np.array([6.0, 0.05, 0.02])
    moved = toward_guess(walls, scan, match, guess, 2.0, 0.1)
    assert moved is not None and np.allclose(moved, [6.0, 0.0, 0.0])
    pinned = MatchResult(match.pose, 1.0, 0.01, 5, True, np.diag([50.0, 500.0, 1e4]))
    assert toward_guess(walls, scan, pinned, guess, 2.0, 0.1) is None
    across = np.concatenate([walls, np.column_stack([np.full_like(y, 8.0), y])])
    assert toward_guess(across, scan, match, np.array([7.0, 0.0, 0.0]), 2.0, 0.1) is None


def test_a_lost_scan_is_counted_apart_from_the_fault_counts() -> None:
    health = Health()
    health.note_lost(160)
    assert health.lost_scans == 1 and health.lost == [160]
    assert health.counts() == Health().counts()  # the four fault counts stay as they were


def test_after_100_blind_scans_leaving_the_corridor_the_place_is_found_again() -> None:
    """closed_to_open: the car drives out of the corridor while blind; placed where the local
    map explains most, the scan fits anywhere along the axis (4 m off), and of the places
    where it sees through none of the map the nearest lies over a decimetre short of the car.
    The run ends within the fault matrix's target."""
    recording = bench.record_drive("closed_to_open/zigzag")
    faulted = bench.with_faults(recording, bench.faults_for(0.1, 2)["blind_100"](), seed=0)
    clean, _, _ = bench.run("lidar_odometry", recording, recording.truth[0])
    estimator = LocalMapOdometry()
    estimator.reset(recording.setup, recording.truth[0])
    for observation, t in zip(faulted.observations(), faulted.times, strict=True):
        estimator.update(observation, float(t))
    assert estimator.health.blind_stretches == 1 and estimator.health.lost_scans == 0
    error = np.hypot(*(estimator.trajectory[-1, :2] - recording.truth[-1, :2]))
    clean_error = np.hypot(*(clean[-1, :2] - recording.truth[-1, :2]))
    assert error <= bench.FINAL_FACTOR * clean_error + bench.FINAL_MARGIN  # issue 43's target


def test_the_run_of_tied_places_holding_the_start_is_found_whole() -> None:
    tied = np.array([True, False, True, True, True, False, True])
    assert tied_run(tied, 3) == (2, 4)
    assert tied_run(tied, 0) == (0, 0)
    assert tied_run(tied, 6) == (6, 6)
