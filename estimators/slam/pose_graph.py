"""SE(2) pose graphs: nodes, edges, their residuals and cost, which
:func:`estimators.slam.solver.optimize` minimises.

A :class:`PoseGraph` holds node poses (x [m], y [m], heading [rad]) in one world frame and
edges ``i -> j`` that each measure the pose of node ``j`` in the frame of node ``i``, with a
3x3 information matrix ``Omega`` (inverse covariance, in the same (x, y, heading) order).

Residual convention (GTSAM's ``BetweenFactorPose2``, default Pose2 chart): with predicted
relative pose ``h = x_i^-1 ⊕ x_j`` and measurement ``z``, the residual is the local pose
difference ``e = z^-1 ⊕ h`` read as the tangent vector ``r = (e_x, e_y, wrap(e_theta))``.
The cost is ``0.5 * sum_e rho(r_e^T Omega_e r_e)``, with ``rho(s) = s`` for the plain
least-squares loss; it is what GTSAM calls the graph error, so its optima on the public
benchmark graphs can be compared number for number (``benchmarks/bench_pose_graph.py``).

The first node (or the one named by ``fixed``) is held fixed: it removes the gauge freedom.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray
from scipy.sparse.csgraph import connected_components

from estimators.slam.growing_rows import GrowingRows
from lidar_env.core import ConfigError, EstimatorInputError, UnknownNameError
from lidar_env.core.se2 import compose, inverse

Loss = Literal["linear", "huber", "cauchy"]
LOSSES: tuple[str, ...] = ("linear", "huber", "cauchy")


#: [m] largest accepted |x|, |y| of a node pose or an edge measurement: a million km, far past
#: any map, yet far enough from float overflow that squared residuals stay finite (poses at
#: 1e200 made the solver's factorisation "exactly singular").
MAX_COORDINATE = 1e9
#: Accepted eigenvalues of an edge information matrix [1/m^2, 1/rad^2]: outside these an edge
#: either says nothing (1e-300 left the poses unmoved with ``converged=True``) or overflows.
MIN_INFORMATION, MAX_INFORMATION = 1e-9, 1e15
#: Node ids are stored as int64 (and written to g2o files as such).
ID_RANGE = (-(2**63), 2**63 - 1)


def _symmetric(matrix: NDArray[np.float64]) -> bool:
    """``np.allclose(matrix, matrix.T)`` (its default tolerances), without its overhead for
    the finite matrices edges carry (a tenth of an edge's checks)."""
    if not np.isfinite(matrix).all():
        return bool(np.allclose(matrix, matrix.T))
    return bool((np.abs(matrix - matrix.T) <= 1e-8 + 1e-5 * np.abs(matrix.T)).all())


def _check_coordinates(what: str, pose: NDArray[np.float64]) -> None:
    """``pose`` (x [m], y [m], ...) lies within ``MAX_COORDINATE`` of the origin."""
    if np.max(np.abs(pose[:2])) > MAX_COORDINATE:
        raise EstimatorInputError(
            f"{what}: expected |x|, |y| <= {MAX_COORDINATE:g} m, got {pose.tolist()}")


class DisconnectedGraphError(EstimatorInputError):
    """The graph falls apart into pieces whose relative placement nothing constrains."""


class PoseGraph:
    """SE(2) nodes and relative-pose edges with information matrices.

    Nodes are indexed ``0..N-1`` in insertion order and keep an external integer id (the
    g2o vertex id, or a keyframe number). Edges refer to node indices.
    """

    def __init__(self) -> None:
        self._poses = GrowingRows((3,))
        self._ids: list[int] = []
        self._index_of: dict[int, int] = {}
        self._edge_nodes = GrowingRows((2,), np.int64)
        self._measurements = GrowingRows((3,))
        self._information = GrowingRows((3, 3))
        self._is_loop = GrowingRows((), bool)
        self._connected_nodes = 0  # nodes when last found connected (0: not known to be)

    # ------------------------------------------------------------------ building
    def add_node(self, pose: ArrayLike, node_id: int | None = None) -> int:
        """Add a node at ``pose`` (x [m], y [m], heading [rad]); return its index."""
        pose_arr = np.asarray(pose, dtype=np.float64)
        if pose_arr.shape != (3,) or not np.all(np.isfinite(pose_arr)):
            raise EstimatorInputError(
                f"node pose: expected 3 finite numbers (x, y, heading), got {pose}")
        _check_coordinates("node pose", pose_arr)
        node_id = len(self._ids) if node_id is None else int(node_id)
        if not ID_RANGE[0] <= node_id <= ID_RANGE[1]:
            raise EstimatorInputError(f"node id: expected a 64-bit integer, got {node_id}")
        if node_id in self._index_of:
            raise EstimatorInputError(f"node id {node_id} is already in the graph")
        self._index_of[node_id] = len(self._ids)
        self._ids.append(node_id)
        self._poses.append(pose_arr)
        return len(self._ids) - 1

    def add_edge(
        self,
        i: int,
        j: int,
        measurement: ArrayLike,
        information: ArrayLike,
        is_loop: bool = False,
    ) -> int:
        """Add an edge measuring node ``j``'s pose in node ``i``'s frame; return its index.

        ``information`` is the 3x3 symmetric positive-definite inverse covariance of the
        measurement (units 1/m^2, 1/(m rad), 1/rad^2).
        """
        n = len(self._ids)
        for name, index in (("i", i), ("j", j)):
            if not 0 <= int(index) < n:
                raise EstimatorInputError(
                    f"edge node {name}={index}: expected a node index in [0, {n})")
        if int(i) == int(j):
            raise EstimatorInputError(f"edge {i}->{j}: expected two different nodes")
        z = np.asarray(measurement, dtype=np.float64)
        if z.shape != (3,) or not np.all(np.isfinite(z)):
            raise EstimatorInputError(
                f"edge measurement: expected 3 finite numbers, got {measurement}")
        _check_coordinates(f"edge {i}->{j} measurement", z)
        omega = np.asarray(information, dtype=np.float64)
        if omega.shape != (3, 3) or not _symmetric(omega):
            raise EstimatorInputError(
                f"edge information: expected a symmetric 3x3 matrix, got {omega}")
        try:
            np.linalg.cholesky(omega)
        except np.linalg.LinAlgError:
            raise EstimatorInputError(
                f"edge {i}->{j} information: expected a positive-definite matrix, got {omega}"
            ) from None
        eigenvalues = np.linalg.eigvalsh(omega)
        if eigenvalues[0] < MIN_INFORMATION or eigenvalues[-1] > MAX_INFORMATION:
            raise EstimatorInputError(
                f"edge {i}->{j} information: expected eigenvalues in [{MIN_INFORMATION:g}, "
                f"{MAX_INFORMATION:g}], got {eigenvalues[0]:.3g} .. {eigenvalues[-1]:.3g}")
        self._edge_nodes.append((int(i), int(j)))
        self._measurements.append(z)
        self._information.append(omega)
        self._is_loop.append(bool(is_loop))
        return len(self._edge_nodes) - 1

    # ------------------------------------------------------------------ reading
    @property
    def n_nodes(self) -> int:
        return len(self._ids)

    @property
    def n_edges(self) -> int:
        return len(self._edge_nodes)

    @property
    def poses(self) -> NDArray[np.float64]:
        """``(N, 3)`` node poses in the world frame (a fresh copy: the graph keeps its own)."""
        return self._poses.rows.copy()

    @poses.setter
    def poses(self, poses: ArrayLike) -> None:
        arr = np.asarray(poses, dtype=np.float64)
        if arr.shape != (self.n_nodes, 3) or not np.all(np.isfinite(arr)):
            raise EstimatorInputError(
                f"poses: expected finite ({self.n_nodes}, 3), got {arr.shape}")
        self._poses.assign(arr)

    def pose(self, index: int) -> NDArray[np.float64]:
        """``(3,)`` node ``index``'s pose (a fresh copy; negative indices count from the end)."""
        return self._poses.rows[index].copy()

    def set_pose(self, index: int, pose: ArrayLike) -> None:
        self._poses.rows[index] = np.asarray(pose, dtype=np.float64)

    @property
    def ids(self) -> NDArray[np.int64]:
        """``(N,)`` external node ids."""
        return np.array(self._ids, dtype=np.int64)

    def index_of(self, node_id: int) -> int:
        """Node index of external id ``node_id``."""
        try:
            return self._index_of[int(node_id)]
        except KeyError:
            raise UnknownNameError(f"no node with id {node_id} in the graph") from None

    def _arrays(self) -> tuple[NDArray, NDArray, NDArray, NDArray]:
        """The edges as arrays (views; a graph of a thousand edges is read several times per
        optimisation)."""
        return (self._edge_nodes.rows, self._measurements.rows, self._information.rows,
                self._is_loop.rows)

    @property
    def edges(self) -> NDArray[np.int64]:
        """``(E, 2)`` node indices ``(i, j)`` of each edge (a fresh copy)."""
        return self._arrays()[0].copy()

    @property
    def measurements(self) -> NDArray[np.float64]:
        """``(E, 3)`` measured pose of node j in the frame of node i (a fresh copy)."""
        return self._arrays()[1].copy()

    @property
    def information(self) -> NDArray[np.float64]:
        """``(E, 3, 3)`` information matrices (a fresh copy)."""
        return self._arrays()[2].copy()

    @property
    def is_loop(self) -> NDArray[np.bool_]:
        """``(E,)`` True for loop-closure edges (as opposed to odometry; a fresh copy)."""
        return self._arrays()[3].copy()

    def remove_edges(self, indices: ArrayLike) -> None:
        """Delete the edges at ``indices`` (e.g. loop closures the optimiser could not
        reconcile); the others keep their order."""
        keep = np.ones(self.n_edges, dtype=bool)
        keep[np.atleast_1d(np.asarray(indices, dtype=np.int64))] = False
        for rows in (self._edge_nodes, self._measurements, self._information, self._is_loop):
            rows.assign(rows.rows[keep])
        self._connected_nodes = 0

    def copy(self) -> PoseGraph:
        other = PoseGraph()
        other._poses = self._poses.copy()
        other._ids = list(self._ids)
        other._index_of = dict(self._index_of)
        other._edge_nodes, other._measurements = self._edge_nodes.copy(), self._measurements.copy()
        other._information, other._is_loop = self._information.copy(), self._is_loop.copy()
        return other

    def check_connected(self) -> None:
        """Raise :class:`DisconnectedGraphError` unless every node links to node 0."""
        n = self.n_nodes
        # Adding edges cannot disconnect a graph: the answer stands until a node is added or
        # an edge removed.
        if n <= 1 or self._connected_nodes == n:
            return
        edges = self.edges
        adjacency = sp.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
        n_parts, labels = connected_components(adjacency, directed=False)
        if n_parts > 1:
            sizes = np.bincount(labels)
            stray = [self._ids[k] for k in np.flatnonzero(labels != labels[0])]
            shown = ", ".join(str(k) for k in stray[:5]) + (", ..." if len(stray) > 5 else "")
            raise DisconnectedGraphError(
                f"pose graph has {n_parts} disconnected parts (sizes {sorted(sizes.tolist())}); "
                f"expected one connected graph. Node ids not linked to node id {self._ids[0]}: "
                f"{shown}"
            )
        self._connected_nodes = n

    def cost(self, poses: ArrayLike | None = None, loss: Loss = "linear",
             loss_scale: float = 1.0, robust_edges: ArrayLike | None = None) -> float:
        """``0.5 * sum rho(r^T Omega r)`` at ``poses`` (default: the graph's own poses);
        ``rho`` is ``loss`` on the ``robust_edges`` (boolean mask, default all), plain
        least squares on the others."""
        poses = self.poses if poses is None else np.asarray(poses, dtype=np.float64)
        chi2 = edge_chi2(poses, self.edges, self.measurements, self.information)
        rho = robust_rho(chi2, loss, loss_scale)[0]
        if robust_edges is not None:
            rho = np.where(robust_edges, rho, chi2)
        return 0.5 * float(np.sum(rho))

    def chi2(self, poses: ArrayLike | None = None) -> NDArray[np.float64]:
        """``(E,)`` Mahalanobis squared error ``r^T Omega r`` of every edge."""
        poses = self.poses if poses is None else np.asarray(poses, dtype=np.float64)
        return edge_chi2(poses, self.edges, self.measurements, self.information)


# ---------------------------------------------------------------------- pure math
def edge_residuals(
    poses: NDArray[np.float64],
    edges: NDArray[np.int64],
    measurements: NDArray[np.float64],
) -> NDArray[np.float64]:
    """``(E, 3)`` residuals ``r = chart(z^-1 ⊕ (x_i^-1 ⊕ x_j))`` (GTSAM BetweenFactorPose2)."""
    predicted = compose(inverse(poses[edges[:, 0]]), poses[edges[:, 1]])
    return compose(inverse(measurements), predicted)


def edge_chi2(
    poses: NDArray[np.float64],
    edges: NDArray[np.int64],
    measurements: NDArray[np.float64],
    information: NDArray[np.float64],
) -> NDArray[np.float64]:
    """``(E,)`` Mahalanobis squared residual ``r^T Omega r`` of every edge."""
    r = edge_residuals(poses, edges, measurements)
    return np.einsum("ei,eij,ej->e", r, information, r)


def chain_covariance(poses: ArrayLike, covariances: ArrayLike, correlated: bool = False
                     ) -> NDArray[np.float64]:
    """``(3, 3)`` first-order covariance of the last pose of a chain relative to its first.

    ``poses`` (n+1, 3) are the chain's node poses (world frame), ``covariances`` (n, 3, 3)
    those of the n edges ``k -> k+1``, each in the residual coordinates of this module (the
    frame of the edge's end node ``k+1``). The result is in the same coordinates for the
    whole chain (the frame of its last node): the covariance of the residual a direct edge
    from the first node to the last would have, before any other edge constrains it. An
    edge's heading error swings every later pose about the edge's end node:
    ``J_k = [[R(theta_k+1), perp(p_n - p_k+1)], [0, 1]]`` in world coordinates.

    ``correlated=False`` takes the edges' errors as independent. ``correlated=True`` returns
    ``n`` times that sum, an upper bound for any correlation between them (``Cov(sum x_k) <=
    n sum Cov(x_k)``, Cauchy-Schwarz), reached when they all err the same way, as a front
    end biased along a stretch of corridor does: the standard deviation then grows linearly
    with the chain's length instead of with its square root.
    """
    poses = np.asarray(poses, dtype=np.float64)
    covariances = np.asarray(covariances, dtype=np.float64)
    if poses.ndim != 2 or poses.shape[1] != 3 or len(poses) < 1:
        raise EstimatorInputError(
            f"chain poses: expected shape (n+1 >= 1, 3), got {poses.shape}")
    if covariances.shape != (len(poses) - 1, 3, 3):
        raise EstimatorInputError(
            f"chain covariances: expected shape ({len(poses) - 1}, 3, 3) for "
            f"{len(poses)} poses, got {covariances.shape}")
    ends = poses[1:]
    lever = poses[-1, :2] - ends[:, :2]
    c, s = np.cos(ends[:, 2]), np.sin(ends[:, 2])
    jacobian = np.zeros((len(ends), 3, 3))
    jacobian[:, 0, 0], jacobian[:, 0, 1], jacobian[:, 0, 2] = c, -s, -lever[:, 1]
    jacobian[:, 1, 0], jacobian[:, 1, 1], jacobian[:, 1, 2] = s, c, lever[:, 0]
    jacobian[:, 2, 2] = 1.0
    world = np.einsum("kij,kjl,kml->im", jacobian, covariances, jacobian)
    if correlated:
        world *= len(ends)
    to_local = np.eye(3)
    c_n, s_n = np.cos(poses[-1, 2]), np.sin(poses[-1, 2])
    to_local[:2, :2] = [[c_n, s_n], [-s_n, c_n]]
    return to_local @ world @ to_local.T


def robust_rho(
    s: NDArray[np.float64], loss: str, scale: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Robust kernel ``rho(s)`` on squared errors ``s`` and its derivative ``rho'(s)``.

    ``scale`` is the Mahalanobis distance (not squared) where the kernel departs from
    least squares: Huber is quadratic below it and linear above, Cauchy is
    ``c^2 log(1 + s / c^2)``.
    """
    if loss not in LOSSES:
        raise ConfigError(f"unknown loss {loss!r}: expected one of {', '.join(LOSSES)}")
    if loss == "linear":
        return s, np.ones_like(s)
    c2 = scale * scale
    if loss == "huber":
        root = np.sqrt(np.maximum(s, 0.0))
        inlier = s <= c2
        rho = np.where(inlier, s, 2.0 * scale * root - c2)
        weight = np.where(inlier, 1.0, scale / np.maximum(root, 1e-300))
        return rho, weight
    rho = c2 * np.log1p(s / c2)
    return rho, 1.0 / (1.0 + s / c2)
