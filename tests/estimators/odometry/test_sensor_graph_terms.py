"""The sensor graph's compiled path makes its edge terms inside the kernel: the same terms,
bit for bit, as the arrays it was given before (row scales, mounts, measured offsets), so the
same solved poses."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.odometry.sensor_graph import (
    MAX_ITERATIONS,
    STEP_TOLERANCE,
    TRUSTED_STEP,
    _checked_edges,
    _solve_compiled,
    _solve_edges_compiled,
)
from lidar_env.core.se2 import rotate, wrap_angle
from tests.estimators.odometry.test_sensor_graph_solver import random_graph


def _solve_from_arrays(start: np.ndarray, mounts: np.ndarray, edges: list, n_fixed: int,
                       sigmas: tuple[float, float], robust_scale: float) -> np.ndarray:
    """The compiled solve as it was called before: its terms made by numpy."""
    index, measured, confidence = _checked_edges(edges, len(start), len(mounts), n_fixed)
    scale = np.sqrt(confidence)[:, None] / np.array([sigmas[0]] * 2 + [sigmas[1]])
    src_mount, dst_mount = mounts[index[:, 1]], mounts[index[:, 3]]
    free = np.arange(n_fixed, len(start))
    column = np.full(len(start), -1)
    column[free] = np.arange(len(free))
    measured_offset = rotate(-measured[:, 2], measured[:, :2])
    heading_offset = src_mount[:, 2] - dst_mount[:, 2] + measured[:, 2]
    solved = _solve_compiled(start, column, index, src_mount, dst_mount, measured[:, 2],
                             measured_offset, heading_offset, scale, robust_scale,
                             STEP_TOLERANCE, TRUSTED_STEP, MAX_ITERATIONS)
    solved[:, 2] = wrap_angle(solved[:, 2])
    return solved


@pytest.mark.parametrize("seed", range(3))
def test_terms_made_in_the_kernel_solve_bit_for_bit_as_from_arrays(seed: int) -> None:
    rng = np.random.default_rng(200 + seed)
    for _ in range(30):
        start, mounts, edges = random_graph(rng)
        n_fixed = int(rng.integers(1, len(start)))
        sigmas = (float(rng.uniform(0.005, 0.05)), float(rng.uniform(0.002, 0.02)))
        robust_scale = float(rng.uniform(1.0, 5.0))
        index, measured, confidence = _checked_edges(edges, len(start), len(mounts), n_fixed)
        inside = _solve_edges_compiled(start, mounts, index, measured, confidence, *sigmas,
                                       n_fixed, robust_scale, STEP_TOLERANCE, TRUSTED_STEP,
                                       MAX_ITERATIONS)
        before = _solve_from_arrays(start, mounts, edges, n_fixed, sigmas, robust_scale)
        np.testing.assert_array_equal(inside.view(np.uint64), before.view(np.uint64))
