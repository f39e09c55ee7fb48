"""Sparse Cholesky factorisation ``A = L L^T`` of a symmetric positive-definite matrix in a
given elimination order, compiled: the up-looking algorithm of Davis, "Direct Methods for
Sparse Linear Systems" (SIAM 2006, CSparse's ``cs_chol``): row ``k`` of ``L`` is a sparse
triangular solve along the elimination tree. The pose-graph solver
(:mod:`estimators.slam.solver`) factorises one sparsity pattern several times per
Levenberg-Marquardt run; the pattern's analysis (:func:`cholesky_pattern`) is done once, each
factorisation (:func:`cholesky_values`) is then half of SuperLU's LU of the same system in the
same order.

Matrices are CSC arrays ``(indptr, indices, data)`` of the whole symmetric matrix (both
triangles; only entries with row <= column are read), already permuted to the elimination
order.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

IntArray = NDArray[np.int64]


@njit(cache=True)
def cholesky_pattern(indptr: IntArray, indices: IntArray
                     ) -> tuple[IntArray, IntArray]:  # pragma: no cover (numba)
    """``(parent, column_starts)``: the elimination tree ``(n,)`` of the matrix (-1 at a
    root) and where each column of ``L`` starts in its arrays ``(n + 1,)`` (its diagonal
    first), from the pattern alone."""
    n = len(indptr) - 1
    parent = np.full(n, -1, np.int64)
    ancestor = np.full(n, -1, np.int64)
    for k in range(n):
        for p in range(indptr[k], indptr[k + 1]):
            i = indices[p]
            while i != -1 and i < k:  # path compression towards k
                following = ancestor[i]
                ancestor[i] = k
                if following == -1:
                    parent[i] = k
                i = following
    counts = np.ones(n, np.int64)
    seen = np.full(n, -1, np.int64)
    for k in range(n):  # row k of L reaches up the tree from each entry of column k
        seen[k] = k
        for p in range(indptr[k], indptr[k + 1]):
            i = indices[p]
            while i < k and seen[i] != k:
                counts[i] += 1
                seen[i] = k
                i = parent[i]
    starts = np.zeros(n + 1, np.int64)
    for k in range(n):
        starts[k + 1] = starts[k] + counts[k]
    return parent, starts


@njit(cache=True)
def cholesky_values(indptr: IntArray, indices: IntArray, data: NDArray[np.float64],
                    parent: IntArray, starts: IntArray
                    ) -> tuple[IntArray, NDArray[np.float64], bool]:  # pragma: no cover (numba)
    """``(rows, values, ok)`` of ``L``'s columns (laid out by ``starts``, diagonal first);
    ``ok`` is False when a pivot is not positive (the matrix is not positive definite)."""
    n = len(indptr) - 1
    rows = np.empty(starts[n], np.int64)
    values = np.empty(starts[n])
    fill = starts[:-1].copy()
    x = np.zeros(n)
    stack = np.empty(n, np.int64)
    mark = np.full(n, -1, np.int64)
    for k in range(n):
        top = n  # the pattern of row k, in topological order, is stack[top:]
        mark[k] = k
        for p in range(indptr[k], indptr[k + 1]):
            i = indices[p]
            if i > k:
                continue
            x[i] += data[p]
            length = 0
            while mark[i] != k:
                stack[length] = i
                length += 1
                mark[i] = k
                i = parent[i]
            while length > 0:
                top -= 1
                length -= 1
                stack[top] = stack[length]
        pivot = x[k]
        x[k] = 0.0
        for t in range(top, n):
            i = stack[t]
            entry = x[i] / values[starts[i]]
            x[i] = 0.0
            for p in range(starts[i] + 1, fill[i]):
                x[rows[p]] -= values[p] * entry
            pivot -= entry * entry
            p = fill[i]
            fill[i] += 1
            rows[p], values[p] = k, entry
        if not pivot > 0.0:
            return rows, values, False
        p = fill[k]
        fill[k] += 1
        rows[p], values[p] = k, np.sqrt(pivot)
    return rows, values, True


@njit(cache=True)
def cholesky_solve(starts: IntArray, rows: IntArray, values: NDArray[np.float64],
                   rhs: NDArray[np.float64]) -> NDArray[np.float64]:  # pragma: no cover (numba)
    """``(L L^T)^-1 rhs`` from :func:`cholesky_values`' ``L``."""
    n = len(starts) - 1
    x = rhs.copy()
    for j in range(n):
        x[j] /= values[starts[j]]
        for p in range(starts[j] + 1, starts[j + 1]):
            x[rows[p]] -= values[p] * x[j]
    for j in range(n - 1, -1, -1):
        for p in range(starts[j] + 1, starts[j + 1]):
            x[j] -= values[p] * x[rows[p]]
        x[j] /= values[starts[j]]
    return x
