"""The paper's four-node graph (Sec. III.D, Fig. 4, eq. 10) solved properly: weighted least
squares on SE(2) over car poses linked by sensor-to-sensor matches.

Sensor ``k`` of a car at pose ``X`` sits at ``X ⊕ mount_k``; a match between sensor ``i`` at
one node and sensor ``j`` at another (:class:`SensorEdge`) measures ``z_ij``, the pose of the
second in the frame of the first, which a car motion ``Δ`` predicts as
``h_ij(Δ) = mount_i⁻¹ ⊕ Δ ⊕ mount_j``. :func:`optimize_poses` finds the car poses that best
explain any set of such edges (``scipy.optimize.least_squares``, analytic Jacobian, Cauchy
loss); :func:`fuse_car_motion` is the four-node case, two nodes with the first held.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import least_squares

from lidar_env.se2 import compose, relative, rotate, wrap_angle

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class SensorEdge:
    """One scan match between two sensors at two car poses (graph nodes).

    ``pose``: the measured pose (x [m], y [m], heading [rad]) of sensor ``target_sensor`` at
    node ``target_node`` in the frame of sensor ``source_sensor`` at node ``source_node``.
    ``confidence`` in (0, 1] scales the edge's information (its weight in the least squares).
    """

    source_node: int
    source_sensor: int
    target_node: int
    target_sensor: int
    pose: FloatArray
    confidence: float


def predict_edges(
    car_poses: FloatArray, mounts: FloatArray, edges: Sequence[SensorEdge]
) -> FloatArray:
    """``(M, 3)`` relative sensor poses the car poses ``(N, 3)`` imply for each edge:
    ``(X_a ⊕ mount_i)⁻¹ ⊕ (X_b ⊕ mount_j)``."""
    index = _edge_index(edges)
    source = compose(car_poses[index[:, 0]], mounts[index[:, 1]])
    target = compose(car_poses[index[:, 2]], mounts[index[:, 3]])
    return relative(source, target)


def _edge_index(edges: Sequence[SensorEdge]) -> NDArray[np.int64]:
    return np.array(
        [(e.source_node, e.source_sensor, e.target_node, e.target_sensor) for e in edges],
        dtype=np.int64,
    ).reshape(-1, 4)


def _perpendicular(vectors: FloatArray) -> FloatArray:
    """``J v`` with ``J = [[0, -1], [1, 0]]`` (so that d/dθ R(θ) = R(θ) J)."""
    return np.column_stack([-vectors[:, 1], vectors[:, 0]])


def _checked_edges(
    edges: Sequence[SensorEdge], n_nodes: int, n_sensors: int, n_fixed: int
) -> tuple[NDArray[np.int64], FloatArray, FloatArray]:
    """The edges' ``(node, sensor, node, sensor)`` index ``(E, 4)``, measured poses ``(E, 3)``
    and confidences ``(E,)``, after checking that they fit a graph of ``n_nodes`` car poses
    (the first ``n_fixed`` held) and ``n_sensors`` mounts."""
    if not 1 <= n_fixed < n_nodes:
        raise ValueError(f"n_fixed: expected 1 <= n_fixed < {n_nodes} nodes, got {n_fixed}")
    if not edges:
        raise ValueError("edges: expected at least one edge, got none")
    index = _edge_index(edges)
    if index[:, [0, 2]].min() < 0 or index[:, [0, 2]].max() >= n_nodes:
        raise ValueError(f"edges refer to nodes outside 0..{n_nodes - 1}")
    if index[:, [1, 3]].min() < 0 or index[:, [1, 3]].max() >= n_sensors:
        raise ValueError(f"edges refer to sensors outside 0..{n_sensors - 1}")
    measured = np.array([e.pose for e in edges], dtype=np.float64)
    confidence = np.array([e.confidence for e in edges], dtype=np.float64)
    if np.any(~(confidence > 0)):
        raise ValueError(f"edge confidences: expected values > 0, got {confidence}")
    return index, measured, confidence


def optimize_poses(
    car_poses: ArrayLike,
    mounts: ArrayLike,
    edges: Sequence[SensorEdge],
    *,
    sigma_translation: float = 0.01,
    sigma_heading: float = 0.005,
    robust_scale: float = 3.0,
    n_fixed: int = 1,
) -> FloatArray:
    """Car poses ``(N, 3)`` that best explain ``edges``, starting from ``car_poses``.

    Minimises ``Σ_e ρ(c_e ‖W r_e‖²)`` with the edge residual ``r_e = z_e⁻¹ ⊕ h_e(X)`` (translation
    in the measured sensor frame, heading wrapped), ``W = diag(1/σ_t, 1/σ_t, 1/σ_θ)``, ``c_e`` the
    edge's confidence and ``ρ`` the Cauchy loss with scale ``robust_scale`` (in σ units, so a
    wrong match of a repetitive scene cannot drag the others along). The first ``n_fixed``
    poses are held (they anchor the gauge). The defaults: ``σ_t`` = 1 cm is the order of the
    range noise and of a 360-beam match's precision; ``σ_θ = σ_t / 2 m`` makes a heading error
    move a point at a typical 2 m range as much as a translation error does.
    """
    poses = np.array(car_poses, dtype=np.float64).reshape(-1, 3)
    mounts = np.asarray(mounts, dtype=np.float64).reshape(-1, 3)
    n_nodes = len(poses)
    index, measured, confidence = _checked_edges(edges, n_nodes, len(mounts), n_fixed)
    if sigma_translation <= 0 or sigma_heading <= 0 or robust_scale <= 0:
        raise ValueError(
            "expected positive sigma_translation, sigma_heading and robust_scale, got "
            f"{sigma_translation}, {sigma_heading}, {robust_scale}"
        )
    # Row scale of each edge's three residuals: sqrt(information).
    scale = np.sqrt(confidence)[:, None] / np.array([sigma_translation] * 2 + [sigma_heading])
    src_mount, dst_mount = mounts[index[:, 1]], mounts[index[:, 3]]
    free = np.arange(n_fixed, n_nodes)
    column = np.full(n_nodes, -1)
    column[free] = np.arange(len(free))

    # The unknowns are corrections to the start poses: starting at exactly zero makes
    # least_squares open with a unit trust region instead of one as small as the start poses
    # (a near-zero motion would otherwise never leave its start).
    def unpack(x: FloatArray) -> FloatArray:
        full = poses.copy()
        full[free] += x.reshape(-1, 3)
        return full

    # r_t = R(φ)ᵀ (t_b + R(θ_b) m_j - t_a - R(θ_a) m_i) - R(z_θ)ᵀ z_t with φ = θ_a + m_iθ + z_θ,
    # r_θ = θ_b + m_jθ - θ_a - m_iθ - z_θ: the translation and heading of z⁻¹ ⊕ h.
    measured_offset = rotate(-measured[:, 2], measured[:, :2])
    heading_offset = src_mount[:, 2] - dst_mount[:, 2] + measured[:, 2]

    def edge_terms(x: FloatArray) -> tuple[FloatArray, ...]:
        full = unpack(x)
        a, b = full[index[:, 0]], full[index[:, 2]]
        phi = a[:, 2] + src_mount[:, 2] + measured[:, 2]
        lever_a = rotate(a[:, 2], src_mount[:, :2])
        lever_b = rotate(b[:, 2], dst_mount[:, :2])
        gap = b[:, :2] + lever_b - a[:, :2] - lever_a
        return a, b, phi, lever_a, lever_b, gap

    def residuals(x: FloatArray) -> FloatArray:
        a, b, phi, _, _, gap = edge_terms(x)
        translation = rotate(-phi, gap) - measured_offset
        heading = wrap_angle(b[:, 2] - a[:, 2] - heading_offset)
        return (np.column_stack([translation, heading]) * scale).ravel()

    def jacobian(x: FloatArray) -> FloatArray:
        _, _, phi, lever_a, lever_b, gap = edge_terms(x)
        c, s = np.cos(phi), np.sin(phi)
        d_translation = np.stack([np.column_stack([c, -s]), np.column_stack([s, c])], axis=-1)
        d_theta_b = rotate(-phi, _perpendicular(lever_b))
        d_theta_a = -rotate(-phi, _perpendicular(gap + lever_a))
        jac = np.zeros((len(edges), 3, 3 * len(free)))
        for node, sign, d_theta in ((index[:, 0], -1.0, d_theta_a), (index[:, 2], 1.0, d_theta_b)):
            rows = np.nonzero(column[node] >= 0)[0]
            cols = 3 * column[node[rows]]
            for offset in (0, 1):
                jac[rows, :2, cols + offset] = sign * d_translation[rows, :, offset]
            jac[rows, :2, cols + 2] = d_theta[rows]
            jac[rows, 2, cols + 2] = sign
        return (jac * scale[:, :, None]).reshape(3 * len(edges), -1)

    result = least_squares(
        residuals,
        np.zeros(3 * len(free)),
        jac=jacobian,
        loss="cauchy",
        f_scale=robust_scale,
        method="trf",
        # Stop when a step is below 1e-3 of the correction so far (plus 1e-3): micrometres for
        # the millimetre corrections of a step's fusion; 1e-6 only added an evaluation
        # (measured: poses equal to 1e-9 m).
        xtol=1e-3,
    )
    solved = unpack(result.x)
    solved[:, 2] = wrap_angle(solved[:, 2])
    return solved


def fuse_car_motion(
    mounts: ArrayLike,
    edges: Sequence[SensorEdge],
    initial_motion: ArrayLike = (0.0, 0.0, 0.0),
    **weights: float,
) -> FloatArray:
    """The car motion ``Δ`` (3,) between two scan times from the four-node graph (Fig. 4):
    edges between node 0 (car at t-1, held at the origin) and node 1 (car at t). ``weights``
    go to :func:`optimize_poses`."""
    start = np.stack([np.zeros(3), np.asarray(initial_motion, dtype=np.float64)])
    return optimize_poses(start, mounts, edges, n_fixed=1, **weights)[1]
