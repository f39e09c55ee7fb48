"""``icp``'s reference: each beam without a return keeps its last return, moved with the car,
for ``held_scans`` scans; with it half the beams dropped at random on every scan no longer
random-walk the heading, and a place seen too little after a long blind stretch is reported
lost."""

from __future__ import annotations

import numpy as np
import pytest

from estimators import SensorSetup, make
from estimators.matching.held_returns import HeldReturns
from estimators.matching.scan_matching import CarPoints
from lidar_env.core import ConfigError, EstimatorInputError
from tests.benchmarks.bench_modules import load

bench = load("bench_faults")

MAX_RANGE = 10.0
SETUP = SensorSetup(np.zeros((1, 3)), np.arange(4) * np.pi / 2, MAX_RANGE)


def observed(ranges: list[float]) -> tuple[dict[str, np.ndarray], np.ndarray]:
    scans = {"lidar_1": np.array(ranges, dtype=np.float64)}
    return scans, CarPoints(SETUP)(scans)


def in_frame(pose: np.ndarray, world: np.ndarray) -> np.ndarray:
    """``world`` (2,) seen from the car at ``pose`` (3,), both in the same frame."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    return np.array([[c, s], [-s, c]]) @ (world - pose[:2])


def test_a_beam_without_a_return_keeps_its_last_one_where_the_world_holds_it() -> None:
    held = HeldReturns(CarPoints(SETUP, 0.05), max_age=2)
    scans, points = observed([2.0, 3.0, 4.0, 5.0])
    assert np.array_equal(held.start(scans, points), points)  # a full scan: its own reference
    wall = np.array([0.0, 3.0])  # beam 1's return in the first car frame
    step = np.array([0.4, 0.1, 0.2])
    scans, points = observed([2.0, MAX_RANGE, 4.0, 5.0])
    reference = held.advance(scans, points, step)
    assert len(reference) == 4 and np.allclose(reference[[0, 2, 3]], points)
    assert np.allclose(reference[1], in_frame(step, wall))
    # one more scan without it: still there, moved again (the car drove straight on)
    second = np.array([0.4 + 0.4 * np.cos(0.2), 0.1 + 0.4 * np.sin(0.2), 0.2])
    reference = held.advance(scans, points, np.array([0.4, 0.0, 0.0]))
    assert np.allclose(reference[1], in_frame(second, wall))
    # older than max_age scans: gone; a return of its own replaces it
    assert len(held.advance(scans, points, np.zeros(3))) == 3
    scans, points = observed([2.0, 2.5, 4.0, 5.0])
    assert np.array_equal(held.advance(scans, points, np.zeros(3)), points)


def test_the_beams_that_returned_are_those_that_give_the_points_in_order() -> None:
    car_points = CarPoints(SETUP, 0.05)
    scans, points = observed([2.0, MAX_RANGE, 0.01, 5.0])
    hit = car_points.returned(scans)
    assert car_points.beams == 4 and hit.tolist() == [True, False, False, True]
    assert np.allclose(points, [[2.0, 0.0], [0.0, -5.0]])


def test_points_that_are_not_the_scans_returns_are_refused() -> None:
    held = HeldReturns(CarPoints(SETUP, 0.05))
    scans, points = observed([2.0, MAX_RANGE, 4.0, 5.0])
    with pytest.raises(EstimatorInputError, match="one per return"):
        held.start(scans, points[:2])


def test_skipped_scans_age_the_held_returns() -> None:
    held = HeldReturns(CarPoints(SETUP, 0.05), max_age=8)
    held.start(*observed([2.0, 3.0, 4.0, 5.0]))
    scans, points = observed([2.0, MAX_RANGE, 4.0, 5.0])
    assert len(held.advance(scans, points, np.zeros(3), scans_since=9)) == 3


@pytest.mark.parametrize("count", [-1, 1.5, True])
def test_held_scans_is_a_whole_number_of_scans(count: object) -> None:
    with pytest.raises(ConfigError, match="held scans"):
        make("icp", held_scans=count)


needs_aces = pytest.mark.skipif(not all(path.exists() for path in bench.log_paths("aces")),
                                reason="ACES or aces-corrected absent")


@pytest.fixture(scope="module")
def aces_6000() -> tuple[object, np.ndarray, float]:
    recording = bench.log_recording("aces", 6000, 600)
    clean, _, _ = bench.run("icp", recording, bench.start_of(recording.truth))
    return recording, clean, bench.score(clean, clean, recording.truth)[1]


@needs_aces
def test_aces_with_half_the_beams_dropped_ends_within_twice_the_clean_error(
        aces_6000: tuple[object, np.ndarray, float]) -> None:
    # matched on the previous (halved) scan alone, the heading random-walked: 2.9 m off
    recording, clean, clean_final = aces_6000
    run = bench.faulted_score("icp", recording, "dropout_half", clean)
    assert run.final <= bench.final_bound(clean_final)


@needs_aces
def test_aces_after_100_blind_scans_a_place_seen_too_little_is_reported_lost(
        aces_6000: tuple[object, np.ndarray, float]) -> None:
    # the first scan back shares a sixth of its points with the last one; the best match
    # explains 12 % of it, 9 m off the car, and contradicts nothing the last scan saw
    recording, clean, clean_final = aces_6000
    run = bench.faulted_score("icp", recording, "blind_100", clean)
    assert run.covered < bench.COVERED_SHARE
    assert run.health["lost_scans"] >= 1
    assert bench.verdict(run, 0.0, clean_final)
