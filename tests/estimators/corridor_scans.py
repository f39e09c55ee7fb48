"""A straight corridor and scans of it, for the tests of where a scan is placed after a blind
stretch (the scan sees through the walls it has driven past when placed short of the car)."""

from __future__ import annotations

import numpy as np


def corridor(end: float) -> np.ndarray:
    """Points (N, 2) of two walls at y = +-2 from x = 0 to ``end``, 5 cm apart."""
    x = np.arange(0.0, end, 0.05)
    return np.concatenate([np.column_stack([x, np.full_like(x, 2.0)]),
                           np.column_stack([x, np.full_like(x, -2.0)])])


def scan_at(x: float, end: float) -> np.ndarray:
    """Car-frame scan (M, 2) from (x, 0), heading 0: the corridor's walls up to ``end`` and a
    wall across at ``end + 6`` beyond its open end."""
    y = np.arange(-8.0, 8.0, 0.05)
    seen = np.concatenate([corridor(end), np.column_stack([np.full_like(y, end + 6.0), y])])
    return seen - [x, 0.0]
