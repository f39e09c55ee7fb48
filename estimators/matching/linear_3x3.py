"""A 3 x 3 linear solve compiled without LAPACK: :func:`solve_3x3`, the operations of OpenBLAS's
``dgesv`` written out, for kernels that solve one small system per point or per iteration
(the local quadratics of :mod:`estimators.matching.curve_refinement_kernel`, ICP's steps in
:mod:`estimators.matching.normal_equations`), where LAPACK's per-call buffers cost more than
the arithmetic. ``tests/estimators/matching/test_linear_3x3.py`` checks it against
``scipy.linalg.lapack.dgesv``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic
from numpy.typing import NDArray


@intrinsic
def _fma(typing_context: Any, a: types.Type, b: types.Type, c: types.Type) -> Any:
    """``a * b + c`` of three floats rounded once (LLVM's ``llvm.fma.f64``), as OpenBLAS's
    dot, gemv and axpy kernels add products on FMA hardware."""
    if not all(isinstance(arg, types.Float) for arg in (a, b, c)):
        return None
    signature = types.float64(types.float64, types.float64, types.float64)

    def codegen(context: Any, builder: Any, _: Any, args: Any) -> Any:
        double = ir.DoubleType()
        fma = builder.module.declare_intrinsic(
            "llvm.fma", [double], ir.FunctionType(double, [double, double, double]))
        return builder.call(fma, [context.cast(builder, value, from_type, types.float64)
                                  for value, from_type in zip(args, (a, b, c), strict=True)])

    return signature, codegen


@njit(cache=True)
def solve_3x3(matrix: NDArray[np.float64], rhs: NDArray[np.float64]) -> bool:
    """Solve ``matrix x = rhs`` (3 x 3) in place -- ``rhs`` becomes ``x``, ``matrix`` its LU
    factors -- by the operations of OpenBLAS's ``dgesv`` in their order: the left-looking LU with
    partial pivoting of its ``getf2`` (the first largest pivot; the column below it scaled by the
    pivot's reciprocal; dot and gemv sums of FMAs), then the row swaps and the two triangular
    solves of ``getrs`` (FMA axpys, a division by each diagonal element). The same numbers bit
    for bit as that LAPACK call on this project's machine (OpenBLAS picks kernels per CPU;
    tested within rounding) without its per-call buffer allocation, which cost 0.35 us a
    solve, three quarters of :func:`chain_curves`. False when a pivot is zero (a singular
    matrix), as ``dgesv``'s ``info > 0``."""
    for j in range(3):
        for i in range(1, 3):  # U's rows by dot, the rest by gemv: one sum of FMAs each
            total = 0.0
            for k in range(min(i, j)):
                total = _fma(matrix[i, k], matrix[k, j], total)
            matrix[i, j] -= total
        largest = j
        for i in range(j + 1, 3):
            if abs(matrix[i, j]) > abs(matrix[largest, j]):
                largest = i
        if matrix[largest, j] == 0.0:
            return False
        if largest != j:
            # the whole rows and rhs now: the columns to the right, untouched until their
            # turn, and rhs, until the solves, take the same swaps in the same order
            for k in range(3):
                matrix[j, k], matrix[largest, k] = matrix[largest, k], matrix[j, k]
            rhs[j], rhs[largest] = rhs[largest], rhs[j]
        scale = 1.0 / matrix[j, j]
        for i in range(j + 1, 3):
            matrix[i, j] *= scale
    for i in range(3):  # L y = P b, L's diagonal ones
        for k in range(i + 1, 3):
            rhs[k] = _fma(-rhs[i], matrix[k, i], rhs[k])
    for i in range(2, -1, -1):  # U x = y
        rhs[i] /= matrix[i, i]
        for k in range(i):
            rhs[k] = _fma(-rhs[i], matrix[k, i], rhs[k])
    return True


@njit(cache=True)
def solved(matrix: NDArray[np.float64], rhs: NDArray[np.float64]) -> NDArray[np.float64]:
    """``np.linalg.solve(matrix, rhs)`` of a 3 x 3 system as numba computes it (LAPACK's dgesv,
    the same errors), by :func:`solve_3x3`, overwriting both arguments: the same bits without
    the copies and the LAPACK call's buffer allocation."""
    if not (np.all(np.isfinite(matrix)) and np.all(np.isfinite(rhs))):
        raise np.linalg.LinAlgError("Array must not contain infs or NaNs.")
    if not solve_3x3(matrix, rhs):
        raise np.linalg.LinAlgError("Matrix is singular to machine precision.")
    return rhs
