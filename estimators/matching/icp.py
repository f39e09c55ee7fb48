"""Point-to-line ICP (Censi's PL-ICP idea) and the scan-to-previous-scan ``icp`` estimator.

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
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimators.base import Estimator
from estimators.health import (
    BLIND_STRETCH,
    CLOCK_HISTORY,
    CLOCK_JUMP_FACTOR,
    evident_time_step,
    intervals_since_used,
)
from estimators.matching.match_result import MatchResult
from estimators.matching.neighbourhood_fits import check_neighbours
from estimators.matching.normal_equations import prior_information, register_loop
from estimators.matching.point_to_line import (
    LOSSES,
    PointToLineReference,
    gauss_newton_step,
    point_to_line_jacobian,
    robust_weights,
    solve_normal_equations,
)
from estimators.matching.scan_matching import DEFAULT_MIN_RANGE, CarPoints
from estimators.matching.scan_recovery import (
    MIN_SEARCH_POINTS,
    lost_after_blind,
    most_likely_match,
    off_seen_through,
    one_turn_guess,
    reach,
    search_starts,
)
from estimators.matching.surface_fits import surface_reference
from estimators.paper.pc import MIN_MATCH_RETURNS
from lidar_env.core import ConfigError, EstimatorInputError
from lidar_env.core.se2 import compose, transform_points, wrap_angle

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


@dataclass
class ICPEstimator(Estimator):
    """Scan-to-previous-scan point-to-line ICP (no odometry): the baseline a user would pick.
    Both Lidars' points are merged in the car frame first.

    Each match starts from the last increment (a constant-velocity guess, as KISS-ICP and
    rf2o seed theirs) rather than from the identity: ICP's nearest-point pairs pull towards
    its starting pose, most where a corridor leaves its axis to a few points, and from the
    identity it needs about twice the iterations.

    The previous scan's lines are the curves fitted through each point's
    ``normal_neighbours`` (up to ``max_normal_neighbours`` along a noisy wall), with their
    midpoints where they bend (:mod:`estimators.matching.surface_fits`): a line through two
    returns of a wall at a grazing angle tilts with their noise and pulls the match off a
    corridor's axis. Directions the pairs pin down with less than ``min_information`` fully
    weighted points follow the constant-velocity guess alone (:func:`register`'s
    ``min_information``), held by a weak prior (``prior_sigma_*`` against ``noise_sigma``,
    widening with the scan intervals it spans), where the guess spans only observations that
    came (a clock gap may be a stamp that jumped alone).

    After skipped or lost scans the match also starts from the translation extrapolated with
    one interval's turn and from a correlative search on the last scan; of the matches
    explaining nearly the most points the least surprising is kept, after skipped ones moved
    off where it sees through the last scan (:mod:`estimators.matching.scan_recovery`).

    Parameters: see :class:`ICPParams` (distances [m]); ``min_range`` [m] drops near returns.
    """

    max_iterations: int = 30
    max_correspondence_distance: float = 1.0
    loss: str = "cauchy"
    loss_scale: float = 0.1
    trim_ratio: float = 1.0
    min_range: float = DEFAULT_MIN_RANGE
    normal_neighbours: int = 9
    max_normal_neighbours: int = 72
    min_information: float = 2.0
    noise_sigma: float = 0.02
    prior_sigma_translation: float = 0.03
    prior_sigma_rotation: float = 0.1

    def __post_init__(self) -> None:
        self.params = ICPParams(
            max_iterations=self.max_iterations,
            max_correspondence_distance=self.max_correspondence_distance,
            loss=self.loss,
            loss_scale=self.loss_scale,
            trim_ratio=self.trim_ratio,
        )
        for name in ("noise_sigma", "prior_sigma_translation", "prior_sigma_rotation"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"{name}: expected a positive value, got {getattr(self, name)}")
        check_neighbours(self.normal_neighbours, self.max_normal_neighbours)
        self._held_params = replace(self.params, min_information=self.min_information)
        self._prior_information = prior_information(
            self.noise_sigma, self.prior_sigma_translation, self.prior_sigma_rotation)

    def _reset_state(self) -> None:
        self._previous: NDArray[np.float64] | None = None
        self._increment = np.zeros(3)
        assert self.setup is not None
        self._points = CarPoints(self.setup, self.min_range)

    def _start(self, scans: dict[str, NDArray[np.float64]], t: float) -> None:
        self._previous = self._points(scans)

    def _intervals_lost(self, t: float) -> float:
        """Scan intervals since the last scan used when the clock jumped before ``t`` [s]: the
        time step over the median of the last positive ones, if :data:`CLOCK_JUMP_FACTOR` or
        more (less, as Intel's bursty stamps jump at most scans, is no loss); else 1."""
        steps = np.diff(self._times[-CLOCK_HISTORY:])
        steps = steps[steps > 0]
        lost = intervals_since_used(0, self.clock_jumped, t - self._times[-1],
                                    float(np.median(steps)) if len(steps) else 0.0)
        return lost if lost >= CLOCK_JUMP_FACTOR else 1.0

    def _recovery_starts(self, current: NDArray[np.float64], span: float, seconds: float
                         ) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
        """Starts of :mod:`estimators.matching.scan_recovery` over a gap of ``span`` intervals
        and ``seconds`` [s], each with the guess its match is judged against: the last
        increment's translation with one turn, and the searches' (far turns: skipped only)."""
        assert self._previous is not None
        kept = one_turn_guess(self._increment, span)
        return [(kept, kept)] + [(found, kept) for found in search_starts(
            self._previous, current, kept, span, seconds, self.skipped_before > 0)]

    def _step(self, scans: dict[str, NDArray[np.float64]], t: float) -> NDArray[np.float64]:
        current = self._points(scans)
        increment = np.zeros(3)
        # too few points on either side: no update (a fit of 3 points can land metres away),
        # and the last scan with enough points stays the reference
        if len(current) < MIN_MATCH_RETURNS:
            return compose(self.pose, increment)
        if self._previous is not None and len(self._previous) >= MIN_MATCH_RETURNS:
            observations = 1 + self.skipped_before  # skipped ones count (Estimator.update)
            guesses = [self._increment * observations]
            lost = self._intervals_lost(t)
            if lost > observations:  # scans lost on the way (the car drove on), or the stamp
                guesses.append(self._increment * lost)  # alone jumped (the scans ran on)
            spans = [float(observations), lost][:len(guesses)]
            starts = list(guesses)
            # after skipped or lost scans (told from a stamp that jumped alone by the matches)
            # the turn is the least known part of the guess; a search needs enough points
            span = float(max(observations, lost))
            if span > 1 and min(len(current), len(self._previous)) >= MIN_SEARCH_POINTS:
                for start, guess in self._recovery_starts(current, span, t - self._times[-1]):
                    starts.append(start)
                    guesses.append(guess)
                    spans.append(span)
            reference = surface_reference(self._previous, self.normal_neighbours,
                                          self.max_normal_neighbours)
            # free directions follow a guess over observations that came (not a clock gap's,
            # whose stamp may have jumped alone, nor the search's); priors weaken with the span
            results = [register(reference, current, start, self._held_params if (
                start is guess and span <= observations) else self.params, guess,
                                self._prior_information / span**2)
                       for start, guess, span in zip(starts, guesses, spans, strict=True)]
            best = most_likely_match(results, guesses, spans, float(np.hypot(
                *self._increment[:2])), len(current), t - self._times[-1] if span > 1 else None)
            increment = results[best].pose
            if observations > BLIND_STRETCH:
                kept, seen, place = off_seen_through(lambda start: register(  # a blind stretch
                    reference, current, start, self.params, start, self._prior_information
                    / span**2), results[best], lambda m: (m.pose, m.quality), self._previous,
                    current, reach(guesses[best], span, t - self._times[-1])[0])
                increment, starts = kept.pose, starts + ([] if place is None else [place])
                if lost_after_blind(kept.quality, seen):  # the scans cannot tell: the guess
                    self.health.note_lost(len(self._observations))
                    increment = one_turn_guess(self._increment, span)
            if min(np.hypot(*(increment[:2] - start[:2])) for start in starts) > (
                    self.params.max_correspondence_distance):
                # no pair is accepted beyond this distance, so no solution this far from the
                # guesses is backed by the points (a few sparse returns slid away): the guess
                self.health.note_unusable(len(self._observations))
                return compose(self.pose, guesses[best])
            if lost > observations:  # per interval the scans bear out at the speed held
                observations = max(observations, evident_time_step(
                    float(np.hypot(*increment[:2])), float(np.hypot(*self._increment[:2])),
                    lost, 1.0))
            self._increment = increment / observations
        self._previous = current
        return compose(self.pose, increment)
