"""The last scans' points thinned to one per cell, kept scan by scan: the moving-point
filter's "moved on" anchors (:class:`~estimators.odometry.moving_points.MovingPointFilter`).

Units: metres; points (n, 2) in the world frame, C-contiguous float64.
"""

from __future__ import annotations

from collections import deque

import numba
import numpy as np
from numpy.typing import NDArray

from estimators.matching.scan_matching import cell_key_and_slot


@numba.njit(cache=True)
def _mark_cells(points: NDArray[np.float64], spacing: float, table: NDArray[np.int64],
                last: NDArray[np.int64], scan: int) -> tuple[NDArray[np.int64], int]:
    """Each of a scan's world ``points`` (n, 2)' previous scan: the last ``scan`` number before
    this one with a point in its ``spacing`` [m] cell (-1: none known), ``scan`` itself for a
    point after the first in its cell; then the cells are marked as seen in ``scan``. The cells
    and their hash are :func:`~estimators.matching.scan_matching.first_in_each_cell`'s
    (:func:`~estimators.matching.scan_matching.cell_key_and_slot`);
    ``table`` (cell keys) and ``last`` (their scans, -1: a free slot) are an open-addressing
    hash set, a power of two long, updated in place. Returns (previous scans, slots filled)."""
    mask = len(table) - 1
    shift = np.uint64(64 - int(np.log2(len(table))))
    previous = np.empty(len(points), np.int64)
    filled = 0
    for i in range(len(points)):
        key, slot = cell_key_and_slot(points[i, 0], points[i, 1], spacing, shift)
        while last[slot] >= 0 and table[slot] != key:
            slot = (slot + 1) & mask
        if last[slot] < 0:
            filled += 1
            table[slot] = key
        previous[i] = last[slot]
        last[slot] = scan
    return previous, filled


@numba.njit(cache=True)
def _rows_before(points: NDArray[np.float64], previous: NDArray[np.int64],
                 oldest: int) -> NDArray[np.float64]:
    """The rows of ``points`` (n, 2) whose ``previous`` scan is before ``oldest``, in order."""
    count = 0
    for i in range(len(previous)):
        count += previous[i] < oldest
    out = np.empty((count, 2))
    row = 0
    for i in range(len(previous)):
        if previous[i] < oldest:
            out[row, 0], out[row, 1] = points[i, 0], points[i, 1]
            row += 1
    return out


class ThinnedScans:
    """The last scans' world points and, as :func:`~estimators.matching.scan_matching.
    voxel_downsample` of the concatenation of any last few of them would keep them, their
    first point per cell, kept incrementally: a point is the first of its cell in the last
    scans from ``oldest`` on when it is the first in its own scan and no scan from ``oldest``
    on before its own had a point there. Which scan last had a point in a cell is found once,
    when the point's scan arrives (:func:`_mark_cells`), in a hash set that keeps the cells of
    the last ``length`` scans (rebuilt from them when half full). The points are packed in
    one buffer, the kept scans one run at its end (moved to the front when it fills).

    Args:
        length: [scans] how many are kept.
        spacing: [m] the cells' size.
    """

    def __init__(self, length: int, spacing: float) -> None:
        self.spacing = spacing
        self._scans: deque[tuple[int, int, int]] = deque(maxlen=length)  # number, start, end
        self._count = 0  # scans added
        self._points = np.empty((1024, 2))
        self._previous = np.empty(1024, np.int64)
        self._table = np.zeros(1024, np.int64)
        self._last = np.full(1024, -1, np.int64)
        self._filled = 0

    def add(self, points: NDArray[np.float64]) -> None:
        """Keep the next scan's world ``points`` (n, 2) [m] (C-contiguous float64)."""
        if len(self._scans) == self._scans.maxlen:
            self._scans.popleft()
        if 2 * (self._filled + len(points)) > len(self._table):
            self._rebuild(len(points))
        previous, filled = _mark_cells(points, self.spacing, self._table, self._last,
                                       self._count)
        self._filled += filled
        start = self._make_room(len(points))
        self._points[start:start + len(points)] = points
        self._previous[start:start + len(points)] = previous
        self._scans.append((self._count, start, start + len(points)))
        self._count += 1

    def _make_room(self, incoming: int) -> int:
        """Where the next ``incoming`` points go: after the kept ones, which move to the
        buffer's front (into a larger buffer if they would fill over half of it) first when
        there is no room."""
        first = self._scans[0][1] if self._scans else 0
        end = self._scans[-1][2] if self._scans else 0
        if end + incoming <= len(self._points):
            return end
        kept = end - first
        size = len(self._points)
        while 2 * (kept + incoming) > size:
            size *= 2
        points, previous = np.empty((size, 2)), np.empty(size, np.int64)
        points[:kept], previous[:kept] = self._points[first:end], self._previous[first:end]
        self._points, self._previous = points, previous
        self._scans = deque(((scan, a - first, b - first) for scan, a, b in self._scans),
                            maxlen=self._scans.maxlen)
        return kept

    def _rebuild(self, incoming: int) -> None:
        """The hash set anew from the kept scans alone (the older ones' cells say nothing), a
        size that leaves it at most a quarter full with ``incoming`` more points."""
        kept = sum(b - a for _, a, b in self._scans)
        size = 1024
        while size < 4 * (kept + incoming):
            size *= 2
        self._table = np.zeros(size, np.int64)
        self._last = np.full(size, -1, np.int64)
        self._filled = 0
        for scan, a, b in self._scans:
            self._filled += _mark_cells(self._points[a:b], self.spacing, self._table,
                                        self._last, scan)[1]

    def thinned(self, count: int) -> NDArray[np.float64]:
        """The last ``count`` scans' points (m, 2), first per cell, in order:
        ``voxel_downsample(np.concatenate(last count scans), spacing)``, row for row."""
        if not count or not self._scans:
            return np.zeros((0, 2))
        oldest, start, _ = self._scans[-min(count, len(self._scans))]
        end = self._scans[-1][2]
        return _rows_before(self._points[start:end], self._previous[start:end], oldest)
