"""The place descriptor loop closure ranks candidate places by: the histogram of the ranges
of a keyframe's points from the car's origin (:func:`range_histogram`), which does not change
when the car turns on the spot, and the distance between two of them. Ranges [m].
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from lidar_env.core import ConfigError


def range_histogram(
    points: NDArray[np.float64], n_bins: int = 40, max_range: float = 20.0
) -> NDArray[np.float64]:
    """Rotation-invariant place descriptor: normalised histogram ``(n_bins,)`` of the
    distances [m] of ``points`` (M, 2, car frame) from the origin, up to ``max_range``.

    Default 40 bins over 20 m (0.5 m bins): coarser than a step between keyframes changes
    most ranges, finer than the layout of a room."""
    if n_bins < 1 or not max_range > 0:
        raise ConfigError(f"n_bins, max_range: expected >= 1 and > 0, got {n_bins}, {max_range}")
    ranges = np.hypot(points[:, 0], points[:, 1]) if len(points) else np.zeros(0)
    counts, _ = np.histogram(np.minimum(ranges, max_range), bins=n_bins, range=(0.0, max_range))
    total = counts.sum()
    return counts / total if total else counts.astype(np.float64)


def descriptor_distance(a: NDArray[np.float64], b: NDArray[np.float64]) -> float:
    """Half the L1 distance of two normalised histograms: 0 = identical, 1 = disjoint."""
    return 0.5 * float(np.abs(a - b).sum())


def descriptor_distances(a: NDArray[np.float64], others: NDArray[np.float64]
                         ) -> NDArray[np.float64]:
    """``(K,)`` :func:`descriptor_distance` of ``a`` (B,) to each row of ``others`` (K, B), in
    one pass (each row summed as numpy sums one histogram, so the same numbers)."""
    return 0.5 * np.abs(others - a).sum(axis=1)
