"""Arrays that grow one row at a time (:class:`GrowingRows`): what the pose graph and the
keyframe table keep per node, edge or keyframe. Read whole after every few appends, a list of
rows would be stacked into an array each time (a graph of 1,500 nodes and 2,500 edges: ~1 ms
per read); here a read is a view and an append amortised O(1).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, DTypeLike, NDArray


class GrowingRows:
    """Rows of one shape and dtype in a buffer that doubles when full.

    Args:
        row_shape: shape of one row (``()`` for scalars); None: taken from the first row.
        dtype: the rows' dtype (values are cast as ``np.asarray(row, dtype)`` would).
    """

    def __init__(self, row_shape: tuple[int, ...] | None = (), dtype: DTypeLike = np.float64
                 ) -> None:
        self._row_shape, self._dtype = row_shape, np.dtype(dtype)
        self._buffer = np.empty((0, *(row_shape or ())), dtype=self._dtype)
        self._size = 0

    def __len__(self) -> int:
        return self._size

    def append(self, row: ArrayLike) -> None:
        """Add one row (of ``row_shape``) at the end."""
        if self._row_shape is None:
            self._row_shape = np.shape(row)
            self._buffer = np.empty((0, *self._row_shape), dtype=self._dtype)
        if self._size == len(self._buffer):
            grown = np.empty((max(16, 2 * self._size), *self._row_shape), dtype=self._dtype)
            grown[: self._size] = self._buffer[: self._size]
            self._buffer = grown
        self._buffer[self._size] = row
        self._size += 1

    @property
    def rows(self) -> NDArray:
        """``(n, *row_shape)`` the rows so far (a view: valid until the next append)."""
        return self._buffer[: self._size]

    def assign(self, rows: ArrayLike) -> None:
        """Replace the rows by ``rows`` (n, *row_shape), any count."""
        rows = np.asarray(rows, dtype=self._dtype)
        if self._row_shape is None:
            self._row_shape = rows.shape[1:]
        self._size = 0
        if len(rows) > len(self._buffer):
            self._buffer = np.empty((len(rows), *rows.shape[1:]), dtype=self._dtype)
        self._buffer[: len(rows)] = rows
        self._size = len(rows)

    def copy(self) -> GrowingRows:
        """An independent copy."""
        other = GrowingRows(self._row_shape, self._dtype)
        other._buffer, other._size = self._buffer[: self._size].copy(), self._size
        return other
