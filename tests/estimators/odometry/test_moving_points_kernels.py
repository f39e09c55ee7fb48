"""The moving-point filter's fast kernels give their plain forms' answers exactly: the
seen-through test from each beam's free reach, the near-anchor test on a grid, the anchors'
thinning kept scan by scan."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from estimators.matching.scan_matching import voxel_downsample
from estimators.odometry.free_space import (
    BeamGeometry,
    _free_ranges,
    _seen_through_free,
    _seen_through_kernel,
)
from estimators.odometry.moving_points import _near_any, _near_any_plain
from estimators.odometry.thinned_scans import ThinnedScans


def _beam_angles(kind: int, n: int, first: float, rng: np.random.Generator) -> np.ndarray:
    """A full turn, a 180-degree fan, or uneven beams, beam 0 at ``first`` [rad]."""
    if kind == 0:
        return first + 2 * np.pi * np.arange(n) / n
    if kind == 1:
        return first + np.linspace(0.0, np.pi, n)
    return first + np.sort(rng.uniform(0.0, 2 * np.pi * rng.uniform(0.3, 1.0), n))


@settings(max_examples=150, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), kinds=st.lists(st.integers(0, 2), min_size=1, max_size=3),
       first=st.sampled_from([0.0, -np.pi / 2, np.pi, 3.0 * np.pi, -7.0]),
       margin=st.sampled_from([0.0, 0.2]), min_range=st.sampled_from([0.0, 0.05, 0.5]),
       resolution=st.sampled_from([math.inf, 0.1, 0.5]))
def test_seen_through_from_free_reach_matches_the_beam_by_beam_kernel(
        seed: int, kinds: list[int], first: float, margin: float, min_range: float,
        resolution: float) -> None:
    rng = np.random.default_rng(seed)
    angles = [_beam_angles(kind, int(rng.integers(1, 40)), first, rng) for kind in kinds]
    max_ranges = [float(rng.uniform(1.0, 10.0)) for _ in kinds]
    beams = BeamGeometry(angles, max_ranges)
    ranges = np.concatenate([rng.uniform(0.0, 1.3 * m, len(a))
                             for a, m in zip(angles, max_ranges, strict=True)])
    ranges[rng.random(len(ranges)) < 0.1] = np.nan  # a reading that says nothing
    ranges[rng.random(len(ranges)) < 0.1] = np.inf
    poses = np.column_stack([rng.uniform(-2, 2, (len(kinds), 2)),
                             rng.uniform(-4, 4, len(kinds))])
    points = rng.uniform(-8, 8, (int(rng.integers(0, 300)), 2))
    points[: len(points) // 10] = np.round(points[: len(points) // 10])  # on axes, at a pose
    if len(points):
        points[0] = poses[0, :2]
    plain = _seen_through_kernel(points, poses, ranges, beams.starts, beams.relative_angles,
                                 beams.order, beams.params, margin, min_range, resolution)
    free = _free_ranges(ranges, beams.starts, beams.order, beams.params, min_range)
    fast = _seen_through_free(points, poses, free, beams.starts, beams.relative_angles,
                              beams.params, margin, min_range, resolution)
    np.testing.assert_array_equal(fast, plain)
    np.testing.assert_array_equal(beams.judge(points, poses, ranges, margin, min_range,
                                              resolution), plain)


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), radius=st.sampled_from([0.3, 0.05, 1.0, 0.25]),
       scale=st.sampled_from([1.0, 10.0, 1e3]))
def test_near_any_on_a_grid_matches_brute_force(seed: int, radius: float, scale: float) -> None:
    rng = np.random.default_rng(seed)
    points = rng.uniform(-scale, scale, (int(rng.integers(0, 200)), 2))
    anchors = rng.uniform(-scale, scale, (int(rng.integers(0, 100)), 2))
    if len(anchors) and len(points):  # anchors next to points, some on cell edges
        picks = rng.integers(0, len(points), len(anchors) // 2)
        anchors[: len(picks)] = points[picks] + rng.uniform(-radius, radius, (len(picks), 2))
        anchors[: len(picks) // 4] = np.round(anchors[: len(picks) // 4] / radius) * radius
        points[: len(points) // 4] = np.round(points[: len(points) // 4] / radius) * radius
    np.testing.assert_array_equal(_near_any(points, anchors, radius),
                                  _near_any_plain(points, anchors, radius))


def test_near_any_far_out_or_not_finite_falls_back_to_brute_force() -> None:
    points = np.array([[1e12, 0.0], [np.nan, 0.0], [0.0, 0.0]])
    anchors = np.array([[1e12 + 0.1, 0.0], [0.2, 0.0]])
    np.testing.assert_array_equal(_near_any(points, anchors, 0.3), [True, False, True])


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), length=st.integers(1, 8),
       spacing=st.sampled_from([0.05, 0.5]))
def test_thinned_scans_match_voxel_downsample_of_the_last_scans(
        seed: int, length: int, spacing: float) -> None:
    """Row for row, over enough scans for the hash set to fill and be rebuilt."""
    rng = np.random.default_rng(seed)
    thinned = ThinnedScans(length, spacing)
    scans: list[np.ndarray] = []
    for _ in range(int(rng.integers(1, 40))):
        n = int(rng.integers(0, 400))
        scan = rng.uniform(-3, 3, (n, 2)) + rng.uniform(-2, 2, 2)
        scan[: n // 3] = np.round(scan[: n // 3] / spacing) * spacing  # on cell edges
        scans.append(scan)
        thinned.add(scan)
        for count in {0, 1, int(rng.integers(1, length + 2)), length}:
            recent = scans[-length:][-count:] if count else []
            expected = (voxel_downsample(np.concatenate(recent), spacing) if recent
                        else np.zeros((0, 2)))
            np.testing.assert_array_equal(thinned.thinned(count), expected)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), clearance=st.sampled_from([0.0, 0.1, 0.3, 1.0]),
       support=st.sampled_from([0.0, 0.05, 0.1]))
def test_mappable_is_its_definition_by_brute_force(seed: int, clearance: float,
                                                    support: float) -> None:
    """Kept: not moving, and farther than ``map_clearance`` from every moving point or within
    ``map_support`` of a map point; every pair measured."""
    from estimators.base import SensorSetup
    from estimators.odometry.moving_points import MovingPointFilter

    rng = np.random.default_rng(seed)
    world = rng.uniform(-2, 2, (int(rng.integers(0, 60)), 2))
    moving = rng.random(len(world)) < rng.uniform(0, 0.5)
    known = [rng.uniform(-2, 2, (int(rng.integers(0, 40)), 2)) for _ in range(3)]
    moving_filter = MovingPointFilter(SensorSetup(np.zeros((1, 3)), [0.0, 2.0, 4.0], 10.0),
                                      map_clearance=clearance, map_support=support)

    def within(a: np.ndarray, b: np.ndarray, radius: float) -> np.ndarray:
        if not len(b) or not len(a):
            return np.zeros(len(a), dtype=bool)
        return (np.hypot(*(a[:, None, :] - b[None, :, :]).transpose(2, 0, 1)) < radius).any(1)

    near = within(world, world[moving], clearance)
    supported = within(world, np.concatenate(known), support)
    expected = ~moving & ~(near & ~supported)
    np.testing.assert_array_equal(moving_filter.mappable(world, moving, known), expected)
