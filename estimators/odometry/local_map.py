"""Lidar odometry by scan-to-local-map matching: the ``lidar_odometry`` estimator.

Each scan is registered by robust point-to-line ICP (:func:`estimators.matching.icp.register`)
onto a local map: the points of the last few keyframes, merged in the world frame, thinned on a
voxel grid, each moved onto the curve fitted through its neighbours, with that curve's normal
(:func:`estimators.matching.scan_matching.fit_local_curves`). Matching against several keyframes
rather than the previous scan averages out range noise and keeps more wall in view, which is
what removes most of scan-to-scan ICP's error (compare KISS-ICP, Vizzo et al. 2023; Hess et
al. 2016, Cartographer's local SLAM); pairing on the fitted curve rather than on the one
reading that happened to land first in a voxel averages the map's own noise too.

The initial guess and a weak prior come from a constant-velocity model of the estimator's own
recent increments (never odometry; :mod:`estimators.odometry.velocity_model`): the translation
averaged over the last few, the rotation from the last one. By default the model counts scans,
not seconds, because logged timestamps cannot be trusted (real logs hold stamps out of order and
bursts of nearly equal ones); ``use_timestamps=True`` scales the increment by the time step
instead (for sources with clean clocks and dropped scans), with steps outside [0.5, 2] x the
running median clipped and non-positive ones replaced by the median. Where the scan constrains
the pose the data dominate; down a bare corridor the prior holds the motion, so two things decide
the error there: the corridor's axis must be recognised as free (wall normals are fitted through
9 neighbours rather than 5, whose noise passes for information along the axis), and the speed
carried into it is the average of several increments, not the last one. The prior's strength
follows the scan clock: a steady clock vouches for the constant-velocity guess, which damps the
step noise of every scan; a jittery one leaves it weak.

A start down a bare corridor hides the start speed: measured later, the start is matched again
(:mod:`estimators.odometry.unknown_start`). Turned towards a wall, a car's steps along a corridor
are tied to the seen ones by its wheels, once the point that does not slip is found
(``calibrated_sideslip_sigma``).

Scans far apart (a metre or more) start ICP from a branch-and-bound search over every pose
the car can have reached; a poor match gets correlative searches in ever wider windows, and
one that stays poor is flagged in ``poor_matches`` (:mod:`estimators.odometry.far_scans`). A
match a search placed, or one explaining less than 90 % of its scan, is checked against the
scan's match to the previous scan: a poorly explained map match
that turns the car away from what the two scans show is matched again from their increment
(:mod:`estimators.odometry.scan_check`; a 180-degree Lidar down a corridor fits the walls
about as well turned round). All
Lidars are merged in the car frame (:func:`estimators.matching.scan_matching.scans_to_car_points`).

Moving things (``reject_dynamic``, on by default,
:class:`~estimators.odometry.moving_points.MovingPointFilter`, used by
:mod:`estimators.odometry.moving_rejection`): points in space recent scans saw as free, or next
to points the new scan sees through, neither pull the registration nor enter the map, and map
points the new scan sees through leave it (from
:data:`~estimators.odometry.moving_rejection.MIN_MOVING_POINTS` on). They are judged at the
matched pose (judged at the guess, a fast turn condemns static points), then the scan is matched
again without them, twice (:mod:`estimators.odometry.static_rematch`).

What each of these choices is worth, with the commands that measure it, is in the
documentation's design page (``docs/design-choices.md``).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from estimators.base import Estimator
from estimators.health import evident_time_step, intervals_since_used
from estimators.matching.icp import ICPParams, leaves_a_direction_free, register
from estimators.matching.match_result import MatchResult
from estimators.matching.neighbourhood_fits import check_neighbours
from estimators.matching.normal_equations import prior_information
from estimators.matching.point_to_line import PointToLineReference
from estimators.matching.scan_matching import (
    DEFAULT_MIN_RANGE,
    CarPoints,
    voxel_downsample,
)
from estimators.odometry.far_scans import FarScanMatching, GlobalSearch
from estimators.odometry.motion_prior import no_sideslip_prior
from estimators.odometry.moving_rejection import MovingPointRejection
from estimators.odometry.no_slip_point import NoSlipFit
from estimators.odometry.static_rematch import StaticRematch
from estimators.odometry.unknown_start import UnknownStartSpeed
from estimators.odometry.velocity_model import ConstantVelocityModel
from lidar_env.core import ConfigError
from lidar_env.core.se2 import compose, relative_floats, transform_points, wrap_float


@dataclass
class LocalMapOdometry(UnknownStartSpeed, FarScanMatching, ConstantVelocityModel,
                       StaticRematch, MovingPointRejection, Estimator):
    """Scan-to-local-map Lidar odometry with a robust loss, a constant-velocity motion prior
    and a correlative fallback. Distances [m], angles [rad]; defaults chosen for indoor 2D
    Lidars (1-3 cm range noise, 5-40 Hz), not for one log:

    Attributes:
        keyframe_distance, keyframe_angle: a scan becomes a keyframe once the car moved this
            far from the last one (0.25 m, 10 deg: consecutive keyframes still overlap by far
            more than half, so the map never loses the surfaces in view).
        n_keyframes: keyframes merged into the local map (10, i.e. the last ~2.5 m of travel;
            older ones carry drift and mostly surfaces out of view).
        voxel_size: map thinning (0.05 m: a few times the range noise, finer than walls'
            curvature). At 3 cm range noise a wall's points spread over several voxels
            across it; ``max_normal_neighbours`` is what keeps such a band a line. Keeping
            one reading per cell weighs every occupied cell alike, so a wall whose noise band
            straddles a cell boundary unevenly moves by up to a few mm (worst at voxels 3-5x
            the range noise: 4-8 mm at 5 cm and 1 cm noise, ~0.5 mm at 2 cm). 0.02 m removes that
            on clean simulated drives but costs about twice the CPU, and at 2-3 cm noise 72
            neighbours then span too little wall, so it is not the default.
        scan_voxel_size: thinning of each scan (0.02 m, about the range noise: only
            near-duplicate returns of dense 360-beam scans of near walls merge).
        loss, loss_scale: robust loss and its scale (Cauchy, 0.1 m: a few range-noise sigmas).
        max_correspondence_distance: pairing gate (0.5 m: a constant-velocity guess is within
            a few cm at 10 Hz; half a metre tolerates a sudden stop or start).
        prediction_acceleration: [m/s^2] how far the constant-velocity guess misses, as
            ``prediction_acceleration * dt^2`` over the scan interval ``dt`` (0.5, a brisk
            indoor robot: 5 mm at 10 Hz, 2 cm at 5 Hz), plus speed times the interval's
            jitter; taken from the logged clock's median and median deviation over the last
            200 scans, so glitching stamps (Intel) only weaken the prior; after a hard stop (a
            miss over twice that in ``velocity_window`` scans) the largest miss (``missed_sigma``).
        prior_sigma_translation, prior_sigma_rotation: the weakest per-scan deviation from
            constant velocity the prior allows, and its value before the clock is known
            (0.03 m: braking or accelerating at ~1 m/s^2 shifts a robot by 0.5 a dt^2 =
            0.02 m over a 0.2 s scan interval; 0.1 rad: a sharp change of turn rate). The
            prior is weighed against points with ``noise_sigma`` (0.02 m): at 0.03 m it is
            worth about half a point, at 5 mm (10 Hz) about 16, against hundreds in a
            well-constrained scan, so it decides the directions the scan leaves (nearly)
            free and damps the noise of the others a little.
        min_information: directions the scan pins down with less information than this many
            points squarely facing that way follow the motion prior alone (2: a corridor's
            axis, seen only through the noise of the wall normals; one small object in view
            already gives more; see :func:`estimators.matching.icp.gauss_newton_step`).
        min_quality: share of points explained below which the correlative search runs (0.5).
        search_linear_window, search_angular_window: its window around the guess (0.5 m,
            30 deg: a sharp change of turn rate); when the match found there is still poor,
            the heading window widens to all headings (rare, and ~0.6 s each), then to the
            far-apart window.
        max_speed, max_turn_rate: [m/s], [rad/s] how fast the car can go (1.5, 1.5: a brisk
            indoor robot, the simulated car's limits): scans far apart are searched over every
            pose within these times the scan interval (:mod:`estimators.odometry.far_scans`).
        search_resolution: the search's translation step and likelihood-field cell (0.05 m:
            it only has to land in ICP's basin, several cm wide; decoupled from
            ``voxel_size`` because the search's cost grows with the inverse square of it).
        min_range: readings below this [m] are "no return".
        use_timestamps: constant velocity per second rather than per scan (False; see above).
        normal_neighbours: map points a normal is fitted through (9: ~0.4 m of wall at the
            0.05 m voxels, so a normal's direction noise is a few degrees at 1-3 cm range
            noise; corners and small objects fail the line test and pair point-to-line
            through their two nearest points instead).
        max_normal_neighbours: where 9 neighbours fail the line test but spread across it no
            more than twice the map's median (the noise of a wall, not a corner's shape), the
            fit is repeated through 18, 36, then 72 (up to 0.5 m away: at 5 cm voxels a band
            3-4 voxels thick needs ~70 points to span 1 m of wall). At 2-3 cm range noise
            9 neighbours of a wall look like a blob, their two-nearest-point lines point anywhere
            in the band, and that noise passes for information along a corridor's axis; at
            1 cm the walls' 9-point fits already pass (fits just past that spread are
            grown too: ``neighbourhood_fits.GROW_SPREAD``). A 5 m wide featureless corridor at
            2-3 cm range noise still drifts 0.1-1.5 m over 15 m: the remaining
            two-nearest-point pairs, often two points of a wall's noise band lying across it,
            carry more information along the axis than the fitted lines and outvote the
            prior (a known limit; see the design page).
        denoise_map: pair on each map point moved onto the parabola through its neighbours
            rather than on the raw point (True; a parabola rather than a line, so a 0.3 m
            cylinder's points are not pulled ~3 cm inwards).
        reject_dynamic, dynamic_margin: drop points on moving things (module docstring) lying
            this far inside space seen free (0.2 m). On by default: walkers drag the plain
            odometry by up to metres, at ~1.5x the CPU.
        moving_filter: the filter's other settings by name, over its defaults (None: all
            defaults): ``radius`` [m], ``history`` [scans], ``stale_resolution`` [m],
            ``anchor_time`` [s], ``max_anchor_scans``, ``anchor_spacing`` [m],
            ``anchor_break`` [m], ``map_clearance`` [m], ``map_support`` [m] (see
            :class:`~estimators.odometry.moving_points.MovingPointFilter`); its margin is
            ``dynamic_margin``, its ``min_range`` ours.
        sideslip_sigma: [m] how far a car frame at the wheels' no-slip point may slip
            sideways over a scan interval where the scan leaves a direction free: there the
            match is run again under that constraint, linearised at the match
            (``motion_prior.no_sideslip_prior``: at the guess, a turn rate that jumps between
            two scans tilts it by half a turn), from the first scan; inf, the default: the
            no-slip point is not known (below). Finite, the velocity keeps no sideways part.
        calibrated_sideslip_sigma: [m] with ``sideslip_sigma`` inf, the slip allowed once the
            no-slip point is found online (6e-4, the simulated car's; inf: never looked for):
            the car frame's offset ahead of it is fitted to the steps the scans pin across the
            car; the constraint (plus the offset's error) holds while that fit is confident and
            consistent (:mod:`estimators.odometry.no_slip_point`; a CARMEN laser frame may be).
        velocity_window: increments the constant-velocity translation is averaged over (5:
            0.25-1 s at 5-20 Hz, shorter than a robot's changes of speed, and it cuts the
            noise of one increment about fivefold).
        speed_information: [points] a direction the match pins with ``lambda`` points' worth
            of information moves the velocity ``lambda / (lambda + speed_information)`` of
            the way to the match's increment (10; see
            ``velocity_model.ConstantVelocityModel._weakly_seen_held``): at 1-2 cm range noise
            ten points fix a step to about 5 mm, far fewer leave its noise to walk the speed.
        start_speed_scans, max_start_replay: where the first scans cannot tell the start
            velocity (:mod:`estimators.odometry.unknown_start`), it is the mean over this many
            scans in a row that pin every direction down (20: the mean of n increments is the
            displacement over n scans over n, its error falls as 1/n), and the scans kept
            until then, at most ``max_start_replay`` (300: 30 s at 10 Hz; 0: never), are
            matched again with it.

    After a run, ``fallbacks`` counts the correlative searches that were needed, ``far_searches``
    the far-apart ones, ``scan_corrections`` the map matches the scan-to-scan check replaced
    (:mod:`estimators.odometry.scan_check`), and ``poor_matches`` lists the scans still matched
    poorly (flagged). ``scan_information`` is the last scan's match information (3, 3): its
    inlier pairs' ``J^T W J`` at the matched pose (world-frame x, y [m], heading [rad]; one
    point squarely facing a direction adds 1), zeros for a scan matched to nothing.
    """

    #: One pillar in range (3-9 returns of a short-range Lidar in a hall) still pins the pose
    #: against the map and the motion prior: skipped, it left TurtleBot drives through
    #: sparse halls at 2.6-28 % drift, matched at 0.6-8 % (``benchmarks/bench_sparse_halls.py``).
    min_returns: ClassVar[int] = 3

    keyframe_distance: float = 0.25
    keyframe_angle: float = np.radians(10.0)
    n_keyframes: int = 10
    voxel_size: float = 0.05
    scan_voxel_size: float = 0.02
    loss: str = "cauchy"
    loss_scale: float = 0.1
    max_correspondence_distance: float = 0.5
    max_iterations: int = 20
    prior_sigma_translation: float = 0.03
    prior_sigma_rotation: float = 0.1
    noise_sigma: float = 0.02
    min_information: float = 2.0
    min_quality: float = 0.5
    search_linear_window: float = 0.5
    search_angular_window: float = np.radians(30.0)
    search_resolution: float = 0.05
    min_range: float = DEFAULT_MIN_RANGE
    use_timestamps: bool = False
    normal_neighbours: int = 9
    max_normal_neighbours: int = 72
    velocity_window: int = 5
    speed_information: float = 10.0
    denoise_map: bool = True
    prediction_acceleration: float = 0.5
    reject_dynamic: bool = True
    dynamic_margin: float = 0.2
    max_speed: float = 1.5
    max_turn_rate: float = 1.5
    sideslip_sigma: float = np.inf
    calibrated_sideslip_sigma: float = 6e-4
    start_speed_scans: int = 20
    max_start_replay: int = 300
    moving_filter: Mapping[str, float] | None = None

    def __post_init__(self) -> None:
        for name in (
            "keyframe_distance", "keyframe_angle", "voxel_size", "scan_voxel_size",
            "prior_sigma_translation",
            "prior_sigma_rotation", "noise_sigma", "search_linear_window",
            "search_angular_window", "search_resolution", "prediction_acceleration",
            "speed_information",
            "dynamic_margin", "max_speed", "max_turn_rate", "sideslip_sigma",
            "calibrated_sideslip_sigma",
        ):
            if not getattr(self, name) > 0:
                raise ConfigError(f"{name}: expected a positive value, got {getattr(self, name)}")
        check_neighbours(self.normal_neighbours, self.max_normal_neighbours)
        lowest = {"velocity_window": 1, "start_speed_scans": 1, "max_start_replay": 0,
                  "n_keyframes": 1}
        for name, least in lowest.items():
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < least:
                raise ConfigError(f"{name}: expected an integer >= {least}, got {value!r}")
        if not 0 <= self.min_quality <= 1:
            raise ConfigError(f"min_quality: expected a share in [0, 1], got {self.min_quality}")
        self._check_moving_filter()
        self.params = ICPParams(
            max_iterations=self.max_iterations,
            max_correspondence_distance=self.max_correspondence_distance, loss=self.loss,
            loss_scale=self.loss_scale, trim_ratio=1.0, min_information=self.min_information)
        self._prior_information = prior_information(
            self.noise_sigma, self.prior_sigma_translation, self.prior_sigma_rotation)

    def _reset_state(self) -> None:
        self._keyframes: deque[tuple[NDArray[np.float64], NDArray[np.float64]]] = deque(
            maxlen=self.n_keyframes
        )
        self._reference: PointToLineReference | None = None
        self._search: GlobalSearch | None = None
        self._reset_motion_model()
        self._car_points = CarPoints(self.setup, self.min_range)
        self._reset_moving_filter()
        self.fallbacks = self.far_searches = self.scan_corrections = 0
        self._previous_scan: tuple[int, NDArray[np.float64]] | None = None  # (index, points)
        self._far_steps: deque[tuple[float, float]] = deque(maxlen=self.velocity_window)
        self.poor_matches: list[int] = []
        self.scan_information = np.zeros((3, 3))

    def _points(self, scans: dict[str, NDArray[np.float64]]) -> NDArray[np.float64]:
        points = self._car_points(scans)
        return voxel_downsample(points, self.scan_voxel_size) if len(points) else points

    def _add_keyframe(self, pose: NDArray[np.float64], points: NDArray[np.float64]) -> None:
        self._keyframes.append((pose.copy(), transform_points(pose, points)))
        self._build_reference()

    def _build_reference(self) -> None:
        merged = voxel_downsample(
            np.concatenate([world for _, world in reversed(self._keyframes)]), self.voxel_size
        )
        if len(merged) < 2:
            self._reference = None
            return
        self._reference = PointToLineReference.with_estimated_normals(
            merged, self.normal_neighbours, self.denoise_map, self.max_normal_neighbours
        )
        self._search = None

    def _start(self, scans: dict[str, NDArray[np.float64]], t: float) -> None:
        self._last_time = t
        points = self._points(scans)
        self._add_keyframe(self._initial_pose, points)
        self._remember(self._initial_pose, scans, points)
        self._watch_start(scans, t)

    def _step(self, scans: dict[str, NDArray[np.float64]], t: float) -> NDArray[np.float64]:
        return (self._watched_step if self._kept is not None else self._odometry_step)(scans, t)

    def _no_sideslip_match(self, result: MatchResult, points: NDArray[np.float64],
                           guess: NDArray[np.float64], fit: NoSlipFit) -> MatchResult:
        """``result`` matched again under the no-sideslip constraint of the step to it
        (``fit``: where the no-slip point is, how well known), held with the slip it allows
        and linearised at the match (twice: at the first match, then at the second), with the
        motion prior it was held by (:func:`~estimators.odometry.motion_prior.
        no_sideslip_prior`)."""
        assert self._reference is not None
        information = np.asarray(self.match_information, dtype=np.float64)
        diagonal = np.diag(information) if information.ndim == 2 else information
        for _ in range(2):
            sigma = fit.sigma(wrap_float(float(result.pose[2] - self.pose[2])), self._sideslip())
            centre, held = no_sideslip_prior(diagonal, guess, self.pose, result.pose,
                                             (self.noise_sigma / sigma) ** 2, fit.offset)
            result = register(self._reference, points, result.pose, self.params, centre, held)
        return result

    def _odometry_step(self, scans: dict[str, NDArray[np.float64]],
                       t: float) -> NDArray[np.float64]:
        interval = t - self._last_time
        dt = self._time_step(t)
        if not self.use_timestamps:  # scans skipped as unusable count (Estimator.update)
            dt += self.skipped_before
        predicted = self._predicted(dt, self.skipped_before)
        guess = compose(self.pose, predicted)
        points = seen = self._points(scans)
        if self._reference is None or len(points) < 3:
            if self._moving is not None:
                points = self._static_points(points, guess, scans)
            self.poor_matches.append(len(self._poses))  # nothing to match: the guess, flagged
            self.scan_information = np.zeros((3, 3))
            self._remember(guess, scans, seen, float("inf"))  # a guess: a jump
            if len(points) >= 2:
                self._add_keyframe(guess, self._map_points(guess, seen, points))
            return guess
        # the scan at the guess leaves a direction free: the no-sideslip constraint holds it
        # (a step of one scan interval: over lost scans the car may have turned and back)
        fit = None if self.skipped_before or self.clock_jumped else self._no_slip_fit()
        degenerate = fit is not None and leaves_a_direction_free(
            self._reference, points, guess, self.params)
        result, points = self._matched_without_moving(
            self._match(points, guess, predicted, interval), seen, guess, scans)
        if degenerate:
            assert fit is not None
            result = self._no_sideslip_match(result, points, guess, fit)
        pose = result.pose
        self.scan_information = (np.zeros((3, 3)) if result.information is None
                                 else result.information)
        floats = pose.tolist()  # relative()'s operations on Python floats, bit for bit
        miss = relative_floats(guess.tolist(), floats)
        self._misses.append(float(np.hypot(miss[0], miss[1])))
        increment = np.array(relative_floats(self.pose.tolist(), floats))
        if self.clock_jumped and not self.use_timestamps:  # lost scans, or a jumping stamp:
            # the scan intervals the increment spans at the speed the car held
            typical = self._clock.typical_step if self._clock.steps else interval
            dt = evident_time_step(float(np.hypot(increment[0], increment[1])),
                                   float(np.hypot(self._velocity[0], self._velocity[1])),
                                   intervals_since_used(self.skipped_before,
                                                        self.clock_jumped, interval, typical),
                                   1.0)
        # after skipped or lost scans the speed held is stale: the match alone sets the new one
        resumed = self.skipped_before > 0 or self.clock_jumped
        self._velocity = self._updated_velocity(increment, dt,
                                                None if resumed else result.information)
        # a step held to the constraint satisfies it by construction: no evidence for it
        self._calibrate_no_slip(increment, None if resumed or degenerate else result.information)
        self._remember(pose, scans, seen, self._misses[-1])
        step = relative_floats(self._keyframes[-1][0].tolist(), floats)
        if (
            np.hypot(step[0], step[1]) >= self.keyframe_distance
            or abs(wrap_float(step[2])) >= self.keyframe_angle
        ):
            self._add_keyframe(pose, self._map_points(pose, seen, points))
        return pose

