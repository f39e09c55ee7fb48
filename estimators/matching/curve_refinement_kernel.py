"""The point-to-curve refinement loop compiled whole: :func:`refine_compiled` runs the
iterations of :func:`estimators.matching.curve_refinement.refine_pure` (pairs, the normal
equations, the motion prior's three rows, the open direction of a corridor, the re-pairing
rule) in one numba call.

A refinement is a handful of Gauss-Newton steps on a few hundred pairs; in the array form each
step cost some forty small numpy calls (rotations, appends, 3 x 3 solves, a 2 x 2
eigen-decomposition), which made the Python around the maths most of ``pc_fusion``'s time.
``tests/estimators/matching/test_curve_refinement_kernel.py`` checks it against the array form.
:func:`curve_reference_arrays` builds a ``CurveReference`` whole (returns, points, the
quadratics of :func:`chain_curves`, smoothed points), bit for bit the array form's
(``test_curve_refinement_reference.py``); each return's 3 x 3 system is solved by
:func:`~estimators.matching.linear_3x3.solve_3x3`, LAPACK's ``dgesv`` (as OpenBLAS computes
it) written out.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

from estimators.matching.linear_3x3 import solve_3x3, solved
from estimators.matching.normal_equations import nearest_on_surfaces, point_to_curve_system


@njit(cache=True)
def _wrap(angle: float) -> float:
    """``lidar_env.core.se2.wrap_angle`` of one angle."""
    return (angle + np.pi) % (2.0 * np.pi) - np.pi


@njit(cache=True)
def _open_direction(information: NDArray[np.float64], ratio: float) -> tuple[bool, float, float]:
    """``curve_refinement._degenerate_translation``: (found, unit direction)."""
    if information[2, 2] <= 0:
        return False, 0.0, 0.0
    translation = np.empty((2, 2))
    for a in range(2):
        for b in range(2):
            translation[a, b] = (information[a, b]
                                 - information[a, 2] * information[2, b] / information[2, 2])
    values, vectors = np.linalg.eigh(translation)
    if values[1] <= 0 or values[0] >= ratio * values[1]:
        return False, 0.0, 0.0
    return True, vectors[0, 0], vectors[1, 0]


@njit(cache=True)
def refine_compiled(
    order: NDArray[np.int64], tree_points: NDArray[np.float64], start: NDArray[np.int64],
    end: NDArray[np.int64], child: NDArray[np.int64], box: NDArray[np.float64],
    pointlike: NDArray[np.bool_], reference_points: NDArray[np.float64],
    tangents: NDArray[np.float64], normals: NDArray[np.float64], a: NDArray[np.float64],
    b: NDArray[np.float64], c: NDArray[np.float64],
    points: NDArray[np.float64], initial: NDArray[np.float64], iterations: int,
    has_prior: bool, prior: NDArray[np.float64], pivot: NDArray[np.float64],
    prior_information: NDArray[np.float64], max_pair_distance: float, loss_scale: float,
    inlier_distance: float, degeneracy_ratio: float, step_tolerance: tuple[float, float],
    repair_distance: float,
) -> tuple[NDArray[np.float64], float]:
    """The pose (3,) and quality of ``refine_on_curves`` (see there for every argument; the
    reference is a ``CurveReference``'s tree and curve arrays)."""
    pose = initial.copy()
    quality = 0.0
    reach = 0.0
    for i in range(points.shape[0]):
        reach = max(reach, np.hypot(points[i, 0], points[i, 1]))
    moved = np.empty_like(points)
    index = np.empty(0, np.int64)
    nearest = np.empty(0, np.int64)
    paired = False
    identity = 1e-9 * np.eye(3)
    for _ in range(iterations):
        cos, sin = np.cos(pose[2]), np.sin(pose[2])
        for i in range(points.shape[0]):
            moved[i, 0] = points[i, 0] * cos - points[i, 1] * sin + pose[0]
            moved[i, 1] = points[i, 0] * sin + points[i, 1] * cos + pose[1]
        if not paired:
            index, nearest = nearest_on_surfaces(order, tree_points, start, end, child, box,
                                                 pointlike, moved, max_pair_distance)
            paired = True
        if len(index) < 3:
            break
        information, gradient, inliers = point_to_curve_system(
            moved, pose[:2], index, nearest, reference_points, tangents, normals, a, b, c,
            loss_scale, inlier_distance)
        quality = inliers / points.shape[0]
        if not has_prior:
            step = solved(information + identity, gradient.copy())
        else:
            lever_x = cos * pivot[0] - sin * pivot[1]
            lever_y = sin * pivot[0] + cos * pivot[1]
            prior_cos, prior_sin = np.cos(prior[2]), np.sin(prior[2])
            predicted_x = prior[0] + (prior_cos * pivot[0] - prior_sin * pivot[1])
            predicted_y = prior[1] + (prior_sin * pivot[0] + prior_cos * pivot[1])
            rows = np.array([[1.0, 0.0, -lever_y], [0.0, 1.0, lever_x], [0.0, 0.0, 1.0]])
            residuals = np.array([-(predicted_x - (pose[0] + lever_x)),
                                  -(predicted_y - (pose[1] + lever_y)),
                                  -_wrap(prior[2] - pose[2])])
            hessian = information.copy()
            total = gradient.copy()
            for r in range(3):
                for p in range(3):
                    total[p] -= prior_information[r] * rows[r, p] * residuals[r]
                    for q in range(3):
                        hessian[p, q] += prior_information[r] * rows[r, p] * rows[r, q]
            step = solved(hessian + identity, total)
            found, open_x, open_y = _open_direction(information, degeneracy_ratio)
            if found:
                heading = pose[2] + step[2]
                moved_x = pose[0] + step[0] + (np.cos(heading) * pivot[0]
                                               - np.sin(heading) * pivot[1])
                moved_y = pose[1] + step[1] + (np.sin(heading) * pivot[0]
                                               + np.cos(heading) * pivot[1])
                along = open_x * (predicted_x - moved_x) + open_y * (predicted_y - moved_y)
                step[0] += open_x * along
                step[1] += open_y * along
        pose = pose + step
        pose[2] = _wrap(pose[2])
        moved_by = np.hypot(step[0], step[1])
        if moved_by < step_tolerance[0] and abs(step[2]) < step_tolerance[1]:
            break
        if moved_by + abs(step[2]) * reach > repair_distance:
            paired = False  # points moved enough to have new nearest returns
    return pose, quality


@njit(cache=True)
def chain_curves(
    points: NDArray[np.float64], hit: NDArray[np.int64], n_beams: int, full_turn: bool,
    half: int, max_gap: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_], NDArray[np.float64],
           NDArray[np.float64], NDArray[np.float64]]:
    """``CurveReference``'s local quadratics of the returns ``points`` (beams ``hit`` of
    ``n_beams``): tangents, normals, pointlike, and the coefficients a, b, c of
    ``v = c + b u + a u^2`` (see :func:`estimators.matching.curve_refinement.chain_curves_pure`)."""
    count = points.shape[0]
    linked = np.empty(count, np.bool_)
    for i in range(count):
        j = (i + 1) % count
        linked[i] = ((hit[j] - hit[i]) % n_beams == 1) and (
            np.hypot(points[j, 0] - points[i, 0], points[j, 1] - points[i, 1]) < max_gap)
    if not full_turn:
        linked[count - 1] = False
    width = 2 * half + 1
    tangents = np.empty((count, 2))
    normals = np.empty((count, 2))
    pointlike = np.empty(count, np.bool_)
    a = np.zeros(count)
    b = np.zeros(count)
    c = np.zeros(count)
    valid = np.empty(width, np.bool_)
    gram = np.empty((3, 3))
    moment = np.empty(3)
    for r in range(count):
        valid[half] = True
        for o in range(1, half + 1):  # every link from the neighbour up to the return holds
            valid[half + o] = valid[half + o - 1] and linked[(r + o - 1) % count]
            valid[half - o] = valid[half - o + 1] and linked[(r - o) % count]
        first = 0
        while not valid[first]:
            first += 1
        last = width - 1
        while not valid[last]:
            last -= 1
        f, g = (r + first - half) % count, (r + last - half) % count
        chord_x, chord_y = points[g, 0] - points[f, 0], points[g, 1] - points[f, 1]
        length = np.hypot(chord_x, chord_y)
        pointlike[r] = length < 1e-9
        divisor = 1.0 if pointlike[r] else length
        tx, ty = chord_x / divisor, chord_y / divisor
        tangents[r, 0], tangents[r, 1] = tx, ty
        normals[r, 0], normals[r, 1] = -ty, tx
        if pointlike[r]:
            continue
        gram[:] = 0.0
        moment[:] = 0.0
        for o in range(width):
            if not valid[o]:
                continue
            k = (r + o - half) % count
            lx, ly = points[k, 0] - points[r, 0], points[k, 1] - points[r, 1]
            u, v = lx * tx + ly * ty, lx * -ty + ly * tx
            basis = (1.0, u, u * u)
            for p in range(3):
                moment[p] += basis[p] * v
                for q in range(3):
                    gram[p, q] += basis[p] * basis[q]
        gram[2, 2] += 1e-9 * max(length, 1e-3) ** 4
        if not solve_3x3(gram, moment):  # np.linalg.solve(gram, moment) in place
            raise np.linalg.LinAlgError("Matrix is singular to machine precision.")
        c[r], b[r], a[r] = moment[0], moment[1], moment[2]
    return tangents, normals, pointlike, a, b, c


@njit(cache=True)
def curve_reference_arrays(
    ranges: NDArray[np.float64], beam_angles: NDArray[np.float64], max_range: float,
    min_range: float, half: int, max_gap: float,
) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
           NDArray[np.bool_], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
           NDArray[np.float64]]:
    """A ``CurveReference``'s arrays in one call: the beams with a return (``min_range`` <
    range < ``max_range``), their points ``(M, 2)`` in the sensor frame, :func:`chain_curves`'
    quadratics (the beams counted a full turn as ``curve_refinement.covers_full_turn`` counts them)
    and the points moved onto their curves -- each by the operations of the array form, in its
    order. With fewer than 3 returns, the quadratics and smoothed points are empty."""
    n_beams = len(ranges)
    hit = np.empty(n_beams, np.int64)
    count = 0
    for beam in range(n_beams):
        if ranges[beam] < max_range and ranges[beam] > min_range:
            hit[count] = beam
            count += 1
    hit = hit[:count]
    points = np.empty((count, 2))
    for i in range(count):
        points[i, 0] = ranges[hit[i]] * np.cos(beam_angles[hit[i]])
        points[i, 1] = ranges[hit[i]] * np.sin(beam_angles[hit[i]])
    if count < 3:
        empty = np.empty((0, 2))
        nothing = np.empty(0)
        return (hit, points, empty, empty, np.empty(0, np.bool_), nothing, nothing, nothing,
                empty)
    step = 2.0 * np.pi / n_beams
    full_turn = True
    for beam in range(n_beams - 1):
        if not abs((beam_angles[beam + 1] - beam_angles[beam]) - step) <= 1e-6 + 1e-5 * step:
            full_turn = False
            break
    tangents, normals, pointlike, a, b, c = chain_curves(points, hit, n_beams, full_turn, half,
                                                         max_gap)
    smoothed = np.empty((count, 2))
    for i in range(count):
        smoothed[i, 0] = points[i, 0] + c[i] * normals[i, 0]
        smoothed[i, 1] = points[i, 1] + c[i] * normals[i, 1]
    return hit, points, tangents, normals, pointlike, a, b, c, smoothed
