"""The batched env draws its range noise and its movers' waypoints inside numba, one value at a
time from each sub-env's ``numpy.random.Generator``: numba's draws must be numpy's, bit for
bit, and leave the generator's state where numpy's would (its ziggurat's rare rejections
included, which 200,000 draws reach a few thousand times), or no batched observation could
match a single env's."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit
from numpy.typing import NDArray


@njit
def draw_one_at_a_time(rng: np.random.Generator, normals: NDArray[np.float64],
                       uniforms: NDArray[np.float64]) -> None:
    """``normals`` then ``uniforms`` filled as :func:`lidar_env.vector.kernel.observe_envs`
    fills its draws (and :func:`~lidar_env.vector.kernel.step_crowd` its waypoint draws)."""
    for j in range(normals.shape[0]):
        normals[j] = rng.standard_normal()
    for j in range(uniforms.shape[0]):
        uniforms[j] = rng.random()


@pytest.mark.parametrize("count", [1, 720, 200_000])
def test_numba_draws_are_numpys_and_advance_the_state_alike(count: int) -> None:
    for seed in range(3):
        numpy_rng, numba_rng = np.random.default_rng(seed), np.random.default_rng(seed)
        expected = numpy_rng.standard_normal(count), numpy_rng.random(count)
        got = np.empty(count), np.empty(count)
        draw_one_at_a_time(numba_rng, *got)
        for name, value, reference in zip(("standard_normal", "random"), got, expected,
                                          strict=True):
            assert value.tobytes() == reference.tobytes(), f"seed {seed}: {name}"
        assert numba_rng.bit_generator.state == numpy_rng.bit_generator.state
        assert numba_rng.standard_normal() == numpy_rng.standard_normal()  # and on from there
