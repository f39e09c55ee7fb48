"""The eq.-4 filter, the eq.-5 pixel rule and the drawing of :mod:`estimators.paper.scan_image`
in one compiled pass over the beams: :func:`draw_scan`.

The array form (``scan_filter``, ``pixel_values``, ``points_to_image``) makes a dozen
temporaries of the scan's length and a ``np.maximum.at``; this loop makes none. It keeps the
array form's operations in its order (``x * x`` for ``x ** 2``, the same sums), so the images
are the same pixel for pixel (``tests/estimators/paper/test_scan_image.py`` checks it).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray


@njit(cache=True, nogil=True)
def draw_scan(
    ranges: NDArray[np.float64], beam_angles: NDArray[np.float64], turn: float,
    max_range: float, size: int, resolution: float, min_value: int, corner_saturation: float,
) -> NDArray[np.uint8]:  # pragma: no cover (numba)
    """The ``(size, size)`` uint8 eq.-5 image of ``ranges`` (n,) [m] along ``beam_angles``
    (n,) [rad] turned by ``turn`` [rad], at ``resolution`` [m/px]: ``scan_to_image``'s (see
    there and ``pixel_values`` for the rule; ``min_value`` the weakest return's pixel value,
    ``corner_saturation`` the corner measure at which its weight saturates)."""
    n = len(ranges)
    half = size // 2
    beam_step = 2.0 * np.pi / n
    image = np.zeros((size, size), dtype=np.uint8)
    for i in range(n):
        measured = ranges[i]
        if not (measured < max_range and measured > 0):
            continue
        before = min(ranges[i - 1], max_range)
        after = min(ranges[(i + 1) % n], max_range)
        angle = beam_angles[i] + turn
        x, y = measured * np.cos(angle), measured * np.sin(angle)
        # eq. 4
        neighbour_term = (before * before - after * after) / (2.0 * measured)
        mean = (before + measured + after) / 3.0
        # eq. 5
        near = 1.0 - mean / max_range
        corner = min(1.0, abs(neighbour_term) / (mean * beam_step) / corner_saturation)
        weight = min(max(max(near, corner), 0.0), 1.0)
        value = np.uint8(min_value + (255 - min_value) * weight)
        col = np.int64(np.floor(x / resolution)) + half
        row = half - 1 - np.int64(np.floor(y / resolution))
        if 0 <= col < size and 0 <= row < size and value > image[row, col]:
            image[row, col] = value
    return image
