"""The compiled 3 x 3 solve against LAPACK's ``dgesv``, the call it replaces."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import lapack

from estimators.matching.linear_3x3 import solve_3x3


@settings(max_examples=300, deadline=None)
@given(seed=st.integers(0, 2**31), symmetric=st.booleans(), scale=st.floats(-6.0, 6.0))
def test_solve_3x3_agrees_with_lapack_dgesv(seed: int, symmetric: bool, scale: float) -> None:
    """Any pivot order (general matrices) and the local quadratics' Gram matrices, whose entries
    span many magnitudes (1, u, u^2 summed), against scipy's dgesv, the OpenBLAS call the
    kernel replaced. It performs dgesv's operations, so on this project's machines (x86-64
    with FMA) the bits were equal on 896,256 systems of real drives; but OpenBLAS picks its
    kernels per CPU, so the test asks for what holds on any: the same singular verdict and
    a solution within rounding of the same LU (normwise, a few ulps times the condition)."""
    rng = np.random.default_rng(seed)
    if symmetric:
        u = 10.0**scale * rng.standard_normal(rng.integers(2, 6))
        basis = np.column_stack([np.ones_like(u), u, u * u])
        matrix = basis.T @ basis
        matrix[2, 2] += 1e-9 * np.ptp(u) ** 4
    else:
        matrix = rng.standard_normal((3, 3)) * 10.0 ** rng.uniform(-abs(scale), abs(scale), (3, 3))
    rhs = rng.standard_normal(3)
    _, _, expected, info = lapack.dgesv(matrix, rhs)
    solution = rhs.copy()
    assert solve_3x3(matrix.copy(), solution) == (info == 0)
    if info == 0:
        bound = 64 * np.finfo(float).eps * np.linalg.cond(matrix) * np.abs(expected).max()
        assert np.abs(solution - expected).max() <= bound


def test_solve_3x3_reports_a_singular_matrix() -> None:
    assert not solve_3x3(np.ones((3, 3)), np.ones(3))
