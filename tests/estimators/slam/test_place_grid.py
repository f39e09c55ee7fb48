"""The loop search's grids against the general tools they replace: the compiled distance
transform against scipy's, the place field against ``LikelihoodField`` (bit for bit), and a
search on the kept window of the pyramid against the same search on the whole one."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from estimators.matching.branch_and_bound import GridPyramid, match
from estimators.matching.scan_matching import LikelihoodField
from estimators.slam.place_grid import PlaceField, distance_scores, search_pyramid


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
def test_place_field_is_the_likelihood_field_bit_for_bit(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for _ in range(10):
        points = rng.normal(size=(int(rng.integers(1, 1500)), 2)) * rng.uniform(0.05, 8.0)
        resolution, sigma = rng.choice([0.05, 0.1]), rng.choice([0.1, 0.2])
        expected = LikelihoodField(points, resolution, sigma)
        field = PlaceField(points, resolution, sigma)
        assert np.array_equal(field.origin, expected.origin)
        assert np.array_equal(field.grid, expected.grid)
    with pytest.raises(ValueError, match="at least one reference point"):
        PlaceField(np.zeros((0, 2)))


@pytest.mark.parametrize("seed", range(8))
def test_a_search_on_its_window_finds_what_it_finds_on_the_whole_pyramid(seed: int) -> None:
    rng = np.random.default_rng(seed)
    field = PlaceField(rng.uniform(-6.0, 6.0, size=(300, 2)), 0.05, 0.1)
    for _ in range(5):
        levels = int(rng.integers(1, 7))
        points = rng.uniform(-4.0, 4.0, size=(int(rng.integers(1, 60)), 2))
        # centres inside, at the edge of and outside the grid
        center = np.array([*rng.uniform(-9.0, 9.0, size=2), rng.uniform(-np.pi, np.pi)])
        search = (points, center, float(rng.uniform(0.0, 1.0)), float(rng.uniform(0.0, 0.3)),
                  0.05)
        whole = match(GridPyramid.from_field(field, levels), *search, -0.5)
        kept = search_pyramid(field, levels, *search)
        found = match(kept, *search, -0.5)
        assert (found.score, found.nodes, found.found) == (whole.score, whole.nodes, whole.found)
        assert np.array_equal(found.pose, whole.pose)
