"""The paper's four-node graph (Sec. III.D, Fig. 4, eq. 10) solved properly: weighted least
squares on SE(2) over car poses linked by sensor-to-sensor matches.

Sensor ``k`` of a car at pose ``X`` sits at ``X ⊕ mount_k``; a match between sensor ``i`` at
one node and sensor ``j`` at another (:class:`SensorEdge`) measures ``z_ij``, the pose of the
second in the frame of the first, which a car motion ``Δ`` predicts as
``h_ij(Δ) = mount_i⁻¹ ⊕ Δ ⊕ mount_j``. :func:`optimize_poses` finds the car poses that best
explain any set of such edges (:func:`robust_gauss_newton`, analytic Jacobian, Cauchy
loss); :func:`fuse_car_motion` is the four-node case, two nodes with the first held.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from lidar_env.core import ConfigError, EstimatorInputError
from lidar_env.core.se2 import compose, relative, rotate, wrap_angle

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
        raise ConfigError(f"n_fixed: expected 1 <= n_fixed < {n_nodes} nodes, got {n_fixed}")
    if not edges:
        raise EstimatorInputError("edges: expected at least one edge, got none")
    # Checked on the Python ints of a handful of edges: a few microseconds where the arrays'
    # fancy indexing and reductions cost tens once per step.
    rows = [(e.source_node, e.source_sensor, e.target_node, e.target_sensor) for e in edges]
    nodes = [row[k] for row in rows for k in (0, 2)]
    sensors = [row[k] for row in rows for k in (1, 3)]
    if min(nodes) < 0 or max(nodes) >= n_nodes:
        raise EstimatorInputError(f"edges refer to nodes outside 0..{n_nodes - 1}")
    if min(sensors) < 0 or max(sensors) >= n_sensors:
        raise EstimatorInputError(f"edges refer to sensors outside 0..{n_sensors - 1}")
    confidences = [e.confidence for e in edges]
    confidence = np.array(confidences, dtype=np.float64)
    if not all(value > 0 for value in confidences):
        raise EstimatorInputError(f"edge confidences: expected values > 0, got {confidence}")
    measured = np.array([e.pose for e in edges], dtype=np.float64)
    return np.array(rows, dtype=np.int64).reshape(-1, 4), measured, confidence


def optimize_poses(
    car_poses: ArrayLike,
    mounts: ArrayLike,
    edges: Sequence[SensorEdge],
    *,
    sigma_translation: float = 0.01,
    sigma_heading: float = 0.005,
    robust_scale: float = 3.0,
    n_fixed: int = 1,
    compiled: bool = True,
) -> FloatArray:
    """Car poses ``(N, 3)`` that best explain ``edges``, starting from ``car_poses``.

    Minimises ``Σ_e ρ(c_e ‖W r_e‖²)`` with the edge residual ``r_e = z_e⁻¹ ⊕ h_e(X)`` (translation
    in the measured sensor frame, heading wrapped), ``W = diag(1/σ_t, 1/σ_t, 1/σ_θ)``, ``c_e`` the
    edge's confidence and ``ρ`` the Cauchy loss with scale ``robust_scale`` (in σ units, so a
    wrong match of a repetitive scene cannot drag the others along). The first ``n_fixed``
    poses are held (they anchor the gauge). The defaults: ``σ_t`` = 1 cm is the order of the
    range noise and of a 360-beam match's precision; ``σ_θ = σ_t / 2 m`` makes a heading error
    move a point at a typical 2 m range as much as a translation error does.

    Solved by :func:`robust_gauss_newton`; ``compiled`` runs the same iterations in one numba
    call (:func:`_solve_compiled`), ``False`` in arrays (the reference the tests hold it to).
    """
    poses = np.array(car_poses, dtype=np.float64).reshape(-1, 3)
    mounts = np.asarray(mounts, dtype=np.float64).reshape(-1, 3)
    n_nodes = len(poses)
    index, measured, confidence = _checked_edges(edges, n_nodes, len(mounts), n_fixed)
    if sigma_translation <= 0 or sigma_heading <= 0 or robust_scale <= 0:
        raise ConfigError(
            "expected positive sigma_translation, sigma_heading and robust_scale, got "
            f"{sigma_translation}, {sigma_heading}, {robust_scale}"
        )
    if compiled:
        return _solve_edges_compiled(poses, mounts, index, measured, confidence,
                                     float(sigma_translation), float(sigma_heading), int(n_fixed),
                                     float(robust_scale), STEP_TOLERANCE, TRUSTED_STEP,
                                     MAX_ITERATIONS)
    # Row scale of each edge's three residuals: sqrt(information).
    scale = np.sqrt(confidence)[:, None] / np.array([sigma_translation] * 2 + [sigma_heading])
    src_mount, dst_mount = mounts[index[:, 1]], mounts[index[:, 3]]
    free = np.arange(n_fixed, n_nodes)
    column = np.full(n_nodes, -1)
    column[free] = np.arange(len(free))

    measured_offset = rotate(-measured[:, 2], measured[:, :2])
    heading_offset = src_mount[:, 2] - dst_mount[:, 2] + measured[:, 2]
    # The unknowns are corrections to the start poses (so the solver starts at zero).
    def unpack(x: FloatArray) -> FloatArray:
        full = poses.copy()
        full[free] += x.reshape(-1, 3)
        return full

    # r_t = R(φ)ᵀ (t_b + R(θ_b) m_j - t_a - R(θ_a) m_i) - R(z_θ)ᵀ z_t with φ = θ_a + m_iθ + z_θ,
    # r_θ = θ_b + m_jθ - θ_a - m_iθ - z_θ: the translation and heading of z⁻¹ ⊕ h.

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

    x = robust_gauss_newton(residuals, jacobian, np.zeros(3 * len(free)), robust_scale)
    solved = unpack(x)
    solved[:, 2] = wrap_angle(solved[:, 2])
    return solved


#: Gauss-Newton stops when no correction moves by more than this [m or rad], or after
#: ``MAX_ITERATIONS`` steps (a step's fusion converges in 3-5 from the main pair's match).
STEP_TOLERANCE = 1e-12
MAX_ITERATIONS = 50
#: A step below this [m or rad] is taken without comparing costs: that close to the optimum
#: the cost changes by less than its own rounding, and the comparison would stop the
#: iterations at a point set by rounding (nanometres apart between two implementations).
TRUSTED_STEP = 1e-7


def robust_gauss_newton(
    residuals: Callable[[FloatArray], FloatArray], jacobian: Callable[[FloatArray], FloatArray],
    start: FloatArray, scale: float,
) -> FloatArray:
    """The ``x`` minimising ``Σ_i ρ(f_i(x)²)`` over the residual components ``f(x)`` (R,),
    ``ρ(s) = c² log(1 + s / c²)`` the Cauchy loss of scale ``c = scale`` (as
    ``scipy.optimize.least_squares(loss="cauchy", f_scale=scale)`` applies it), from
    ``start``, by iteratively reweighted Gauss-Newton: each step solves ``Jᵀ W J d = -Jᵀ W f``
    with ``W = ρ'(f²) = 1 / (1 + f² / c²)`` (``J`` = ``jacobian(x)``, (R, len(x))), halved
    while it raises the cost (unless below ``TRUSTED_STEP``). It reaches the optimum of
    ``scipy.optimize.least_squares`` (to 1e-7, see the tests), whose trust-region machinery
    was a third of ``pc_fusion``'s time on the four-edge graph of a step."""
    x = np.asarray(start, dtype=np.float64).copy()
    c2 = scale**2
    f = residuals(x)
    cost = float(np.sum(np.log1p(f**2 / c2)))
    for _ in range(MAX_ITERATIONS):
        jac = jacobian(x)
        weights = 1.0 / (1.0 + f**2 / c2)
        normal = jac.T @ (weights[:, None] * jac)
        step = np.linalg.lstsq(normal, -jac.T @ (weights * f), rcond=None)[0]
        for _ in range(30):  # halve a step that raises the cost (far from the optimum)
            trial = residuals(x + step)
            trial_cost = float(np.sum(np.log1p(trial**2 / c2)))
            if trial_cost <= cost or np.max(np.abs(step)) < TRUSTED_STEP:
                break
            step = 0.5 * step
        else:
            return x
        x, f, cost = x + step, trial, trial_cost
        if np.max(np.abs(step), initial=0.0) < STEP_TOLERANCE:
            break
    return x


@njit(cache=True)
def _edge_system(full: FloatArray, column: NDArray[np.int64], index: NDArray[np.int64],
                 src_mount: FloatArray, dst_mount: FloatArray, measured_heading: FloatArray,
                 measured_offset: FloatArray, heading_offset: FloatArray, scale: FloatArray,
                 f: FloatArray, jac: FloatArray, with_jacobian: bool) -> None:  # pragma: no cover
    """The residuals ``f`` (3E,) and, ``with_jacobian``, ``jac`` (3E, 3F) of
    :func:`optimize_poses`'s ``residuals`` and ``jacobian`` at the car poses ``full`` (N, 3)."""
    if with_jacobian:
        jac[:] = 0.0
    for e in range(len(index)):
        a, b = full[index[e, 0]], full[index[e, 2]]
        phi = a[2] + src_mount[e, 2] + measured_heading[e]
        ca, sa, cb, sb = np.cos(a[2]), np.sin(a[2]), np.cos(b[2]), np.sin(b[2])
        lever_ax = ca * src_mount[e, 0] - sa * src_mount[e, 1]
        lever_ay = sa * src_mount[e, 0] + ca * src_mount[e, 1]
        lever_bx = cb * dst_mount[e, 0] - sb * dst_mount[e, 1]
        lever_by = sb * dst_mount[e, 0] + cb * dst_mount[e, 1]
        gap_x = b[0] + lever_bx - a[0] - lever_ax
        gap_y = b[1] + lever_by - a[1] - lever_ay
        c, s = np.cos(phi), np.sin(phi)  # R(-phi) = [[c, s], [-s, c]]
        f[3 * e] = (c * gap_x + s * gap_y - measured_offset[e, 0]) * scale[e, 0]
        f[3 * e + 1] = (-s * gap_x + c * gap_y - measured_offset[e, 1]) * scale[e, 1]
        turn = b[2] - a[2] - heading_offset[e]
        f[3 * e + 2] = ((turn + np.pi) % (2.0 * np.pi) - np.pi) * scale[e, 2]
        if not with_jacobian:
            continue
        # d/dθ of R(-phi) v for the levers: R(-phi) J v, J v = (-v_y, v_x)
        arm_a_x, arm_a_y = -(gap_y + lever_ay), gap_x + lever_ax
        for node, sign, arm_x, arm_y in ((index[e, 0], -1.0, -arm_a_x, -arm_a_y),
                                         (index[e, 2], 1.0, -lever_by, lever_bx)):
            col = column[node]
            if col < 0:
                continue
            k = 3 * col
            jac[3 * e, k] = sign * c * scale[e, 0]
            jac[3 * e, k + 1] = sign * s * scale[e, 0]
            jac[3 * e + 1, k] = -sign * s * scale[e, 1]
            jac[3 * e + 1, k + 1] = sign * c * scale[e, 1]
            jac[3 * e, k + 2] = (c * arm_x + s * arm_y) * scale[e, 0]
            jac[3 * e + 1, k + 2] = (-s * arm_x + c * arm_y) * scale[e, 1]
            jac[3 * e + 2, k + 2] = sign * scale[e, 2]


@njit(cache=True)
def _solve_compiled(poses: FloatArray, column: NDArray[np.int64], index: NDArray[np.int64],
                    src_mount: FloatArray, dst_mount: FloatArray, measured_heading: FloatArray,
                    measured_offset: FloatArray, heading_offset: FloatArray, scale: FloatArray,
                    robust_scale: float, tolerance: float, trusted: float,
                    max_iterations: int) -> FloatArray:  # pragma: no cover (numba)
    """:func:`robust_gauss_newton` on :func:`_edge_system`: the solved car poses (N, 3),
    headings not yet wrapped."""
    n_free = int((column >= 0).sum())
    terms = (column, index, src_mount, dst_mount, measured_heading, measured_offset,
             heading_offset, scale)
    full = poses.copy()
    trial_poses = poses.copy()
    f = np.empty(3 * len(index))
    trial = np.empty(3 * len(index))
    jac = np.empty((3 * len(index), 3 * n_free))
    c2 = robust_scale**2
    _edge_system(full, *terms, f, jac, False)
    cost = np.sum(np.log1p(f**2 / c2))
    for _ in range(max_iterations):
        _edge_system(full, *terms, f, jac, True)
        weights = 1.0 / (1.0 + f**2 / c2)
        weighted = jac * weights[:, None]
        step = np.linalg.lstsq(jac.T @ weighted, -(weighted.T @ f))[0]
        accepted = False
        for _ in range(30):
            trial_poses[:] = full
            for node in range(len(full)):
                if column[node] >= 0:
                    trial_poses[node] += step[3 * column[node]:3 * column[node] + 3]
            _edge_system(trial_poses, *terms, trial, jac, False)
            trial_cost = np.sum(np.log1p(trial**2 / c2))
            if trial_cost <= cost or np.max(np.abs(step)) < trusted:
                accepted = True
                break
            step *= 0.5
        if not accepted:
            break
        full[:], f[:], cost = trial_poses, trial, trial_cost
        if np.max(np.abs(step)) < tolerance:
            break
    return full


@njit(cache=True)
def _solve_edges_compiled(poses: FloatArray, mounts: FloatArray, index: NDArray[np.int64],
                          measured: FloatArray, confidence: FloatArray, sigma_translation: float,
                          sigma_heading: float, n_fixed: int, robust_scale: float,
                          tolerance: float, trusted: float,
                          max_iterations: int) -> FloatArray:  # pragma: no cover (numba)
    """:func:`optimize_poses`'s compiled path whole: the edge terms its array path makes
    (row scales, mounts, measured offsets, the same operations in the same order), then
    :func:`_solve_compiled`, headings wrapped. In one call, since a dozen small numpy calls
    around the solve cost as much as the solve itself on a step's four edges."""
    n_nodes, n_edges = len(poses), len(index)
    column = np.full(n_nodes, -1)
    for node in range(n_fixed, n_nodes):
        column[node] = node - n_fixed
    scale = np.empty((n_edges, 3))
    src_mount = np.empty((n_edges, 3))
    dst_mount = np.empty((n_edges, 3))
    measured_offset = np.empty((n_edges, 2))
    heading_offset = np.empty(n_edges)
    for e in range(n_edges):
        root = np.sqrt(confidence[e])
        scale[e, 0] = root / sigma_translation
        scale[e, 1] = root / sigma_translation
        scale[e, 2] = root / sigma_heading
        src_mount[e] = mounts[index[e, 1]]
        dst_mount[e] = mounts[index[e, 3]]
        c, s = np.cos(-measured[e, 2]), np.sin(-measured[e, 2])
        measured_offset[e, 0] = c * measured[e, 0] - s * measured[e, 1]
        measured_offset[e, 1] = s * measured[e, 0] + c * measured[e, 1]
        heading_offset[e] = src_mount[e, 2] - dst_mount[e, 2] + measured[e, 2]
    solved = _solve_compiled(poses, column, index, src_mount, dst_mount,
                             np.ascontiguousarray(measured[:, 2]), measured_offset,
                             heading_offset, scale, robust_scale, tolerance, trusted,
                             max_iterations)
    for node in range(n_nodes):
        solved[node, 2] = (solved[node, 2] + np.pi) % (2.0 * np.pi) - np.pi
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
    start = np.zeros((2, 3))
    start[1] = initial_motion
    return optimize_poses(start, mounts, edges, n_fixed=1, **weights)[1]
