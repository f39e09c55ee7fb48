"""Loop-closure detection and verification for 2D Lidar keyframes.

Three stages, each a pure function of plain arrays:

1. **Place descriptor** (:mod:`estimators.slam.place_descriptor`): the histogram of the
   ranges of a keyframe's points from the car's origin. It does not change when the car
   turns on the spot, so it ranks candidate places without knowing the heading. It only
   ranks: where the drift is small the candidates come from the pose uncertainty.
2. **Verification** (:func:`verify_loop`): a correlative scan match (Olson, "Real-time
   correlative scan matching", ICRA 2009) over a window of headings and translations on a
   likelihood field of the old place's points, searched exactly by the multi-resolution
   branch-and-bound of :mod:`estimators.matching.branch_and_bound` (:func:`correlative_match`),
   then refined by robust point-to-line ICP
   (:func:`estimators.matching.icp.register`).
3. **Rejection** of false loops: a match is accepted only if enough of the scan lands on the
   old map (ICP inlier share and likelihood-field score) and if the best match is clearly
   better than the best match elsewhere in the window (ambiguity test) and if it does not lay
   the scan onto the far side of what the old place saw (:mod:`estimators.slam.view_side`:
   a shelf or a row of posts seen from the aisles on either side). An accepted match is
   refined without its points on surfaces seen from their other side (a pillar's far side
   laid on its near side is a pillar's width off), and its edge's uncertainty is its ICP
   Hessian's plus the spread of the near-best poses
   (:mod:`estimators.slam.match_uncertainty`); the pose graph then
   weighs loop edges with a robust kernel and drops those it cannot reconcile
   (:mod:`estimators.slam.graph_slam`).

Frames: a keyframe's points are in its own car frame; a loop measurement is the pose of the
query keyframe in the frame of the reference keyframe. Distances [m], angles [rad].
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimators.matching.branch_and_bound import (
    MAX_LEVELS,
    GridPyramid,
    PyramidBuffer,
    levels_for_window,
    match,
)
from estimators.matching.icp import ICPParams, register
from estimators.matching.point_to_line import PointToLineReference
from estimators.matching.scan_matching import (
    LikelihoodField,
    first_in_each_cell,
    voxel_downsample,
)
from estimators.slam.match_uncertainty import match_information, score_spread
from estimators.slam.place_grid import search_pyramid
from estimators.slam.view_side import far_side_share, without_far_side
from lidar_env.core import ConfigError, EstimatorInputError
from lidar_env.core.se2 import transform_points, wrap_angle

#: A match is judged on at least this many points (fewer fit too many places).
MIN_POINTS = 10


@dataclass(frozen=True)
class LoopClosureParams:
    """Settings of :func:`verify_loop`; distances [m], angles [rad].

    Defaults are for indoor 2D Lidars with 1-3 cm range noise, not for one log:

    Attributes:
        resolution: likelihood-field cell and fine translation step (0.05 m, a few range-noise
            sigmas: finer gives no better pose, ICP refines anyway).
        sigma: likelihood-field width (0.1 m).
        coarse_factor: the translation window is whole blocks of ``2 * coarse_factor + 1``
            fine cells per axis (2: 0.25 m), and the ambiguity test compares blocks.
        angular_step: heading step (1 deg: a point 6 m away moves one 0.1 m field width).
        angular_window: heading window around the graph's guess (20 deg: the rotation drift a
            good front end accumulates over a loop of a few hundred metres).
        voxel_size, search_range: the search scores the query points within 20 m of its
            origin thinned to a 0.2 m grid (its cost is linear in the points; beyond 20 m a
            1-deg beam spacing leaves gaps wider than the field, and ICP refines with all
            points anyway).
        min_quality: share of query points within ``inlier_distance`` of the old map after ICP
            (0.6: an honest revisit sees mostly the same walls; new clutter or open doors
            take the rest).
        inlier_distance: (0.1 m).
        min_score: mean likelihood-field score after ICP (0.4).
        ambiguity_ratio: reject when a match at least ``ambiguity_distance`` away scores above
            this share of the best (0.9: a corridor's repetitive structure gives two
            near-equal peaks; a real place gives one clear peak).
        ambiguity_distance: (0.5 m).
        max_far_side: reject when more than this share of the matched points lies on
            surfaces the old place saw from their other side
            (:func:`~estimators.slam.view_side.far_side_share`).
        normal_neighbours, denoise_reference: the old place's lines come from each point's
            9 nearest neighbours, the point moved onto the parabola through them
            (:meth:`~estimators.matching.icp.PointToLineReference.with_estimated_normals`, as the
            ``lidar_odometry`` front end's map): a line through one raw reading and its 5
            neighbours carries that reading's range noise into the loop edge, and its normal
            tilts by the noise of a few points (about 1 ms CPU per place map of 1,800
            points).
        max_normal_neighbours: where 9 neighbours fail the line test, their fit is repeated
            through up to 72 (as in the ``lidar_odometry`` front end's map, whose docstring
            explains it: at 2-3 cm range noise 9 points of a wall look like a blob, and lines
            through two of them point anywhere).
        loss_scale: Cauchy scale of the refining ICP (0.03 m, about the range noise: views
            metres apart see different sides of objects, and walls behind them; those points
            pair with the wrong line, and with a wider kernel they pull the match by
            millimetres).
        search_levels: the branch and bound's pyramid has at most 5 levels (its coarsest
            nodes 16 x 16 cells; exact at any depth): a search's query has a few hundred
            points, so the 36 first nodes per heading of a +-2 m window cost less than two
            more pooled levels of the place).
        point_sigma, effective_points: the ICP Hessian becomes the edge's information
            matrix as if ``effective_points`` independent pairs of noise ``point_sigma`` had
            made it (0.05 m, 20: neighbouring residuals are strongly correlated, so hundreds
            of pairs would claim mm accuracy; loop matches are good to ~1-2 cm).
        spread_turn, spread_sigmas: an accepted match's covariance adds the spread of the
            poses within ``ambiguity_distance`` and 5 deg of it that score at least
            ``ambiguity_ratio`` of the best or within 2 standard errors of it
            (:func:`~estimators.slam.match_uncertainty.score_spread`): the Hessian's point
            noise does not hold where one pillar or a shelf's end fixes a direction.
    """

    resolution: float = 0.05
    sigma: float = 0.1
    coarse_factor: int = 2
    angular_step: float = np.radians(1.0)
    angular_window: float = np.radians(20.0)
    voxel_size: float = 0.2
    search_range: float = 20.0
    min_quality: float = 0.6
    inlier_distance: float = 0.1
    min_score: float = 0.4
    ambiguity_ratio: float = 0.9
    ambiguity_distance: float = 0.5
    max_far_side: float = 0.5
    normal_neighbours: int = 9
    denoise_reference: bool = True
    point_sigma: float = 0.05
    effective_points: float = 20.0
    loss_scale: float = 0.03
    max_normal_neighbours: int | None = 72
    search_levels: int = 5
    spread_turn: float = np.radians(5.0)
    spread_sigmas: float = 2.0

    def __post_init__(self) -> None:
        for name in ("resolution", "sigma", "angular_step", "voxel_size", "inlier_distance",
                     "point_sigma", "ambiguity_distance", "effective_points", "search_range",
                     "loss_scale"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"{name}: expected a positive value, got {getattr(self, name)}")
        if self.max_normal_neighbours is not None and (
                self.max_normal_neighbours < self.normal_neighbours):
            raise ConfigError("max_normal_neighbours: expected None or at least normal_neighbours "
                             f"({self.normal_neighbours}), got {self.max_normal_neighbours}")
        if not 1 <= self.search_levels <= MAX_LEVELS:
            raise ConfigError(f"search_levels: expected an integer in [1, {MAX_LEVELS}], got "
                              f"{self.search_levels}")
        if self.normal_neighbours < 3:
            raise ConfigError("normal_neighbours: expected an integer >= 3 (a line needs "
                             f"neighbours), got {self.normal_neighbours}")
        if self.angular_window < 0 or self.coarse_factor < 0 or self.spread_turn < 0:
            raise ConfigError("angular_window, coarse_factor and spread_turn: expected values "
                             f">= 0, got {self.angular_window}, {self.coarse_factor}, "
                             f"{self.spread_turn}")
        for name in ("min_quality", "min_score", "ambiguity_ratio", "max_far_side"):
            if not 0 <= getattr(self, name) <= 1:
                raise ConfigError(f"{name}: expected a share in [0, 1], got {getattr(self, name)}")


@dataclass(frozen=True)
class LoopVerification:
    """Outcome of :func:`verify_loop`.

    Attributes:
        accepted: the match passed every test; ``reason`` says which failed otherwise.
        pose: ``(3,)`` pose of the query keyframe in the reference keyframe's frame.
        information: ``(3, 3)`` information matrix of ``pose`` from the ICP Hessian (zeros
            when not measured: too few points, or rejected with ``measure_rejected=False``).
        quality: ICP inlier share; score: mean likelihood-field score; runner_up: best score
            of a match at least ``ambiguity_distance`` away, relative to the best, when
            above ``ambiguity_ratio`` (else 0: not searched further, see
            :meth:`CorrelativeMatch.runner_up`); searched only when every other test passed
            (else 0, and ``reason`` lists the others that failed). far_side: share of the
            matched points seen from the other side of their surface (``max_far_side``; 0
            where not measured). spread: ``(3, 3)`` covariance of the near-best poses about
            ``pose`` (:func:`~estimators.slam.match_uncertainty.score_spread`; zeros where
            ``information`` is).
    """

    accepted: bool
    reason: str
    pose: NDArray[np.float64]
    information: NDArray[np.float64]
    quality: float
    score: float
    runner_up: float
    far_side: float = 0.0
    spread: NDArray[np.float64] = field(default_factory=lambda: np.zeros((3, 3)))

    @property
    def edge_information(self) -> NDArray[np.float64]:
        """``(3, 3)`` information of the loop edge: the inverse of the Hessian's covariance
        plus :attr:`spread` (the Hessian's alone is the match's, which the loop gate tests)."""
        if not self.spread.any():
            return self.information
        return np.linalg.inv(np.linalg.inv(self.information) + self.spread)


class PlaceMap:
    """The old place's points (reference frame) ready for matching: likelihood field
    (:class:`~estimators.matching.scan_matching.LikelihoodField`), the part of its max-pooled
    pyramid each search reads (:meth:`pyramid`), a point-to-line ICP reference, and where each
    of its points was seen from (``viewpoints`` (N, 2), default the origin: one scan's points
    in its car frame). Its pyramids go into ``buffer`` when given (shared by places searched
    one after another: each pyramid is valid until the buffer's next, see
    :class:`~estimators.matching.branch_and_bound.PyramidBuffer`)."""

    def __init__(self, points: ArrayLike, params: LoopClosureParams,
                 buffer: PyramidBuffer | None = None, viewpoints: ArrayLike | None = None) -> None:
        points = np.asarray(points, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 2 or len(points) < 3:
            raise EstimatorInputError(
                f"reference points: expected shape (N >= 3, 2), got {points.shape}")
        seen = np.zeros_like(points) if viewpoints is None else np.asarray(viewpoints, np.float64)
        if seen.shape != points.shape:
            raise EstimatorInputError(f"viewpoints: expected the points' shape {points.shape}, "
                                      f"got {seen.shape}")
        keep = first_in_each_cell(np.ascontiguousarray(points), params.resolution)
        if keep.sum() >= 3:
            points, seen = points[keep], seen[keep]
        thinned, self.viewpoints = points, seen
        self.field = LikelihoodField(thinned, params.resolution, params.sigma)
        self._levels, self._buffer = 0, buffer
        self.reference = PointToLineReference.with_estimated_normals(
            thinned, params.normal_neighbours, params.denoise_reference,
            params.max_normal_neighbours)

    def forget_levels(self) -> None:
        """Search as a map built anew would: from the next search's own depth on."""
        self._levels = 0

    def pyramid(self, levels: int, points: NDArray[np.float64], center: NDArray[np.float64],
                linear_window: float, angular_window: float,
                angular_step: float) -> GridPyramid:
        """The field's pyramid where a search of ``points`` (M, 2) around ``center`` (3,)
        reads it (:func:`~estimators.slam.place_grid.search_pyramid`), with at least
        ``levels`` levels: as many as the deepest search of this place asked for (the
        depth orders the search, which decides between equal scores)."""
        self._levels = max(self._levels, levels)
        return search_pyramid(self.field, self._levels, points, center, linear_window,
                              angular_window, angular_step, self._buffer)


class CorrelativeMatch:
    """Best pose of ``points`` (M, 2, query frame) in ``place`` within ``guess[:2] ±
    linear_window`` [m] (rounded up to whole blocks of ``2 * coarse_factor + 1`` cells, plus
    ``coarse_factor`` cells) and ``guess[2] ± params.angular_window``: the exact grid optimum
    (:func:`estimators.matching.branch_and_bound.match`), as :attr:`pose` (3,) and its mean
    likelihood :attr:`score`; the ambiguity measure on demand (:meth:`runner_up`), on the
    same pyramid window."""

    def __init__(self, place: PlaceMap, points: NDArray[np.float64], guess: ArrayLike,
                 linear_window: float, params: LoopClosureParams) -> None:
        guess = np.asarray(guess, dtype=np.float64)
        res, c = params.resolution, params.coarse_factor
        block = 2 * c + 1
        n = block * int(np.ceil(linear_window / (block * res))) + c  # cells either way
        n_ang = int(np.ceil(params.angular_window / params.angular_step))
        search = (points, guess, n * res, n_ang * params.angular_step, params.angular_step)
        levels = levels_for_window(n * res, res, params.search_levels)
        self._window = (place.pyramid(levels, *search), *search)
        best = match(*self._window, -0.5)  # every score (>= 0) counts
        self.pose, self.score = best.pose, best.score
        self._guess, self._n, self._params = guess, n, params

    def runner_up(self) -> float:
        """The best score of a pose in a block whose centre lies at least
        ``ambiguity_distance`` plus one block from the best one's, relative to
        :attr:`score` (found by the same search over those blocks' translations only), when it
        exceeds ``ambiguity_ratio``, else 0: the ambiguity test needs no more, and a search
        that prunes every node below that share of the best costs less than one that ranks
        them all."""
        params, n = self._params, self._n
        res, c = params.resolution, params.coarse_factor
        block = 2 * c + 1
        shift = np.round((self.pose[:2] - self._guess[:2]) / res).astype(int)
        blocks = (np.arange(-n, n + 1) + c) // block  # the block each shift lies in
        best_block = (shift + c) // block
        reach = params.ambiguity_distance / res + block
        far = np.hypot(block * (blocks[:, None] - best_block[0]),
                       block * (blocks[None, :] - best_block[1])) >= reach
        if not far.any():
            return 0.0
        # The bound sits a hair below the ratio so that the division below, not the
        # search's rounding, makes the call.
        best = max(self.score, 1e-12)
        found = match(*self._window, params.ambiguity_ratio * best * (1.0 - 1e-9), allowed=far)
        share = max(found.score, 0.0) / best
        return share if share > params.ambiguity_ratio else 0.0


def correlative_match(
    place: PlaceMap,
    points: NDArray[np.float64],
    guess: ArrayLike,
    linear_window: float,
    params: LoopClosureParams,
) -> tuple[NDArray[np.float64], float, float]:
    """:class:`CorrelativeMatch`'s pose (3,), score and :meth:`~CorrelativeMatch.runner_up`."""
    found = CorrelativeMatch(place, points, guess, linear_window, params)
    return found.pose, found.score, found.runner_up()


def verify_loop(
    place: PlaceMap,
    query_points: ArrayLike,
    guess: ArrayLike,
    linear_window: float,
    params: LoopClosureParams = LoopClosureParams(),
    measure_rejected: bool = True,
) -> LoopVerification:
    """Verify a loop candidate: is the query keyframe (points (M, 2) in its own frame) at the
    old place, near the pose ``guess`` (3,) in the place's frame predicted by the graph?

    ``linear_window`` [m] is how far the truth may be from the guess (the pose uncertainty).
    Never raises for a bad candidate: the result says ``accepted=False`` and why.
    ``measure_rejected=False`` leaves a rejected match's ``information`` zero, unmeasured
    (:func:`match_information`, a tenth of a verification: slam reads only accepted ones').
    """
    query = np.asarray(query_points, dtype=np.float64)
    if query.ndim != 2 or query.shape[1] != 2:
        raise EstimatorInputError(f"query points: expected shape (M, 2), got {query.shape}")
    guess = np.asarray(guess, dtype=np.float64)
    if guess.shape != (3,) or not np.all(np.isfinite(guess)):
        raise EstimatorInputError(f"guess: expected a finite pose (x, y, heading), got {guess}")
    if not linear_window >= 0:
        raise ConfigError(f"linear_window: expected a distance >= 0 [m], got {linear_window}")
    nothing = np.zeros((3, 3))
    if len(query) < MIN_POINTS:
        return LoopVerification(False, f"too few query points ({len(query)} < {MIN_POINTS})", guess,
                                nothing, 0.0, 0.0, 0.0)
    near = query[np.hypot(query[:, 0], query[:, 1]) <= params.search_range]
    thinned = voxel_downsample(near if len(near) >= MIN_POINTS else query, params.voxel_size)
    search = CorrelativeMatch(place, thinned, guess, linear_window, params)
    icp = ICPParams(max_correspondence_distance=3 * params.inlier_distance,
                    inlier_distance=params.inlier_distance, loss_scale=params.loss_scale)
    result = register(place.reference, query, search.pose, icp)
    pose = result.pose
    score = float(place.field.score(transform_points(pose, query)).mean())
    failures = []
    if result.quality < params.min_quality:
        failures.append(f"ICP inlier share {result.quality:.2f} < {params.min_quality}")
    if score < params.min_score:
        failures.append(f"likelihood score {score:.2f} < {params.min_score}")
    offset = np.hypot(*(pose[:2] - guess[:2]))
    turn = abs(float(wrap_angle(pose[2] - guess[2])))
    if offset > linear_window + params.inlier_distance or turn > params.angular_window + 1e-9:
        failures.append(f"ICP left the search window ({offset:.2f} m, {np.degrees(turn):.1f} deg)")
    # The ambiguity search costs as much as the match: only a match that passed the rest
    # needs it (most rejected candidates fail on the inlier share).
    far_side = 0.0 if failures else far_side_share(
        place.reference, place.viewpoints, query, pose, params.inlier_distance)
    if far_side > params.max_far_side:
        failures.append(f"seen from behind: {far_side:.2f} of the matched points lie on "
                        f"surfaces the place saw from their other side > {params.max_far_side}")
    runner_up = 0.0 if failures else search.runner_up()
    if runner_up > params.ambiguity_ratio:
        failures.append(f"ambiguous: a match {params.ambiguity_distance} m away scores "
                        f"{runner_up:.2f} of the best > {params.ambiguity_ratio}")
    reason = "; ".join(failures) if failures else "accepted"
    if far_side > 0:  # refined, weighed and spread on the pairs seen from their own side
        kept = without_far_side(place.reference, place.viewpoints, query, pose,
                                params.inlier_distance)
        thinned = without_far_side(place.reference, place.viewpoints, thinned, pose,
                                   params.inlier_distance)
        if len(kept) >= MIN_POINTS:
            query, pose = kept, register(place.reference, kept, pose, icp).pose
    measured = measure_rejected or not failures
    information = match_information(place.reference, query, pose, params) if measured else nothing
    spread = (score_spread(place.field, thinned, pose, params.ambiguity_distance,
                           params.spread_turn, params.angular_step, params.ambiguity_ratio,
                           params.spread_sigmas)
              if measured else nothing)
    return LoopVerification(not failures, reason, pose, information, result.quality, score,
                            runner_up, far_side, spread)
