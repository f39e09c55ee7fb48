"""The compiled likelihood grids against the general tools they replace: the distance
transform against scipy's, and ``LikelihoodField`` on it against the same field on scipy's
(bit for bit)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from estimators.matching.likelihood_grids import distance_scores, likelihood_scores
from estimators.matching.scan_matching import LikelihoodField


@pytest.mark.parametrize("seed", range(6))
def test_distances_are_scipys_exact_euclidean_transform(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for _ in range(40):
        shape = tuple(int(n) for n in rng.integers(1, 70, size=2))
        occupied = rng.random(shape) < rng.choice([0.002, 0.02, 0.2, 0.7])
        occupied[tuple(rng.integers(0, shape))] = True
        identity = np.arange(shape[0] ** 2 + shape[1] ** 2 + 1, dtype=np.float64)
        squared = distance_scores(occupied, identity)
        assert np.array_equal(np.sqrt(squared), ndimage.distance_transform_edt(~occupied))


@pytest.mark.parametrize("seed", range(4))
def test_the_field_is_the_scipy_transforms_bit_for_bit(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for _ in range(10):
        points = rng.normal(size=(int(rng.integers(1, 1500)), 2)) * rng.uniform(0.05, 8.0)
        resolution, sigma = float(rng.choice([0.05, 0.1])), float(rng.choice([0.1, 0.2]))
        field = LikelihoodField(points, resolution, sigma)
        occupied = np.zeros(field.grid.shape, dtype=bool)
        cells = np.floor((points - field.origin) / resolution).astype(int)
        occupied[cells[:, 0], cells[:, 1]] = True
        assert np.array_equal(field.grid,
                              likelihood_scores(occupied, resolution, sigma, compiled=False))
        assert np.array_equal(field.grid, likelihood_scores(occupied, resolution, sigma))
    with pytest.raises(ValueError, match="at least one reference point"):
        LikelihoodField(np.zeros((0, 2)))
