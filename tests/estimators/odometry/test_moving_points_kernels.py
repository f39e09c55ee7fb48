"""The moving-point filter's fast kernels give their plain forms' answers exactly: the
seen-through test from each beam's free reach."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from estimators.odometry.free_space import (
    BeamGeometry,
    _free_ranges,
    _seen_through_free,
    _seen_through_kernel,
)


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
