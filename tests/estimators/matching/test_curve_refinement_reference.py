"""A ``CurveReference`` built in one compiled call (``curve_reference_arrays``) holds the
arrays of its array form bit for bit: the returns, their points, the local quadratics and the
smoothed points, for full-turn and partial scans with gaps, depth jumps and no-returns."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from estimators.matching.curve_refinement import (
    MAX_SURFACE_GAP,
    SURFACE_HALF_WINDOW,
    CurveReference,
    covers_full_turn,
)
from estimators.matching.curve_refinement_kernel import chain_curves
from estimators.matching.scan_matching import DEFAULT_MIN_RANGE


def _array_form(ranges: np.ndarray, beam_angles: np.ndarray, max_range: float) -> tuple:
    """The reference's arrays as numpy made them before (with the compiled quadratics)."""
    hit = np.flatnonzero((ranges < max_range) & (ranges > DEFAULT_MIN_RANGE))
    angles = beam_angles[hit]
    points = np.column_stack([ranges[hit] * np.cos(angles), ranges[hit] * np.sin(angles)])
    curves = chain_curves(points, hit.astype(np.int64), len(ranges), covers_full_turn(beam_angles),
                          SURFACE_HALF_WINDOW, MAX_SURFACE_GAP)
    return (points, *curves, points + curves[5][:, None] * curves[1])


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31), n_beams=st.integers(3, 720), full=st.booleans(),
       missing=st.floats(0.0, 0.5), smooth=st.booleans())
def test_compiled_reference_is_the_array_form_bit_for_bit(
    seed: int, n_beams: int, full: bool, missing: float, smooth: bool
) -> None:
    rng = np.random.default_rng(seed)
    span = 2.0 * np.pi if full else rng.uniform(0.5, 6.0)
    angles = -np.pi + span * np.arange(n_beams) / n_beams
    if smooth:  # a room-like scan: neighbouring returns on one surface
        ranges = 3.0 + np.sin(3.0 * angles) + 0.01 * rng.standard_normal(n_beams)
    else:  # depth jumps everywhere
        ranges = rng.uniform(0.0, 12.0, n_beams)
    ranges[rng.random(n_beams) < missing] = 10.0
    if int(np.count_nonzero((ranges < 10.0) & (ranges > DEFAULT_MIN_RANGE))) < 3:
        return
    reference = CurveReference(ranges, angles, 10.0)
    built = (reference.points, reference.tangents, reference.normals, reference.pointlike,
             reference.a, reference.b, reference.c, reference.smoothed)
    for ours, theirs in zip(built, _array_form(ranges, angles, 10.0), strict=True):
        assert ours.dtype == theirs.dtype and ours.shape == theirs.shape
        if ours.dtype == np.float64:  # bit for bit, signed zeros too
            ours, theirs = ours.view(np.uint64), theirs.view(np.uint64)
        np.testing.assert_array_equal(ours, theirs)
