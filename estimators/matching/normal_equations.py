"""Compiled ICP iterations: pairs, residuals, Jacobians and weights summed straight into the
3 x 3 Gauss-Newton normal equations, one numba call per iteration.

The math is that of the pure functions in :mod:`estimators.matching.point_to_line` (pairs by
:meth:`~estimators.matching.point_to_line.PointToLineReference.correspond`, residuals
``n . (R p + t - q)`` (Censi eq. 5), :func:`~estimators.matching.point_to_line.
point_to_line_jacobian`, :func:`~estimators.matching.point_to_line.robust_weights`) and of
:meth:`~estimators.matching.curve_refinement.CurveReference.project`; what changes is that no
per-pair array is built: a scan's few hundred pairs cost a few microseconds instead of the
dozens of numpy calls (each a few microseconds on its own) an iteration took.
``tests/estimators/matching/test_normal_equations.py`` checks every kernel against those pure
functions on random inputs. The sums run in pair order rather than through BLAS, so the
normal equations agree with the pure ones to rounding (~1e-15 relative), not bit for bit.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

from estimators.matching.linear_3x3 import solved
from estimators.matching.nearest import KEPT, STACK, kept_answer, search, search_near

#: Loss codes of the kernels, in the order of :data:`estimators.matching.point_to_line.LOSSES`.
CAUCHY, HUBER, SQUARED = 0, 1, 2


@njit(cache=True)
def _weight(residual: float, loss: int, scale: float) -> float:
    """IRLS weight of one residual (``robust_weights``)."""
    if loss == CAUCHY:
        ratio = residual / scale
        return 1.0 / (1.0 + ratio * ratio)
    if loss == HUBER:
        magnitude = abs(residual)
        return 1.0 if magnitude <= scale else scale / max(magnitude, 1e-12)
    return 1.0


@njit(cache=True)
def _accumulate(hessian: NDArray[np.float64], gradient: NDArray[np.float64], nx: float,
                ny: float, lever: float, residual: float, weight: float) -> None:
    """Add one pair's ``w J^T J`` and ``-w J^T r`` (J = (nx, ny, lever))."""
    row = (nx, ny, lever)
    for a in range(3):
        gradient[a] -= weight * row[a] * residual
        for b in range(3):
            hessian[a, b] += weight * row[a] * row[b]


@njit(cache=True)
def fresh_neighbours(m: int) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """``kept`` and ``near`` for ``m`` query points not searched yet
    (:func:`estimators.matching.nearest.search_near`)."""
    return np.full((m, 3 + 2 * KEPT), np.nan), np.empty((m, KEPT), np.int64)


@njit(cache=True)
def point_to_line_system(
    order: NDArray[np.int64], tree_points: NDArray[np.float64], start: NDArray[np.int64],
    end: NDArray[np.int64], child: NDArray[np.int64], box: NDArray[np.float64],
    points: NDArray[np.float64], normals: NDArray[np.float64], valid: NDArray[np.bool_],
    anchors: NDArray[np.float64], has_normals: bool,
    query: NDArray[np.float64], pose: NDArray[np.float64], max_distance: float, loss: int,
    scale: float, residuals: NDArray[np.float64], kept: NDArray[np.float64],
    near: NDArray[np.int64],
) -> tuple[NDArray[np.float64], NDArray[np.float64], int, float]:
    """One point-to-line iteration of ``query`` (M, 2) at ``pose`` onto a reference (its tree,
    ``points``, and with ``has_normals`` its stored ``normals``/``valid``/``anchors``).

    Returns the normal equations ``H = sum w J^T J`` (3, 3), ``g = -sum w J^T r`` (3,), the
    number of pairs and the sum of the squared rotation column of J; ``residuals`` (M,) is
    filled with each query point's residual [m], NaN where it has no pair. ``kept`` and
    ``near`` are the query points' neighbours from the previous iterations
    (:func:`estimators.matching.nearest.search_near`; :func:`fresh_neighbours` before the
    first), updated where they are searched again.
    """
    n = points.shape[0]
    c, s = np.cos(pose[2]), np.sin(pose[2])
    bound = max_distance * max_distance
    hessian = np.zeros((3, 3))
    gradient = np.zeros(3)
    count = 0
    rotation_squares = 0.0
    pending = np.empty(STACK, np.int64)
    for i in range(query.shape[0]):
        residuals[i] = np.nan
        wx = query[i, 0] * c - query[i, 1] * s + pose[0]
        wy = query[i, 0] * s + query[i, 1] * c + pose[1]
        # the nearest point with stored normals, else (or where its normal is not valid)
        # the two nearest: one call site, as each inlines the whole search
        k = 1 if has_normals else 2
        while True:
            d0, i0, d1, i1, _, _, holds = kept_answer(kept, near, i, wx, wy, k, bound, n)
            if not holds:
                d0, i0, d1, i1, _, _ = search_near(order, tree_points, start, end, child,
                                                   box, points, wx, wy, k, bound, pending, i,
                                                   kept, near)
            if k == 2 or i0 == n or valid[i0]:
                break
            k = 2
        if i0 == n:
            continue
        if has_normals and valid[i0]:
            ax, ay = anchors[i0, 0], anchors[i0, 1]
            nx, ny = normals[i0, 0], normals[i0, 1]
        else:
            ax, ay = points[i0, 0], points[i0, 1]
            has_line = i1 != n
            second = i1 if has_line else i0
            alx, aly = points[second, 0] - ax, points[second, 1] - ay
            length = np.hypot(alx, aly)
            if has_line and length > 1e-9:
                nx, ny = -aly / max(length, 1e-12), alx / max(length, 1e-12)
            else:  # point-to-point, linearised along the current offset
                ox, oy = wx - ax, wy - ay
                offset = max(np.hypot(ox, oy), 1e-12)
                nx, ny = ox / offset, oy / offset
        residual = (wx - ax) * nx + (wy - ay) * ny
        lever = ny * (wx - pose[0]) - nx * (wy - pose[1])
        _accumulate(hessian, gradient, nx, ny, lever, residual, _weight(residual, loss, scale))
        residuals[i] = residual
        count += 1
        rotation_squares += lever * lever
    return hessian, gradient, count, rotation_squares


@njit(cache=True)
def nearest_on_surfaces(
    order: NDArray[np.int64], tree_points: NDArray[np.float64], start: NDArray[np.int64],
    end: NDArray[np.int64], child: NDArray[np.int64], box: NDArray[np.float64],
    pointlike: NDArray[np.bool_],
    query: NDArray[np.float64], max_distance: float,
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The query points (M, 2) whose nearest return lies within ``max_distance`` and is not
    ``pointlike``, and those returns (``CurveReference.nearest_returns``)."""
    n = tree_points.shape[0]
    index = np.empty(query.shape[0], np.int64)
    nearest = np.empty(query.shape[0], np.int64)
    count = 0
    bound = max_distance * max_distance
    pending = np.empty(STACK, np.int64)
    for i in range(query.shape[0]):
        i0 = search(order, tree_points, start, end, child, box,
                    query[i, 0], query[i, 1], 1, bound, pending)[1]
        if i0 != n and not pointlike[i0]:
            index[count], nearest[count] = i, i0
            count += 1
    return index[:count], nearest[:count]


@njit(cache=True)
def point_to_curve_system(
    moved: NDArray[np.float64], position: NDArray[np.float64], index: NDArray[np.int64],
    nearest: NDArray[np.int64], points: NDArray[np.float64], tangents: NDArray[np.float64],
    normals: NDArray[np.float64], a: NDArray[np.float64], b: NDArray[np.float64],
    c: NDArray[np.float64], scale: float, inlier_distance: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64], int]:
    """One point-to-curve iteration (``refine_on_curves``): the points ``moved[index]``
    (already mapped by the pose whose translation is ``position``) against the quadratics of
    returns ``nearest`` (``CurveReference.project``), Cauchy weights at ``scale``.

    Returns ``H`` (3, 3), ``g`` (3,) as :func:`point_to_line_system`, and the number of pairs
    with ``|r| < inlier_distance``.
    """
    hessian = np.zeros((3, 3))
    gradient = np.zeros(3)
    inliers = 0
    for row in range(len(index)):
        i, k = index[row], nearest[row]
        ox, oy = moved[i, 0] - points[k, 0], moved[i, 1] - points[k, 1]
        tx, ty, nx, ny = tangents[k, 0], tangents[k, 1], normals[k, 0], normals[k, 1]
        u = ox * tx + oy * ty
        slope = 2.0 * a[k] * u + b[k]
        height = c[k] + b[k] * u + a[k] * u**2
        anchor_x = points[k, 0] + u * tx + height * nx
        anchor_y = points[k, 1] + u * ty + height * ny
        norm = np.sqrt(1.0 + slope**2)
        cx, cy = (nx - slope * tx) / norm, (ny - slope * ty) / norm
        residual = (moved[i, 0] - anchor_x) * cx + (moved[i, 1] - anchor_y) * cy
        if abs(residual) < inlier_distance:
            inliers += 1
        lever = cy * (moved[i, 0] - position[0]) - cx * (moved[i, 1] - position[1])
        _accumulate(hessian, gradient, cx, cy, lever, residual, _weight(residual, CAUCHY, scale))
    return hessian, gradient, inliers


@njit(cache=True)
def _solve_step(hessian: NDArray[np.float64], gradient: NDArray[np.float64], lever: float,
                has_prior: bool, prior_information: NDArray[np.float64],
                prior_offset: NDArray[np.float64], min_information: float,
                ) -> NDArray[np.float64]:
    """``point_to_line.solve_normal_equations``, compiled; ``prior_information`` (3, 3). The
    3 x 3 system is summed and solved in place (:func:`~estimators.matching.linear_3x3.
    solved`), in the order of the array form's operations."""
    if min_information > 0 and has_prior:
        scale = np.array([1.0, 1.0, lever if lever != 0 else 1.0])
        outer = np.outer(scale, scale)
        values, vectors = np.linalg.eigh(hessian / outer)
        kept = vectors[:, values >= min_information]
        projection = kept @ kept.T
        hessian = outer * (projection @ (hessian / outer) @ projection)
        gradient = scale * (projection @ (gradient / scale))
    system = np.empty((3, 3))
    step = np.empty(3)
    for a in range(3):
        pull = 0.0  # (prior_information @ prior_offset)[a]
        for b in range(3):
            system[a, b] = hessian[a, b] + prior_information[a, b] if has_prior else (
                hessian[a, b])
            pull += prior_information[a, b] * prior_offset[b]
        system[a, a] += 1e-9
        step[a] = gradient[a] + pull if has_prior else gradient[a]
    return solved(system, step)


@njit(cache=True)
def register_loop(
    order: NDArray[np.int64], tree_points: NDArray[np.float64], start: NDArray[np.int64],
    end: NDArray[np.int64], child: NDArray[np.int64], box: NDArray[np.float64],
    points: NDArray[np.float64], normals: NDArray[np.float64], valid: NDArray[np.bool_],
    anchors: NDArray[np.float64], has_normals: bool, query: NDArray[np.float64],
    initial: NDArray[np.float64], max_iterations: int, max_distance: float, loss: int,
    scale: float, has_prior: bool, prior: NDArray[np.float64],
    prior_information: NDArray[np.float64], min_information: float,
    tolerance_translation: float, tolerance_rotation: float, inlier_distance: float,
    kept: NDArray[np.float64], near: NDArray[np.int64],
) -> tuple[NDArray[np.float64], int, bool, NDArray[np.float64], NDArray[np.float64]]:
    """The iterations of ``icp.register`` (untrimmed) in one call: the pose, the iterations
    run, whether the step fell below the tolerances, the squared residuals [m^2] at that pose
    of the query points whose residual against their pair within ``inlier_distance`` is
    below it (in query order), which the match is assessed on, and those pairs' ``J^T W J``
    (3, 3), the points' information at the pose. ``prior_information`` is (3, 3); ``kept`` and
    ``near`` the query points' neighbours found so far (:func:`fresh_neighbours` for none),
    updated in place (:func:`point_to_line_system`)."""
    pose = initial.copy()
    residuals = np.empty(query.shape[0])
    iterations = 0
    converged = False
    while iterations < max_iterations:
        iterations += 1
        hessian, gradient, count, rotation_squares = point_to_line_system(
            order, tree_points, start, end, child, box, points, normals, valid, anchors,
            has_normals, query, pose, max_distance, loss, scale, residuals, kept, near)
        if count < 3:
            break
        offset = prior - pose
        offset[2] = (offset[2] + np.pi) % (2.0 * np.pi) - np.pi
        step = _solve_step(hessian, gradient, np.sqrt(rotation_squares / count), has_prior,
                           prior_information, offset, min_information)
        pose = pose + step
        pose[2] = (pose[2] + np.pi) % (2.0 * np.pi) - np.pi
        if np.hypot(step[0], step[1]) < tolerance_translation and (
                abs(step[2]) < tolerance_rotation):
            converged = True
            break
    hessian = point_to_line_system(
        order, tree_points, start, end, child, box, points, normals, valid, anchors,
        has_normals, query, pose, inlier_distance, loss, scale, residuals, kept, near)[0]
    squares = np.empty(query.shape[0])
    inliers = 0
    for residual in residuals:
        if abs(residual) < inlier_distance:  # NaN (no pair) is never below
            squares[inliers] = residual * residual
            inliers += 1
    return pose, iterations, converged, squares[:inliers], hessian


def prior_information(noise_sigma: float, sigma_translation: float,
                      sigma_rotation: float) -> NDArray[np.float64]:
    """A motion prior's diagonal information (3,) [1/m^2, 1/m^2, 1/rad^2] in units of fully
    weighted points (the cost over ``noise_sigma^2`` [m]), from its sigmas [m, m, rad]."""
    return (noise_sigma / np.array([sigma_translation, sigma_translation, sigma_rotation])) ** 2
