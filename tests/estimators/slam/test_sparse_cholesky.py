"""The compiled sparse Cholesky against numpy's dense one on random sparse SPD matrices (the
pose-graph solver's systems: 3 x 3 blocks, a chain plus random loops), and the LM solver's
solutions against SuperLU's."""

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.sparse.linalg import splu

from estimators.slam.solver import EliminationOrdering
from estimators.slam.sparse_cholesky import cholesky_pattern, cholesky_solve, cholesky_values
from lidar_env.core.errors import ConfigError


def pose_graph_system(seed: int, nodes: int, loops: int) -> sp.csc_matrix:
    """``J^T J + diag``: 3 x 3 blocks of a chain of ``nodes`` with ``loops`` random edges."""
    rng = np.random.default_rng(seed)
    edges = [(k, k + 1) for k in range(nodes - 1)]
    edges += [tuple(sorted(rng.choice(nodes, 2, replace=False))) for _ in range(loops)]
    rows, cols, vals = [], [], []
    for e, (i, j) in enumerate(edges):
        for node in (i, j):
            block = rng.normal(size=(3, 3))
            for a in range(3):
                for b in range(3):
                    rows.append(3 * e + a)
                    cols.append(3 * node + b)
                    vals.append(block[a, b])
    jacobian = sp.csr_matrix((vals, (rows, cols)), shape=(3 * len(edges), 3 * nodes))
    hessian = (jacobian.T @ jacobian).tocsc() + sp.identity(3 * nodes, format="csc")
    hessian.sort_indices()
    return hessian


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 10**6), nodes=st.integers(2, 40), loops=st.integers(0, 30))
def test_factor_and_solve_match_the_dense_cholesky(seed: int, nodes: int, loops: int) -> None:
    matrix = pose_graph_system(seed, nodes, loops)
    order = np.random.default_rng(seed).permutation(matrix.shape[0])
    permuted = matrix[order][:, order].tocsc()
    permuted.sort_indices()
    indptr, indices = permuted.indptr.astype(np.int64), permuted.indices.astype(np.int64)
    parent, starts = cholesky_pattern(indptr, indices)
    rows, values, ok = cholesky_values(indptr, indices, permuted.data, parent, starts)
    assert ok
    factor = np.zeros(matrix.shape)
    for j in range(matrix.shape[0]):
        factor[rows[starts[j]:starts[j + 1]], j] = values[starts[j]:starts[j + 1]]
    dense = permuted.toarray()
    np.testing.assert_allclose(factor, np.linalg.cholesky(dense), rtol=1e-9, atol=1e-12)
    rhs = np.random.default_rng(seed + 1).normal(size=matrix.shape[0])
    np.testing.assert_allclose(cholesky_solve(starts, rows, values, rhs),
                               np.linalg.solve(dense, rhs), rtol=1e-8, atol=1e-10)


def test_a_matrix_that_is_not_positive_definite_is_reported() -> None:
    matrix = sp.csc_matrix(np.array([[1.0, 2.0], [2.0, 1.0]]))
    indptr, indices = matrix.indptr.astype(np.int64), matrix.indices.astype(np.int64)
    assert not cholesky_values(indptr, indices, matrix.data, *cholesky_pattern(indptr, indices))[2]


def test_the_lm_solver_agrees_with_superlu_on_every_solve_of_a_growing_graph() -> None:
    solver = EliminationOrdering()
    rng = np.random.default_rng(3)
    # one LM run's systems (one pattern), then a graph grown by a few nodes, then one rebuilt
    for nodes, damping in ((60, 1e-5), (60, 1e-4), (60, 1e-2), (65, 1e-5), (70, 1e-5),
                           (40, 1e-5)):
        matrix = pose_graph_system(7, nodes, 25) + damping * sp.identity(3 * nodes, format="csc")
        matrix.sort_indices()
        rhs = rng.normal(size=3 * nodes)
        expected = splu(matrix, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                        options={"SymmetricMode": True}).solve(rhs)
        np.testing.assert_allclose(solver.solve(matrix, rhs), expected, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), float("inf"), "1.3"])
def test_a_fill_ratio_that_is_none_is_named(bad: object) -> None:
    with pytest.raises(ConfigError, match="max_fill"):
        EliminationOrdering(bad)  # type: ignore[arg-type]
