"""Eq. 10 on the four-node loop, with exact, biased and inconsistent cross-Lidar edges."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.paper.pose_graph_correlation import pose_graph_correlation


def _loop(rng: np.random.Generator) -> tuple[np.ndarray, ...]:
    """Random true nodes: P1 past main, P2 = P1 + o_past, P3 = P1 + d, P4 = P3 + o_present."""
    p1, d = rng.normal(size=2), rng.normal(size=2)
    o_past, o_present = rng.normal(size=2), rng.normal(size=2)
    p2, p3 = p1 + o_past, p1 + d
    p4 = p3 + o_present
    return p1, p2, p3, p4, o_past, o_present


def test_exact_edges_give_the_main_lidar_motion_even_when_the_offset_turns() -> None:
    rng = np.random.default_rng(0)
    for _ in range(10):
        p1, p2, p3, p4, o_past, o_present = _loop(rng)
        result = pose_graph_correlation(p4 - p1, p2 - p3, o_past, o_present)
        np.testing.assert_allclose(result.motion, p3 - p1, atol=1e-12)
        np.testing.assert_allclose(result.error, (o_present - o_past) / 2.0, atol=1e-12)
        np.testing.assert_allclose(result.loop_residual, 0.0, atol=1e-12)


def test_an_error_shared_by_both_cross_estimates_cancels() -> None:
    rng = np.random.default_rng(1)
    p1, p2, p3, p4, o, _ = _loop(rng)
    p4 = p3 + o  # the car only translates: same offset at both scans
    shared = np.array([0.07, -0.03])
    result = pose_graph_correlation(p4 - p1 + shared, p2 - p3 + shared, o, o)
    np.testing.assert_allclose(result.motion, p3 - p1, atol=1e-12)
    np.testing.assert_allclose(result.loop_residual, 2.0 * shared, atol=1e-12)


def test_independent_errors_are_averaged() -> None:
    o = np.array([-0.5, 0.0])
    d = np.array([0.1, 0.02])
    e14, e32 = np.array([0.04, 0.0]), np.array([0.0, 0.02])
    result = pose_graph_correlation(d + o + e14, o - d + e32, o, o)
    np.testing.assert_allclose(result.motion, d + (e14 - e32) / 2.0, atol=1e-12)


@pytest.mark.parametrize("bad", [[1.0], [1.0, np.nan], [[1.0, 2.0]], "ab"])
def test_bad_vectors_are_readable_errors(bad: object) -> None:
    with pytest.raises(ValueError, match=r"xi14: expected 2 finite numbers"):
        pose_graph_correlation(bad, [0.0, 0.0], [0.5, 0.0], [0.5, 0.0])
    with pytest.raises(ValueError, match=r"offset_present: expected 2 finite numbers"):
        pose_graph_correlation([0.0, 0.0], [0.0, 0.0], [0.5, 0.0], bad)
