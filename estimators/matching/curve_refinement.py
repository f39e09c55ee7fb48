"""Point-to-curve refinement of a scan match: each reference return carries the local quadratic
fitted through its neighbours on the same surface (:class:`CurveReference`), and
:func:`refine_on_curves` runs robust Gauss-Newton ICP onto those curves from a starting pose,
with an optional motion prior that takes over the directions the scans leave open.

The refinement stage of rotation-aware phase correlation (:mod:`estimators.matching.rotation_pc`);
the Gauss-Newton step and robust weights are :mod:`estimators.matching.icp`'s.
"""

from __future__ import annotations

from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from estimators.matching.curve_refinement_kernel import curve_reference_arrays, refine_compiled
from estimators.matching.nearest import PointIndex
from estimators.matching.normal_equations import nearest_on_surfaces, point_to_curve_system
from estimators.matching.point_to_line import solve_normal_equations
from estimators.matching.scan_matching import DEFAULT_MIN_RANGE
from lidar_env.core import EstimatorInputError
from lidar_env.core.se2 import rotate, transform_points, wrap_angle, wrap_float

FloatArray = NDArray[np.float64]



#: Neighbouring returns further apart than this [m] are not one surface (a depth jump).
MAX_SURFACE_GAP = 0.3


#: Neighbours on each side fitted with a return's local quadratic: 5 points for 3 unknowns.
SURFACE_HALF_WINDOW = 2


#: Refinement settings [m]: pairs beyond ``MAX_PAIR_DISTANCE`` are ignored; the Cauchy loss
#: scale and the inlier distance are a few times a cheap Lidar's 1-3 cm range noise.
MAX_PAIR_DISTANCE = 0.5


LOSS_SCALE = 0.05


INLIER_DISTANCE = 0.1


#: Information of a motion prior relative to one return's: ``(sigma_r / sigma_p)^2`` with the
#: range noise ``sigma_r`` = 1 cm and a prior good to ``sigma_p`` = 5 cm and 0.05 rad (a car
#: changes its step by ``a dt^2`` = 5 cm at 5 m/s^2 and 10 Hz). Hundreds of returns outweigh
#: it wherever they constrain the pose.
PRIOR_SIGMA = np.array([0.05, 0.05, 0.05])


RANGE_NOISE = 0.01


PRIOR_INFORMATION = (RANGE_NOISE / PRIOR_SIGMA) ** 2


#: A translation direction with less information than this share of the best direction's is
#: open: the spurious information of normals tilted by noise (a few hundredths of a radian
#: on 1 cm noise) is a share of about their tilt squared, well under 2 %.
DEGENERACY_RATIO = 0.02


#: A refinement has converged when its step is below 10 micrometres and 1 microradian, far
#: under the millimetre a 1 cm noisy scan supports.
STEP_TOLERANCE = (1e-5, 1e-6)


#: A refinement step that moves no point further than this [m] keeps the pairs: a point that
#: then changes its nearest return sits halfway between two returns of one surface, whose
#: curves agree there (the k-d tree search is most of an iteration's cost).
REPAIR_DISTANCE = 0.005


#: The kernel's pivot and prior arguments when none is given (read, never written).
_ZERO_PIVOT = np.zeros(2)
_NO_PRIOR = np.zeros(3)


class CurveReference:
    """A scan as a chain of local quadratics, for point-to-curve refinement.

    Point-to-line ICP (Censi 2008) pairs a point with the chord through two reference points;
    on a curved surface (a 0.3 m cylinder seen at 3 m with 1-degree beams) the chord lies up
    to ``c^2 / 8R`` ~ 1 mm inside the surface, a bias that changes with the sampling from scan
    to scan. Here each return carries the quadratic ``v = c + b u + a u^2`` (``u`` along the
    local chord, ``v`` across it) fitted by least squares to itself and up to
    ``SURFACE_HALF_WINDOW`` neighbours on each side in beam order that lie on the same surface
    (a line with fewer than three points); a point's residual is its distance to that curve
    along the curve's normal. Fitting more points than parameters also averages the range
    noise: :attr:`smoothed` holds each return moved onto its own curve.

    Args:
        ranges: ``(n,)`` [m]; beam_angles: ``(n,)`` [rad] in beam order; max_range: [m].
    """

    def __init__(self, ranges: FloatArray, beam_angles: FloatArray, max_range: float) -> None:
        # In one compiled call: the returns' points, their curves and the smoothed points
        # (some twenty small numpy calls in array form, a third of the build).
        hit, self.points, self.tangents, self.normals, self.pointlike, self.a, self.b, self.c, \
            self.smoothed = curve_reference_arrays(
                np.asarray(ranges, dtype=np.float64), np.asarray(beam_angles, dtype=np.float64),
                float(max_range), DEFAULT_MIN_RANGE, SURFACE_HALF_WINDOW, MAX_SURFACE_GAP)
        count = len(hit)
        if count < 3:
            raise EstimatorInputError(f"reference scan: expected at least 3 returns, got {count}")

    @cached_property
    def search_tree(self) -> PointIndex:
        """The returns' k-d tree, built on first use: most scans of a pipeline are only
        matched onto a reference (they need :attr:`smoothed`), and a third of the build of a
        reference that never becomes one would be its tree."""
        return PointIndex(self.points)

    @cached_property
    def refinement_arrays(self) -> tuple[NDArray[np.generic], ...]:
        """The tree's and the curves' arrays in :func:`refine_compiled`'s order."""
        return (*self.search_tree.arrays, self.pointlike, self.points, self.tangents,
                self.normals, self.a, self.b, self.c)

    def correspond(self, points: FloatArray) -> tuple[NDArray[np.intp], FloatArray, FloatArray]:
        """For the points ``(M, 2)`` (reference frame) whose nearest return lies within
        ``MAX_PAIR_DISTANCE`` and on a surface: their index, the nearest point on that return's
        curve, and its unit normal.

        A lone return (no neighbour on the same surface: a thin post, or a wall seen so
        obliquely that its returns lie far apart) pairs with nothing: point-to-point pairs with
        the same beams of the other scan would pull the match towards no motion.
        """
        index, k = self.nearest_returns(points)
        return (index, *self.project(points, index, k))

    def nearest_returns(self, points: FloatArray) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """The indices of the points ``(M, 2)`` that pair (see :meth:`correspond`) and of the
        returns they pair with."""
        return nearest_on_surfaces(*self.search_tree.arrays, self.pointlike,
                                   np.ascontiguousarray(points, dtype=np.float64),
                                   MAX_PAIR_DISTANCE)

    def project(
        self, points: FloatArray, index: NDArray[np.intp], k: NDArray[np.intp]
    ) -> tuple[FloatArray, FloatArray]:
        """The nearest points on the curves of returns ``k`` to ``points[index]``, and the
        curves' unit normals there."""
        offset = points[index] - self.points[k]
        tangent, normal = self.tangents[k], self.normals[k]
        u = np.einsum("ij,ij->i", offset, tangent)
        slope = 2.0 * self.a[k] * u + self.b[k]
        anchors = (
            self.points[k]
            + u[:, None] * tangent
            + (self.c[k] + self.b[k] * u + self.a[k] * u**2)[:, None] * normal
        )
        normals = (normal - slope[:, None] * tangent) / np.sqrt(1.0 + slope**2)[:, None]
        return anchors, normals


def chain_curves_pure(
    points: FloatArray, hit: NDArray[np.intp], n_beams: int, full_turn: bool
) -> tuple[FloatArray, FloatArray, NDArray[np.bool_], FloatArray, FloatArray, FloatArray]:
    """The local quadratics of :class:`CurveReference` in arrays: tangents, normals, which
    returns are pointlike, and the coefficients a, b, c of ``v = c + b u + a u^2`` for the
    returns ``points`` (M, 2) of beams ``hit`` of ``n_beams``. The reference the compiled
    :func:`estimators.matching.curve_refinement_kernel.chain_curves` is tested against."""
    count = len(points)
    # Neighbours at beam offsets -h..h on the same surface: every link of the chain joins
    # adjacent beams less than MAX_SURFACE_GAP apart.
    half = SURFACE_HALF_WINDOW
    offsets = np.arange(-half, half + 1)
    following = np.append(np.arange(1, count), 0)
    linked = ((hit[following] - hit) % n_beams == 1) & (
        np.hypot(*(points[following] - points).T) < MAX_SURFACE_GAP
    )
    if not full_turn:
        linked[-1] = False  # the last beam does not neighbour the first
    rows = np.arange(count)
    # links[:, h + s] joins neighbours s and s + 1 (s = -h..h-1); neighbour o < 0 is on the
    # surface when every link from it up to the return holds, o > 0 likewise.
    links = linked[(rows[:, None] + np.arange(-half, half)) % count]
    valid = np.hstack(
        [
            np.cumprod(links[:, half - 1 :: -1], axis=1)[:, ::-1],
            np.ones((count, 1), dtype=bool),
            np.cumprod(links[:, half:], axis=1),
        ]
    ).astype(bool)
    neighbours = points[(rows[:, None] + offsets) % count]
    # Local frame: along the chord between the outermost neighbours on the same surface.
    first = np.argmax(valid, axis=1)
    last = len(offsets) - 1 - np.argmax(valid[:, ::-1], axis=1)
    chord = neighbours[rows, last] - neighbours[rows, first]
    length = np.hypot(*chord.T)
    pointlike = length < 1e-9
    tangents = chord / np.where(pointlike, 1.0, length)[:, None]
    normals = np.column_stack([-tangents[:, 1], tangents[:, 0]])
    local = neighbours - points[:, None, :]
    u = np.einsum("mkj,mj->mk", local, tangents)
    v = np.einsum("mkj,mj->mk", local, normals)
    # Weighted normal equations of v = c + b u + a u^2; the tiny ridge on a turns an
    # under-determined fit (two points) into the line through them.
    design = np.stack([np.ones_like(u), u, u**2], axis=-1) * valid[..., None]
    normal_matrix = np.einsum("mki,mkj->mij", design, design)
    scale = np.maximum(length, 1e-3) ** 4
    normal_matrix[:, 2, 2] += 1e-9 * scale
    normal_matrix[pointlike] = np.eye(3)
    coefficients = np.linalg.solve(
        normal_matrix, np.einsum("mki,mk->mi", design, v)[..., None]
    )[..., 0]
    coefficients[pointlike] = 0.0
    c, b, a = coefficients.T
    return tangents, normals, pointlike, a, b, c


def refine_on_curves(
    reference: CurveReference,
    points: FloatArray,
    initial: FloatArray,
    iterations: int,
    prior: FloatArray | None = None,
    pivot: FloatArray | None = None,
    prior_information: FloatArray = PRIOR_INFORMATION,
) -> tuple[FloatArray, float]:
    """Point-to-curve ICP of ``points`` (M, 2, query sensor frame) onto ``reference`` from the
    pose ``initial`` (3,) for at most ``iterations`` (>= 1); returns the pose and the share of
    points within ``INLIER_DISTANCE`` of the reference surface (the match's confidence). The
    Gauss-Newton step and robust weights are :mod:`estimators.matching.icp`'s.

    ``prior`` (3,): a predicted pose, added with ``prior_information`` (3,) (relative to one
    return's; by default the weak ``PRIOR_INFORMATION``).
    Where the scans leave a translation direction open (a featureless corridor) their
    information along it is not zero but noise (normals fitted to noisy walls tilt by a few
    hundredths of a radian), and that noise would outweigh any weak prior; so a direction
    whose information is below ``DEGENERACY_RATIO`` of the best direction's takes the prior's
    value outright (solution remapping, Zhang, Kaess & Singh, ICRA 2016).

    ``pivot`` (2,) [m, query sensor frame]: the point whose position the prior's translation
    predicts (default the sensor itself). A motion prediction is one of the car, whose heading
    is the least certain part of it: about the car's centre, a heading error of the prediction
    does not shift the predicted position, whereas at a sensor mounted ``l`` away it shifts it
    by ``l`` times the error -- which the open direction of a corridor would then take over.
    """
    pivot = _ZERO_PIVOT if pivot is None else np.asarray(pivot, dtype=np.float64)
    pose, quality = refine_compiled(
        *reference.refinement_arrays, np.ascontiguousarray(points, dtype=np.float64),
        np.asarray(initial, dtype=np.float64), int(iterations), prior is not None,
        _NO_PRIOR if prior is None else np.asarray(prior, dtype=np.float64), pivot,
        np.asarray(prior_information, dtype=np.float64), MAX_PAIR_DISTANCE, LOSS_SCALE,
        INLIER_DISTANCE, DEGENERACY_RATIO, STEP_TOLERANCE, REPAIR_DISTANCE)
    return pose, float(quality)


def refine_pure(
    reference: CurveReference,
    points: FloatArray,
    initial: FloatArray,
    iterations: int,
    prior: FloatArray | None = None,
    pivot: FloatArray | None = None,
    prior_information: FloatArray = PRIOR_INFORMATION,
) -> tuple[FloatArray, float]:
    """:func:`refine_on_curves` step by step in arrays: the reference the compiled loop
    (:func:`estimators.matching.curve_refinement_kernel.refine_compiled`) is tested against."""
    pose = np.asarray(initial, dtype=np.float64).copy()
    pivot = np.zeros(2) if pivot is None else np.asarray(pivot, dtype=np.float64)
    quality = 0.0
    reach = float(np.max(np.hypot(points[:, 0], points[:, 1]), initial=0.0))
    pairs = None
    for _ in range(iterations):
        moved = transform_points(pose, points)
        if pairs is None:
            pairs = reference.nearest_returns(moved)
        index, k = pairs
        if len(index) < 3:
            break
        # The pairs' J^T W J and -J^T W r (Cauchy weights) and inliers, compiled: the math of
        # ``reference.project``, ``point_to_line_jacobian`` and ``robust_weights``.
        information, gradient, inliers = point_to_curve_system(
            moved, pose[:2], index, k, reference.points, reference.tangents, reference.normals,
            reference.a, reference.b, reference.c, LOSS_SCALE, INLIER_DISTANCE)
        # Scored before the step, which by then is tiny: one correspondence search saved.
        quality = inliers / len(points)
        if prior is None:
            step = solve_normal_equations(information, gradient, 0.0)
        else:
            # The prior enters as three more residual rows, on the pivot's position and the
            # heading: r + J d = (pivot moved by pose + d) - (pivot moved by prior), linearised.
            lever = rotate(pose[2], pivot)
            prior_jacobian = np.array([[1.0, 0.0, -lever[1]], [0.0, 1.0, lever[0]], [0, 0, 1]])
            prior_residuals = -pose_difference(
                np.append(prior[:2] + rotate(prior[2], pivot), prior[2]),
                np.append(pose[:2] + lever, pose[2]),
            )
            weighted = prior_jacobian * prior_information[:, None]
            step = solve_normal_equations(information + weighted.T @ prior_jacobian,
                                          gradient - weighted.T @ prior_residuals, 0.0)
            open_direction = _degenerate_translation(information)
            if open_direction is not None:
                predicted = prior[:2] + rotate(prior[2], pivot)
                moved_pivot = pose[:2] + step[:2] + rotate(pose[2] + step[2], pivot)
                step[:2] += open_direction * (open_direction @ (predicted - moved_pivot))
        pose = pose + step
        pose[2] = float(wrap_angle(pose[2]))
        if np.hypot(step[0], step[1]) < STEP_TOLERANCE[0] and abs(step[2]) < STEP_TOLERANCE[1]:
            break
        if np.hypot(step[0], step[1]) + abs(step[2]) * reach > REPAIR_DISTANCE:
            pairs = None  # points moved enough to have new nearest returns
    return pose, float(quality)



def _degenerate_translation(information: FloatArray) -> FloatArray | None:
    """The unit translation direction (2,) the weighted pairs do not constrain, or None.

    The information on translation with the heading marginalised out is the Schur complement
    of the pairs' 3x3 normal matrix ``information`` (``J^T W J``); its weaker eigen-direction
    is open when its eigenvalue is under ``DEGENERACY_RATIO`` times the stronger one.
    """
    if information[2, 2] <= 0:
        return None
    translation = (
        information[:2, :2] - np.outer(information[:2, 2], information[2, :2]) / (information[2, 2])
    )
    values, vectors = np.linalg.eigh(translation)
    if values[1] <= 0 or values[0] >= DEGENERACY_RATIO * values[1]:
        return None
    return vectors[:, 0]


def pose_difference(a: FloatArray, b: FloatArray) -> FloatArray:
    """``a - b`` with the heading difference wrapped."""
    difference = np.asarray(a, dtype=np.float64) - b
    difference[2] = wrap_float(float(difference[2]))
    return difference


def covers_full_turn(*angle_sets: FloatArray) -> bool:
    """Beams evenly spread over a full turn in every set (range profiles then correlate)."""
    for angles in angle_sets:
        steps = np.diff(angles)
        step = 2.0 * np.pi / len(angles)
        # np.allclose(steps, step, atol=1e-6) written out: a fifth of its cost, once per scan
        if not np.all(np.abs(steps - step) <= 1e-6 + 1e-5 * step):
            return False
    return True
