"""The loop search's kept pyramid window: a search on it finds what the same search finds on
the whole pyramid (the compiled distance transform is tested in
``tests/estimators/matching/test_likelihood_grids.py``)."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.matching.branch_and_bound import GridPyramid, match
from estimators.matching.scan_matching import LikelihoodField
from estimators.slam.place_grid import search_pyramid


@pytest.mark.parametrize("seed", range(8))
def test_a_search_on_its_window_finds_what_it_finds_on_the_whole_pyramid(seed: int) -> None:
    rng = np.random.default_rng(seed)
    field = LikelihoodField(rng.uniform(-6.0, 6.0, size=(300, 2)), 0.05, 0.1)
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
