"""Point-to-line ICP (Censi's PL-ICP idea), the registration every scan matcher here builds on
(the ``icp`` estimator: :mod:`estimators.matching.icp_estimator`).

A. Censi, "An ICP variant using a point-to-line metric", ICRA 2008.

Each query point is paired with the line through its two nearest reference points (or, when
the reference carries normals, the line through its nearest point along that normal), and the
pose minimises the robust sum of squared point-to-line distances

    sum_i rho(n_i . (R(theta) p_i + t - q_i))                                   (Censi eq. 5)

Why a closed-form Gauss-Newton step rather than ``scipy.optimize.least_squares``: for fixed
pairs the problem has 3 unknowns, so one step is a 3x3 solve; a ``least_squares`` call costs
about a millisecond of set-up alone, and ICP needs 10-30 of them per scan, which would break
the real-time budget (<= 5 ms/scan). The robust loss is applied by iteratively reweighted
least squares, whose fixed point is the M-estimator's minimum;
``tests/estimators/matching/test_icp.py`` checks the step against ``least_squares`` on the
same pairs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimators.matching.match_result import MatchResult
from estimators.matching.normal_equations import register_loop
from estimators.matching.point_to_line import (
    LOSSES,
    PointToLineReference,
    gauss_newton_step,
    point_to_line_jacobian,
    robust_weights,
    solve_normal_equations,
)
from lidar_env.core import ConfigError, EstimatorInputError
from lidar_env.core.se2 import transform_points, wrap_angle

#: The prior pose (3,) and information (3, 3) register_loop reads when there is no prior.
_NO_PRIOR = np.zeros(3)
_NO_INFORMATION = np.zeros((3, 3))


@dataclass(frozen=True)
class ICPParams:
    """Settings of one point-to-line registration; distances [m], angles [rad].

    Defaults suit indoor 2D Lidars (1-3 cm range noise, walls metres away) at 5-10 Hz:
    ``max_correspondence_distance`` covers a step of ~1 m/s plus a fast turn's sweep of the
    near walls; the robust ``loss_scale`` is a few times the range noise so wall points keep
    full weight while clutter and new surfaces fade out. ``trim_ratio`` < 1 drops that share
    of the largest residuals each iteration (Chetverikov's trimmed ICP); it is off by default
    because in a corridor the few points on the far wall are the only ones that fix the motion
    along it, and they are the ones a fixed-share trim throws away.
    """

    max_iterations: int = 30
    max_correspondence_distance: float = 1.0
    loss: str = "cauchy"
    loss_scale: float = 0.1
    trim_ratio: float = 1.0
    inlier_distance: float = 0.1
    tolerance_translation: float = 1e-4
    tolerance_rotation: float = 1e-5
    min_information: float = 0.0

    def __post_init__(self) -> None:
        if self.max_iterations < 1:
            raise ConfigError(f"max_iterations: expected >= 1, got {self.max_iterations}")
        for name in ("max_correspondence_distance", "loss_scale", "inlier_distance"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"{name}: expected a positive distance [m], got "
                                 f"{getattr(self, name)}")
        if not 0 < self.trim_ratio <= 1:
            raise ConfigError(f"trim_ratio: expected a share in (0, 1], got {self.trim_ratio}")
        if self.loss not in LOSSES:
            raise ConfigError(f"unknown loss {self.loss!r}: expected one of {', '.join(LOSSES)}")
        if not self.min_information >= 0:
            raise ConfigError(f"min_information: expected a number of points >= 0, got "
                              f"{self.min_information}")


def register(
    reference: PointToLineReference, query_points: NDArray[np.float64], initial_guess: ArrayLike,
    params: ICPParams = ICPParams(), prior_pose: ArrayLike | None = None,
    prior_information: ArrayLike | None = None, compiled: bool = True,
    neighbours: tuple[NDArray[np.float64], NDArray[np.int64]] | None = None,
) -> MatchResult:
    """Robust point-to-line ICP of ``query_points`` (M, 2, query frame) onto ``reference``.

    ``prior_pose`` (3,) and ``prior_information`` ``L`` (3, 3), or (3,) for a diagonal one, add
    ``(x - prior)^T L (x - prior)`` to the cost: a motion prior [1/m^2, 1/m^2, 1/rad^2] that
    holds the pose where the scan alone does not (a long corridor); a full ``L`` can hold
    sideways motion tighter than forward motion (a car does not slip sideways). ``compiled``
    runs the iterations in one numba call
    (:func:`estimators.matching.normal_equations.register_loop`); ``False``, or a trimmed
    loss, steps in Python (the same math; the tests' reference). The compiled pair searches
    start from ``neighbours``, the query points' nearest reference points found so far (by
    default those of the last ICP of the same array: ``reference.neighbours_for``).
    """
    query_points = np.asarray(query_points).astype(np.float64, copy=False)  # (neighbours_for)
    if query_points.ndim != 2 or query_points.shape[1] != 2:
        raise EstimatorInputError(f"query points: expected shape (M, 2), got {query_points.shape}")
    pose = np.array(initial_guess, dtype=np.float64)
    if pose.shape != (3,):
        raise EstimatorInputError(
            f"initial_guess: expected a pose (x, y, heading), got shape {pose.shape}")
    information = None if prior_information is None else np.asarray(prior_information, float)
    if information is not None and information.shape not in ((3,), (3, 3)):
        raise EstimatorInputError(
            f"prior_information: expected shape (3,) or (3, 3), got {information.shape}")
    if information is not None and information.ndim == 1:
        information = np.diag(information)
    prior = None if prior_pose is None else np.asarray(prior_pose, dtype=np.float64)
    if compiled and params.trim_ratio >= 1.0 and (information is None) == (prior is None):
        pose, iterations, converged, squares, hessian = register_loop(
            *reference.kernel_arrays, np.ascontiguousarray(query_points), pose,
            params.max_iterations, params.max_correspondence_distance,
            LOSSES.index(params.loss), params.loss_scale, prior is not None,
            _NO_PRIOR if prior is None else prior,
            _NO_INFORMATION if information is None else information, params.min_information,
            params.tolerance_translation, params.tolerance_rotation, params.inlier_distance,
            *reference.neighbours_for(query_points, neighbours))
        return _assess(squares, len(query_points), pose, iterations, converged, hessian)
    converged = False
    iterations = 0
    while iterations < params.max_iterations:
        iterations += 1
        if params.trim_ratio < 1.0:
            step = _trimmed_step(reference, query_points, pose, params, information, prior)
        else:
            hessian, gradient, count, lever, _ = reference.normal_equations(
                query_points, pose, params.max_correspondence_distance, params.loss,
                params.loss_scale)
            step = None if count < 3 else solve_normal_equations(
                hessian, gradient, lever, information, _prior_offset(pose, information, prior),
                params.min_information)
        if step is None:
            break
        pose = pose + step
        pose[2] = wrap_angle(pose[2])
        if (
            np.hypot(step[0], step[1]) < params.tolerance_translation
            and abs(step[2]) < params.tolerance_rotation
        ):
            converged = True
            break
    hessian, *_, residuals = reference.normal_equations(
        query_points, pose, params.inlier_distance, params.loss, params.loss_scale)
    magnitudes = np.abs(residuals)
    inliers = magnitudes[magnitudes < params.inlier_distance]  # NaN (no pair) is never below
    return _assess(inliers * inliers, len(residuals), pose, iterations, converged, hessian)


def leaves_a_direction_free(reference: PointToLineReference, query_points: NDArray[np.float64],
                            pose: ArrayLike, params: ICPParams) -> bool:
    """Whether the pairs of ``query_points`` (M, 2) at ``pose`` (3,) carry less information than
    ``params.min_information`` fully weighted points in some direction (rotation scaled by the
    RMS lever arm): the directions :func:`register` leaves to the motion prior (a corridor's
    axis). False with ``min_information`` 0 or fewer than 3 pairs."""
    hessian, _, count, lever, _ = reference.normal_equations(
        np.asarray(query_points).astype(np.float64, copy=False), np.asarray(pose, float),
        params.max_correspondence_distance, params.loss, params.loss_scale)
    if params.min_information <= 0 or count < 3:
        return False
    scale = np.array([1.0, 1.0, lever or 1.0])
    return bool(np.linalg.eigvalsh(hessian / np.outer(scale, scale))[0] < params.min_information)


def _prior_offset(pose: NDArray[np.float64], information: NDArray[np.float64] | None,
                  prior: NDArray[np.float64] | None) -> NDArray[np.float64] | None:
    """Prior pose minus ``pose``, heading wrapped (None without a prior)."""
    if information is None or prior is None:
        return None
    offset = prior - pose
    offset[2] = wrap_angle(offset[2])
    return offset


def _trimmed_step(
    reference: PointToLineReference, query_points: NDArray[np.float64],
    pose: NDArray[np.float64], params: ICPParams, information: NDArray[np.float64] | None,
    prior: NDArray[np.float64] | None,
) -> NDArray[np.float64] | None:
    """One iteration with the largest residuals trimmed (``trim_ratio`` < 1), from the pairs
    as arrays: the pure form of what :meth:`PointToLineReference.normal_equations` compiles."""
    world = transform_points(pose, query_points)
    pairs = reference.correspond(world, params.max_correspondence_distance)
    if len(pairs.index) < 3:
        return None
    moved = world[pairs.index]
    residuals = np.einsum("ij,ij->i", moved - pairs.anchors, pairs.normals)
    keep = np.abs(residuals) <= np.quantile(np.abs(residuals), params.trim_ratio)
    jacobian = point_to_line_jacobian(moved[keep], pose[:2], pairs.normals[keep])
    weights = robust_weights(residuals[keep], params.loss, params.loss_scale)
    return gauss_newton_step(jacobian, residuals[keep], weights, information,
                             _prior_offset(pose, information, prior), params.min_information)


def _assess(squares: NDArray[np.float64], points: int, pose: NDArray[np.float64],
            iterations: int, converged: bool, information: NDArray[np.float64]) -> MatchResult:
    """The match at ``pose`` of ``points`` query points from the squared residuals [m^2] of
    those within ``inlier_distance`` of their pair and those pairs' ``information`` (3, 3)."""
    quality = len(squares) / max(points, 1)
    # np.mean's sum and division, without its checks
    rmse = math.sqrt(np.add.reduce(squares) / len(squares)) if len(squares) else math.inf
    return MatchResult(pose, quality, rmse, iterations, converged, information)


def match_scans(
    reference_points: ArrayLike,
    query_points: ArrayLike,
    initial_guess: ArrayLike = (0.0, 0.0, 0.0),
    params: ICPParams = ICPParams(),
) -> MatchResult:
    """Pose (3,) of the query scan's frame in the reference scan's frame by PL-ICP.

    Args:
        reference_points: ``(N, 2)`` [m] points of the reference scan, in its own frame.
        query_points: ``(M, 2)`` [m] points of the query scan, in its own frame.
        initial_guess: ``(3,)`` starting pose of the query frame in the reference frame.
        params: ICP settings.

    Returns:
        :class:`MatchResult`; ``result.pose`` maps query points into the reference frame
        (``transform_points(result.pose, query) ~ reference``), ``result.quality`` in [0, 1].

    Example:
        >>> result = match_scans(previous_points, current_points)
        >>> pose = compose(previous_pose, result.pose)
    """
    reference = PointToLineReference(reference_points)
    return register(reference, np.asarray(query_points, dtype=np.float64), initial_guess, params)
