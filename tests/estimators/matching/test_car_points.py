"""Scans to car-frame points: the compiled, per-setup :class:`CarPoints` against the pure
:func:`scan_to_points` of each Lidar mapped through its mount, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimators.base import SensorSetup
from estimators.matching.scan_matching import CarPoints, scan_to_points, scans_to_car_points


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n_lidars=st.integers(1, 3), beams=st.integers(3, 400),
       min_range=st.sampled_from([0.0, 0.05, 0.5]))
def test_car_points_are_each_scans_points_through_its_mount_bit_for_bit(
        seed: int, n_lidars: int, beams: int, min_range: float) -> None:
    rng = np.random.default_rng(seed)
    mounts = np.column_stack([rng.uniform(-1, 1, (n_lidars, 2)), rng.uniform(-4, 4, n_lidars)])
    angles = np.sort(rng.uniform(-np.pi, np.pi, beams))
    setup = SensorSetup(mounts, angles, 8.0)
    scans = {}
    for key in setup.keys:  # no returns (0, max range), near ones and ordinary ones
        ranges = rng.uniform(0.0, 10.0, beams)
        ranges[rng.random(beams) < 0.2] = 0.0
        ranges[rng.random(beams) < 0.1] = 8.0
        scans[key] = ranges
    pure = np.concatenate([
        scan_to_points(scans[key], sensor.beam_angles, sensor.max_range, sensor.mount, min_range)
        for key, sensor in zip(setup.keys, setup.sensors, strict=True)])
    converter = CarPoints(setup, min_range)
    once = scans_to_car_points(scans, setup, min_range)
    for points in (converter(scans), converter(scans), once):
        assert points.shape == pure.shape
        assert points.tobytes() == pure.tobytes()


def test_a_scan_of_the_wrong_length_is_named() -> None:
    setup = SensorSetup(np.zeros((1, 3)), np.linspace(-1.0, 1.0, 5), 8.0)
    with pytest.raises(ValueError, match=r"lidar_1: expected 5 ranges \(one per beam\), got"):
        CarPoints(setup)({"lidar_1": np.ones(4)})
