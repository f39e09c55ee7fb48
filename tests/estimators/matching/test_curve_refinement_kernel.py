"""The compiled point-to-curve refinement against its array form (``refine_pure``): the same
pose to 1e-9 and the same quality, with and without a motion prior, about any pivot, in a
room and in a featureless corridor (where the prior takes over the open direction); the
compiled local quadratics of a scan against theirs (``chain_curves_pure``)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimators.matching.curve_refinement import (
    MAX_SURFACE_GAP,
    SURFACE_HALF_WINDOW,
    CurveReference,
    chain_curves_pure,
    refine_on_curves,
    refine_pure,
)
from estimators.matching.curve_refinement_kernel import chain_curves

ANGLES = np.linspace(-np.pi, np.pi, 360, endpoint=False)


def _scan(pose: np.ndarray, corridor: bool, rng: np.random.Generator) -> np.ndarray:
    """Ranges [m] from ``pose`` in a 6 x 4 m room with a post (or a 2 m wide endless
    corridor), 1 cm noise, a few beams without return."""
    directions = np.column_stack([np.cos(pose[2] + ANGLES), np.sin(pose[2] + ANGLES)])
    with np.errstate(divide="ignore"):
        across = np.abs((np.where(directions[:, 1] > 0, 1.0, -1.0) - pose[1]) / directions[:, 1])
        along = np.abs((np.where(directions[:, 0] > 0, 3.0, -3.0) - pose[0]) / directions[:, 0])
    ranges = across if corridor else np.minimum(across, along)
    if not corridor:
        centre = np.array([1.2, 0.4]) - pose[:2]
        reach = directions @ centre
        disc = reach**2 - (centre @ centre - 0.3**2)
        post = np.where(disc > 0, reach - np.sqrt(np.maximum(disc, 0.0)), np.inf)
        ranges = np.minimum(ranges, np.where(post > 0, post, np.inf))
    ranges = np.minimum(ranges, 20.0) + 0.01 * rng.standard_normal(len(ANGLES))
    ranges[rng.random(len(ANGLES)) < 0.03] = 20.0
    return ranges


@settings(max_examples=50, deadline=None)
@given(
    seed=st.integers(0, 2**31), corridor=st.booleans(), with_prior=st.booleans(),
    iterations=st.integers(1, 8), dx=st.floats(-0.1, 0.1), dy=st.floats(-0.1, 0.1),
    turn=st.floats(-0.1, 0.1), px=st.floats(-1.0, 1.0), py=st.floats(-1.0, 1.0),
    information=st.floats(1e-3, 10.0),
)
def test_compiled_refinement_matches_the_array_form(
    seed: int, corridor: bool, with_prior: bool, iterations: int, dx: float, dy: float,
    turn: float, px: float, py: float, information: float,
) -> None:
    rng = np.random.default_rng(seed)
    reference = CurveReference(_scan(np.zeros(3), corridor, rng), ANGLES, 20.0)
    motion = np.array([0.1, 0.02, 0.03])
    later = CurveReference(_scan(motion, corridor, rng), ANGLES, 20.0).smoothed
    start = motion + np.array([dx, dy, turn])
    prior = motion + 0.01 if with_prior else None
    args = (reference, later, start, iterations, prior, np.array([px, py]),
            np.full(3, information))
    pose, quality = refine_on_curves(*args)
    expected_pose, expected_quality = refine_pure(*args)
    np.testing.assert_allclose(pose, expected_pose, rtol=0, atol=1e-9)
    assert quality == pytest.approx(expected_quality, abs=1e-12)


def test_too_few_pairs_stop_at_the_start() -> None:
    rng = np.random.default_rng(0)
    reference = CurveReference(_scan(np.zeros(3), False, rng), ANGLES, 20.0)
    far = np.array([[50.0, 50.0], [51.0, 50.0], [52.0, 50.0]])
    pose, quality = refine_on_curves(reference, far, np.array([0.1, 0.0, 0.0]), 5)
    np.testing.assert_array_equal(pose, [0.1, 0.0, 0.0])
    assert quality == 0.0


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31), corridor=st.booleans(), fov=st.sampled_from([360, 270, 5]),
       drop=st.floats(0.0, 0.5))
def test_compiled_chain_curves_match_the_array_form(seed: int, corridor: bool, fov: int,
                                                    drop: float) -> None:
    """The local quadratics of a scan (partial fields of view, gaps, lone returns)."""
    rng = np.random.default_rng(seed)
    ranges = _scan(np.array([0.3, 0.2, 0.1]), corridor, rng)[:fov]
    ranges[rng.random(fov) < drop] = 20.0
    angles = ANGLES[:fov]
    hit = np.flatnonzero(ranges < 20.0)
    if len(hit) < 3:
        return
    points = np.column_stack([ranges[hit] * np.cos(angles[hit]), ranges[hit] * np.sin(angles[hit])])
    found = chain_curves(points, hit.astype(np.int64), fov, fov == 360, SURFACE_HALF_WINDOW,
                         MAX_SURFACE_GAP)
    expected = chain_curves_pure(points, hit, fov, fov == 360)
    np.testing.assert_array_equal(found[2], expected[2])
    for got, want in zip(found[:2], expected[:2], strict=True):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    # a, b, c: the curve's height and slope at the return to 1e-9 (a alone is ill-conditioned
    # where two returns fit a line: its tiny ridge leaves it ~1e-9 relative)
    for got, want in zip(found[3:], expected[3:], strict=True):
        np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-9)
