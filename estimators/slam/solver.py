"""Optimising a :class:`~estimators.slam.pose_graph.PoseGraph`: :func:`optimize` minimises the
graph's robust cost with our own Levenberg-Marquardt on the sparse normal equations of the
whitened residuals (``solver="lm"``), or with ``scipy.optimize.least_squares`` and the analytic
sparse Jacobian (``solver="scipy"``); the first node (or ``fixed``) is held.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import least_squares
from scipy.sparse.linalg import splu

from estimators.slam.pose_graph import LOSSES, Loss, PoseGraph, edge_residuals, robust_rho
from estimators.slam.sparse_cholesky import cholesky_pattern, cholesky_solve, cholesky_values
from lidar_env.core import ConfigError, EstimatorInputError
from lidar_env.core.se2 import wrap_angle

Solver = Literal["lm", "scipy"]


SOLVERS: tuple[str, ...] = ("lm", "scipy")


@dataclass(frozen=True)
class OptimizationResult:
    """Outcome of :func:`optimize`.

    Attributes:
        poses: ``(N, 3)`` optimised node poses.
        initial_cost / final_cost: ``0.5 * sum rho(r^T Omega r)`` before and after.
        iterations: linear solves (LM) or Jacobian evaluations (scipy).
        seconds: wall time of the optimisation.
        converged: the relative cost decrease fell under the tolerance.
        chi2: ``(E,)`` final Mahalanobis squared error of every edge.
    """

    poses: NDArray[np.float64]
    initial_cost: float
    final_cost: float
    iterations: int
    seconds: float
    converged: bool
    chi2: NDArray[np.float64]


class _WhitenedProblem:
    """Stacked whitened residuals ``f = L^T r`` (``Omega = L L^T``) and their sparse Jacobian
    over the free nodes' poses, with the sparsity pattern built once."""

    def __init__(self, graph: PoseGraph, fixed: int) -> None:
        self.n = graph.n_nodes
        self.edges = graph.edges
        self.z = graph.measurements
        omega = graph.information
        self.sqrt_info_t = np.transpose(np.linalg.cholesky(omega), (0, 2, 1))  # L^T
        self.fixed = fixed
        self.fixed_pose = graph.poses[fixed].copy()
        free = np.ones(self.n, dtype=bool)
        free[fixed] = False
        self.free = free
        var_of_node = np.full(self.n, -1, dtype=np.int64)
        var_of_node[free] = np.arange(free.sum())
        n_edges = len(self.edges)
        # Each edge contributes a 3x6 dense block: 3 rows, 3 columns of node i then of node j.
        rows = np.repeat(3 * np.arange(n_edges)[:, None] + np.arange(3)[None, :], 6, axis=1)
        node_of_col = np.concatenate(
            [np.repeat(self.edges[:, :1], 3, axis=1), np.repeat(self.edges[:, 1:], 3, axis=1)],
            axis=1,
        )
        cols = 3 * var_of_node[node_of_col] + np.tile(np.arange(3), 2)[None, :]
        cols = np.broadcast_to(cols[:, None, :], (n_edges, 3, 6))
        keep = np.broadcast_to((var_of_node[node_of_col] >= 0)[:, None, :], (n_edges, 3, 6))
        self.keep = keep.ravel()
        self.rows = rows.reshape(n_edges, 3, 6).ravel()[self.keep]
        self.cols = cols.ravel()[self.keep]
        self.shape = (3 * n_edges, 3 * int(free.sum()))
        # The canonical CSR layout of the pattern (what scipy's COO conversion makes: rows in
        # order, columns sorted, no duplicates since an edge joins two different nodes), found
        # once: every Jacobian is then its values put in that order, the same matrix bit for
        # bit without a conversion per iteration.
        layout = sp.csr_matrix((np.arange(1.0, len(self.rows) + 1.0), (self.rows, self.cols)),
                               shape=self.shape)
        self._order = layout.data.astype(np.int64) - 1
        self._indices, self._indptr = layout.indices, layout.indptr

    def poses_of(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        poses = np.empty((self.n, 3))
        poses[self.free] = x.reshape(-1, 3)
        poses[self.fixed] = self.fixed_pose
        return poses

    def residuals(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        r = edge_residuals(self.poses_of(x), self.edges, self.z)
        return np.einsum("eij,ej->ei", self.sqrt_info_t, r).ravel()

    def jacobian(self, x: NDArray[np.float64], edge_weight: NDArray[np.float64] | None = None
                 ) -> sp.csr_matrix:
        """Analytic ``d f / d x`` as a sparse matrix (rows scaled by ``sqrt(edge_weight)``)."""
        values = self.jacobian_entries(x, edge_weight)[self._order]
        return sp.csr_matrix((values, self._indices, self._indptr), shape=self.shape)

    def jacobian_entries(self, x: NDArray[np.float64],
                         edge_weight: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
        """The Jacobian's entries at ``(self.rows, self.cols)`` (its COO form)."""
        poses = self.poses_of(x)
        pi, pj = poses[self.edges[:, 0]], poses[self.edges[:, 1]]
        ci, si = np.cos(pi[:, 2]), np.sin(pi[:, 2])
        cz, sz = np.cos(self.z[:, 2]), np.sin(self.z[:, 2])
        dx, dy = pj[:, 0] - pi[:, 0], pj[:, 1] - pi[:, 1]
        # R_z^T R_i^T = R(-(theta_i + theta_z)); the chart (x, y, theta) of e = z^-1 ⊕ h has
        # d e_xy / d t_j = R_z^T R_i^T, d e_xy / d t_i = -R_z^T R_i^T,
        # d e_xy / d theta_i = R_z^T dR_i^T/dtheta (t_j - t_i), d e_theta / d theta_{i,j} = -+1.
        ca, sa = np.cos(pi[:, 2] + self.z[:, 2]), np.sin(pi[:, 2] + self.z[:, 2])
        d_th_x = -si * dx + ci * dy
        d_th_y = -ci * dx - si * dy
        block = np.zeros((len(self.edges), 3, 6))
        block[:, 0, 0], block[:, 0, 1] = -ca, -sa
        block[:, 1, 0], block[:, 1, 1] = sa, -ca
        block[:, 0, 2] = cz * d_th_x + sz * d_th_y
        block[:, 1, 2] = -sz * d_th_x + cz * d_th_y
        block[:, 2, 2] = -1.0
        block[:, 0, 3], block[:, 0, 4] = ca, sa
        block[:, 1, 3], block[:, 1, 4] = -sa, ca
        block[:, 2, 5] = 1.0
        whitened = self.sqrt_info_t @ block
        if edge_weight is not None:
            whitened *= np.sqrt(edge_weight)[:, None, None]
        return whitened.ravel()[self.keep]


def optimize(
    graph: PoseGraph,
    *,
    loss: Loss = "linear",
    loss_scale: float = 3.0,
    solver: Solver = "lm",
    fixed: int = 0,
    max_iterations: int = 100,
    tolerance: float = 1e-10,
    robust_edges: ArrayLike | None = None,
    ordering: EliminationOrdering | None = None,
) -> OptimizationResult:
    """Minimise ``0.5 * sum rho(r^T Omega r)`` over all node poses except ``graph``'s node
    ``fixed``; the graph itself is left unchanged (assign ``result.poses`` to keep them).

    Args:
        loss: ``"linear"`` (plain least squares), or a robust kernel ``"huber"`` /
            ``"cauchy"`` applied per edge to its Mahalanobis squared error.
        loss_scale: Mahalanobis distance where the robust kernel departs from least squares.
            Default 3: an edge whose error is within 3 sigma counts fully (chi-square with
            3 DOF exceeds 9 in under 3 % of honest measurements).
        solver: ``"lm"``: Levenberg–Marquardt on the sparse normal equations (analytic
            Jacobian, SuperLU), robust kernels by iteratively reweighted least squares as GTSAM
            does. ``"scipy"``: ``scipy.optimize.least_squares`` (trust-region reflective, LSMR)
            with the same analytic sparse Jacobian; its robust loss acts per residual component.
        max_iterations: cap on linear solves (``lm``) or function evaluations (``scipy``).
        tolerance: stop when the relative cost decrease falls below it.
        robust_edges: ``(E,)`` boolean mask of the edges the robust kernel applies to
            (default all; e.g. ``graph.is_loop`` to trust odometry and doubt loop closures).
            Only the ``lm`` solver honours it.
        ordering: the ``lm`` solver's :class:`EliminationOrdering`, kept by a caller that
            optimises one growing graph again and again (default: a new one per call).
    """
    if solver not in SOLVERS:
        raise ConfigError(f"unknown solver {solver!r}: expected one of {', '.join(SOLVERS)}")
    if loss not in LOSSES:
        raise ConfigError(f"unknown loss {loss!r}: expected one of {', '.join(LOSSES)}")
    if not loss_scale > 0:
        raise ConfigError(f"loss_scale: expected a positive Mahalanobis distance, got {loss_scale}")
    if graph.n_nodes == 0:
        raise EstimatorInputError("pose graph is empty: expected at least one node")
    if not 0 <= fixed < graph.n_nodes:
        raise EstimatorInputError(f"fixed={fixed}: expected a node index in [0, {graph.n_nodes})")
    graph.check_connected()
    if robust_edges is not None:
        robust_edges = np.asarray(robust_edges, dtype=bool)
        if robust_edges.shape != (graph.n_edges,):
            raise ConfigError(f"robust_edges: expected a boolean mask of shape ({graph.n_edges},),"
                            f" got {robust_edges.shape}")
    start = time.perf_counter()
    initial_cost = graph.cost(loss=loss, loss_scale=loss_scale, robust_edges=robust_edges)
    if graph.n_nodes == 1 or graph.n_edges == 0:
        return OptimizationResult(graph.poses, initial_cost, initial_cost, 0,
                                  time.perf_counter() - start, True, graph.chi2())
    problem = _WhitenedProblem(graph, fixed)
    x0 = graph.poses[problem.free].ravel()
    if solver == "lm":
        x, iterations, converged = _levenberg_marquardt(
            problem, x0, loss, loss_scale, max_iterations, tolerance, robust_edges,
            EliminationOrdering() if ordering is None else ordering)
    else:
        scipy_loss = "soft_l1" if loss == "huber" else loss
        result = least_squares(
            problem.residuals, x0, jac=lambda x: problem.jacobian(x), method="trf",
            tr_solver="lsmr", loss=scipy_loss, f_scale=loss_scale, ftol=tolerance,
            xtol=tolerance, gtol=tolerance, max_nfev=max_iterations,
        )
        x, iterations, converged = result.x, int(result.njev), result.status > 0
    poses = problem.poses_of(x)
    poses[:, 2] = wrap_angle(poses[:, 2])
    return OptimizationResult(
        poses=poses,
        initial_cost=initial_cost,
        final_cost=graph.cost(poses, loss=loss, loss_scale=loss_scale, robust_edges=robust_edges),
        iterations=iterations,
        seconds=time.perf_counter() - start,
        converged=converged,
        chi2=graph.chi2(poses),
    )


def _levenberg_marquardt(
    problem: _WhitenedProblem,
    x: NDArray[np.float64],
    loss: str,
    loss_scale: float,
    max_iterations: int,
    tolerance: float,
    robust_edges: NDArray[np.bool_] | None,
    ordering: EliminationOrdering,
) -> tuple[NDArray[np.float64], int, bool]:
    """LM with GTSAM's damping schedule (lambda x10 on rejection, /10 on success) on
    ``(J^T W J + lambda diag) dx = -J^T W f``; ``W`` are the robust per-edge weights; the
    systems are solved by ``ordering``."""

    def evaluate(x: NDArray[np.float64]) -> tuple[float, NDArray[np.float64], NDArray[np.float64]]:
        f = problem.residuals(x).reshape(-1, 3)
        s = np.einsum("ei,ei->e", f, f)
        rho, weight = robust_rho(s, loss, loss_scale)
        if robust_edges is not None:
            rho = np.where(robust_edges, rho, s)
            weight = np.where(robust_edges, weight, 1.0)
        return 0.5 * float(rho.sum()), f, weight

    cost, f, weight = evaluate(x)
    damping = 1e-5
    iterations = 0
    while iterations < max_iterations:
        jac = problem.jacobian(x, weight)
        gradient = jac.T @ (f * np.sqrt(weight)[:, None]).ravel()
        hessian = (jac.T @ jac).tocsc()
        hessian.sum_duplicates()  # sorted, as splu would sort it (the same values)
        diagonal = np.maximum(hessian.diagonal(), 1e-9)
        on_diagonal = _diagonal_positions(hessian)
        improved = False
        while iterations < max_iterations:
            iterations += 1
            step = -ordering.solve(_damped(hessian, damping * diagonal, on_diagonal), gradient)
            candidate = x + step
            new_cost, new_f, new_weight = evaluate(candidate)
            if new_cost < cost:
                decrease = (cost - new_cost) / max(cost, 1e-300)
                x, cost, f, weight = candidate, new_cost, new_f, new_weight
                damping = max(damping / 10.0, 1e-12)
                improved = True
                if decrease < tolerance:
                    return x, iterations, True
                break
            damping *= 10.0
            if damping > 1e12:
                return x, iterations, True
        if not improved:
            break
    return x, iterations, False


class EliminationOrdering:
    """Solves of the SPD systems of LM runs (damped normal equations), kept across the runs
    of a growing graph. A system is factorised by a compiled Cholesky
    (:mod:`estimators.slam.sparse_cholesky`) in a kept elimination order: SuperLU's
    minimum-degree ordering (MMD on ``A^T + A``), found by a SuperLU solve, then kept while
    the pattern stays (one LM run) and, for a system of more variables (a graph grown by
    nodes at its end), extended by the new variables last, while that order's fill stays
    within ``max_fill`` of the size-scaled fill MMD gave; else SuperLU orders anew. Intel's
    final graph: 9.7 ms per SuperLU solve, 2.5 ms per Cholesky. Solutions agree with
    SuperLU's to ~1e-13 relative, not bit for bit."""

    def __init__(self, max_fill: float = 1.3) -> None:
        if not (isinstance(max_fill, int | float) and math.isfinite(max_fill) and max_fill > 0):
            raise ConfigError(f"max_fill: expected a finite ratio > 0 of a kept order's fill to "
                              f"a new minimum-degree order's, got {max_fill!r}")
        self.max_fill = max_fill
        self._pattern: tuple[NDArray[np.int32], NDArray[np.int32]] | None = None
        self._order = np.zeros(0, dtype=np.int64)
        self._fill_per_variable = 0.0  # nnz(L) / n of the last MMD ordering
        # the kept order's permuted pattern (_analyse): where its entries sit in the matrix's
        # data, its CSC arrays, its elimination tree and column starts (cholesky_pattern)
        self._take = self._indptr = self._indices = np.zeros(0, dtype=np.int64)
        self._tree: tuple[NDArray[np.int64], ...] = ()

    def solve(self, matrix: sp.csc_matrix, rhs: NDArray[np.float64]) -> NDArray[np.float64]:
        """``matrix^-1 rhs`` for a square SPD CSC ``matrix`` with sorted indices."""
        n = matrix.shape[0]
        same = self._pattern is not None and np.array_equal(matrix.indptr, self._pattern[0]) \
            and np.array_equal(matrix.indices, self._pattern[1])
        if not same and 0 < len(self._order) <= n:  # the graph grew: new variables last
            self._analyse(matrix, np.concatenate([self._order, np.arange(len(self._order), n)]))
            same = self._tree[1][-1] <= self.max_fill * self._fill_per_variable * n
        if same:
            rows, values, ok = cholesky_values(self._indptr, self._indices,
                                               matrix.data[self._take], *self._tree)
            if ok:
                x = np.empty_like(rhs)
                x[self._order] = cholesky_solve(self._tree[1], rows, values, rhs[self._order])
                return x
        # symmetric mode (no off-diagonal pivoting) keeps MMD's low fill on these systems: 17
        # ms instead of 0.5 s per factorisation on M3500
        factor = splu(matrix, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                      options={"SymmetricMode": True})
        self._analyse(matrix, np.argsort(factor.perm_c))
        self._fill_per_variable = self._tree[1][-1] / n
        return factor.solve(rhs)

    def _analyse(self, matrix: sp.csc_matrix, order: NDArray[np.int64]) -> None:
        """Keep ``order`` (variable eliminated k-th), the permuted pattern and its tree."""
        self._order = order
        # where each entry of the permuted matrix sits in matrix.data
        probe = sp.csc_matrix((np.arange(1.0, matrix.nnz + 1.0), matrix.indices, matrix.indptr),
                              shape=matrix.shape)[order][:, order].tocsc()
        probe.sort_indices()
        self._take = probe.data.astype(np.int64) - 1
        self._indptr = probe.indptr.astype(np.int64)
        self._indices = probe.indices.astype(np.int64)
        self._tree = cholesky_pattern(self._indptr, self._indices)
        self._pattern = (matrix.indptr.copy(), matrix.indices.copy())


def _diagonal_positions(matrix: sp.csc_matrix) -> NDArray[np.int64] | None:
    """Where ``matrix``'s (square, sorted CSC) diagonal entries sit in its ``data``, or None
    when one of them is not stored (then only a sparse sum can add to it)."""
    counts = np.diff(matrix.indptr)
    columns = np.repeat(np.arange(matrix.shape[1]), counts)
    positions = np.flatnonzero(matrix.indices == columns)
    return positions if len(positions) == matrix.shape[0] else None


def _damped(hessian: sp.csc_matrix, damping: NDArray[np.float64],
            on_diagonal: NDArray[np.int64] | None) -> sp.csc_matrix:
    """``hessian + diag(damping)``: the sum scipy's sparse addition gives (each diagonal entry
    ``h_ii + d_i``, the others unchanged; the hessian holds no explicit zeros, a sparse
    product drops them), on the hessian's own layout when its diagonal is stored."""
    if on_diagonal is None:
        return hessian + sp.diags(damping, format="csc")
    data = hessian.data.copy()
    data[on_diagonal] += damping
    return sp.csc_matrix((data, hessian.indices, hessian.indptr), shape=hessian.shape)

