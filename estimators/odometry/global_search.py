"""Where the car can be after scans far apart (:class:`SearchWindow`) and the correlative
searches on one local map (:class:`GlobalSearch`), shared by the far-apart matching
(``far_scans``) and the match after a long blind stretch (``blind_resume``). Poses are in the
map frame: x, y [m], heading [rad]."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from estimators.matching.branch_and_bound import GridPyramid, Match, levels_for_window
from estimators.matching.scan_matching import LikelihoodField
from estimators.matching.window_search import box_pyramid, search_in_box, thinned_for_search

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class SearchWindow:
    """Where the car can be: ``linear`` [m] around the guess, ``angular`` [rad] either side."""

    linear: float
    angular: float


class GlobalSearch:
    """The correlative searches on one map: its likelihood field (``resolution`` cells, 0.1 m
    wide) for the exhaustive search, built once when first needed, and for each
    branch-and-bound search a grid and pyramid over the part of the map the scan can reach,
    kept for the next search of the same part at the same depth (a scan far apart is searched
    in its whole window, then in its near half; where the scan reaches past the map, every
    search covers all of it)."""

    def __init__(self, map_points: FloatArray, resolution: float) -> None:
        self.map_points = map_points
        self.resolution = resolution
        self._field: LikelihoodField | None = None
        self._pyramid: tuple[tuple[float, ...], GridPyramid] | None = None  # (box, levels)

    @property
    def field(self) -> LikelihoodField:
        """The likelihood field of the whole map (built once)."""
        if self._field is None:
            self._field = LikelihoodField(self.map_points, resolution=self.resolution)
        return self._field

    def search(self, points: FloatArray, guess: FloatArray, window: SearchWindow) -> Match:
        """Exact best pose of ``points`` (M, 2, car frame) within ``window`` of ``guess``."""
        thinned = thinned_for_search(points)
        scan_reach = float(np.hypot(thinned[:, 0], thinned[:, 1]).max())
        # no shift beyond where the scan still touches the map counts: a clock gap of minutes
        # must not size the search (memory and time) by max_speed x the gap
        corners = np.array([self.map_points.min(axis=0), self.map_points.max(axis=0)])
        farthest = float(np.hypot(np.abs(corners[:, 0] - guess[0]).max(),
                                  np.abs(corners[:, 1] - guess[1]).max()))
        window = SearchWindow(min(window.linear, farthest + scan_reach), window.angular)
        reach = window.linear + scan_reach + 0.5
        low = np.maximum(self.map_points.min(axis=0), guess[:2] - reach) - 0.5
        high = np.minimum(self.map_points.max(axis=0), guess[:2] + reach) + 0.5
        levels = levels_for_window(window.linear, self.resolution)
        key = (*low.tolist(), *high.tolist(), levels)
        if self._pyramid is None or self._pyramid[0] != key:
            self._pyramid = key, box_pyramid(self.map_points, low, high, self.resolution, levels)
        return search_in_box(self.map_points, low, high, thinned, guess, window.linear,
                             window.angular, self.resolution, self._pyramid[1])
