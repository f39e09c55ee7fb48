"""Two-Lidar fusion beyond the paper's eq. 10: weighted least squares on SE(2).

The paper (Sec. III.D, Fig. 4) links four nodes -- the main Lidar P1 and the offset Lidar P2
at time t-1, P3 and P4 at time t -- and averages two cross matches (eq. 10), translation only.
Here every edge of that graph is used with its full pose and its own weight:

* the two known-offset edges P1-P2 and P3-P4 are fixed by the mounts: sensor ``k`` of a car
  at pose ``X`` sits at ``X ⊕ mount_k``;
* the four matches -- same sensor 1→3 and 2→4, cross sensor 1→4 and 2→3 -- each measure
  ``z_ij``, the pose of sensor ``j`` at ``t`` in the frame of sensor ``i`` at ``t-1`` (exactly
  what a scan matcher returns for those two sensor-frame scans). With the car motion
  ``Δ = X(t-1)⁻¹ ⊕ X(t)`` each predicts ``h_ij(Δ) = mount_i⁻¹ ⊕ Δ ⊕ mount_j``.

:func:`~estimators.odometry.sensor_graph.optimize_poses` solves for the car poses that best
explain any such set of edges (:mod:`estimators.odometry.sensor_graph`); :class:`FusionEstimator`
runs it over a sliding window of keyframes.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from estimators.base import Estimator
from estimators.health import evident_time_step, intervals_since_used
from estimators.matching.curve_refinement import PRIOR_SIGMA
from estimators.matching.held_returns import MAX_AGE, check_max_age
from estimators.matching.rotation_pc import (
    PreparedScan,
    ScanMatcher,
    require_sensor_frame,
)
from estimators.odometry.edge_consensus import fuse_from_consensus
from estimators.odometry.fusion_held import HeldKeyframeScans
from estimators.odometry.fusion_keyframes import Keyframe, KeyframeMatching
from estimators.odometry.fusion_motion import CLOCK_HISTORY, FusedVelocity
from estimators.odometry.fusion_recovery import (
    POOR_SCORE,
    SCORE_TOLERANCE,
    BlindScans,
    recovered,
)
from estimators.odometry.motion_prior import (
    ScanClock,
    midpoint_velocity,
    within_prediction_horizon,
)
from estimators.odometry.sensor_graph import SensorEdge
from lidar_env.core import ConfigError, EstimatorInputError
from lidar_env.core.se2 import (
    PoseFloats,
    compose_floats,
    inverse,
    inverse_floats,
    relative_floats,
    wrap_float,
)

FloatArray = NDArray[np.float64]

@dataclass
class FusionEstimator(KeyframeMatching, FusedVelocity, Estimator):
    """Both Lidars, all four same- and cross-sensor matches, fused on SE(2) over keyframes.

    Every scan pair is matched by :class:`estimators.matching.rotation_pc.ScanMatcher` against the
    latest keyframe -- the main Lidar's pair by rotation-aware phase correlation, all four by
    ``icp_iterations`` of point-to-curve ICP -- and the four edges (paper Fig. 4) give the car
    pose by :func:`optimize_poses`.
    When the car has moved ``keyframe_distance`` [m] or turned ``keyframe_turn`` [rad] from that
    keyframe, the scans become a keyframe: they are also matched (same-sensor pairs) against
    the older keyframes of the window (``window`` keyframes in all) and the window's poses are
    re-solved with its oldest keyframe held. Matching against keyframes rather than the
    previous scan means the error grows per keyframe, not per scan, and standing still adds no
    drift.

    Defaults: ``image_size`` 200 px (10 cm pixels for a 10 m range): the correlation only
    has to land within ICP's basin, and it costs a quarter of the paper's 400 px;
    ``icp_iterations`` 3: every refinement starts within a centimetre or so (the correlation,
    or the main pair's solution), from where Gauss-Newton settles in two or three steps;
    ``keyframe_distance`` 0.3 m and ``keyframe_turn`` 0.2 rad keep consecutive
    keyframes sharing nearly all of a 10 m scan; ``window`` 2: each keyframe is solved from the
    four-node graph against the one before (measured on the Table I scenarios, 4 cases x 2
    seeds: a third keyframe 0.6 m back lowers the mean ATE from 0.014 to 0.011 m but not the
    step error -- eq.-11 accuracy 99.13 -> 99.10 % -- for 10 % more time: its scans overlap
    the latest keyframe's almost entirely); larger windows re-solve more keyframes together;
    the sigmas and ``robust_scale`` are :func:`optimize_poses`'s.

    Motion prediction (never odometry): the car's velocity is the mean of its own steps over
    the last ``velocity_window`` [s] (1 s: it carries a tenth of one step's match noise at
    10 Hz); the predicted step turns by the heading change the main pair's correlation
    measured (a constant twist moves along the chord of its turn), and each match gets it as
    a prior held about the car's centre with
    :func:`estimators.odometry.motion_prior.prediction_information`.
    It resolves the rotation's pi ambiguity, damps the steps' noise where few returns pin the
    translation down, and is the answer along featureless corridors.

    Beams lost at random (``held_scans``, default 8; 0: none): a keyframe whose Lidar lost
    a quarter or more of its beams takes them back from the returns of the last
    ``held_scans`` scans, moved by the car's estimated poses
    (:mod:`estimators.odometry.fusion_held`), so the scans after it are refined onto whole
    surfaces rather than onto the scattered half of them.
    """

    window: int = 2
    keyframe_distance: float = 0.3
    keyframe_turn: float = 0.2
    image_size: int = 200
    resolution: float | None = None
    icp_iterations: int = 3
    sigma_translation: float = 0.01
    sigma_heading: float = 0.005
    robust_scale: float = 3.0
    velocity_window: float = 1.0
    held_scans: int = MAX_AGE
    _matcher: ScanMatcher | None = field(default=None, init=False, repr=False)
    _held: HeldKeyframeScans | None = field(default=None, init=False, repr=False)
    #: the setup's mounts (N, 3) and their inverses, made once per reset
    _mounts: FloatArray = field(default_factory=lambda: np.zeros((0, 3)), init=False, repr=False)
    _mount_inverses: FloatArray = field(
        default_factory=lambda: np.zeros((0, 3)), init=False, repr=False)
    #: the same as Python floats, and the main mount's inverse made as of one pose
    _mount_floats: list[PoseFloats] = field(default_factory=list, init=False, repr=False)
    _mount_inverse_floats: list[PoseFloats] = field(
        default_factory=list, init=False, repr=False)
    _main_mount_inverse: PoseFloats = field(default=(0.0, 0.0, 0.0), init=False, repr=False)
    _keyframes: list[Keyframe] = field(default_factory=list, init=False, repr=False)
    _edges: list[tuple[int, int, SensorEdge]] = field(default_factory=list, init=False, repr=False)
    _n_keyframes: int = field(default=0, init=False, repr=False)
    _velocity: FloatArray = field(default_factory=lambda: np.zeros(3), init=False, repr=False)
    _recent: deque[tuple[list[float], float]] = field(default_factory=deque, init=False, repr=False)
    _clock: ScanClock = field(
        default_factory=lambda: ScanClock(CLOCK_HISTORY, CLOCK_HISTORY), init=False, repr=False
    )
    _bunched: bool = field(default=False, init=False, repr=False)

    def __post_init__(self) -> None:
        if isinstance(self.icp_iterations, bool) or not (
            isinstance(self.icp_iterations, int) and self.icp_iterations >= 1
        ):
            raise ConfigError(
                f"icp_iterations: expected an integer >= 1 (the cross-sensor edges are "
                f"refined matches), got {self.icp_iterations!r}"
            )
        if isinstance(self.window, bool) or not (isinstance(self.window, int) and self.window >= 1):
            raise ConfigError(f"window: expected an integer >= 1 keyframes, got {self.window!r}")
        if not self.velocity_window > 0:
            raise ConfigError(
                f"velocity_window: expected a positive duration [s], got {self.velocity_window!r}"
            )
        check_max_age(self.held_scans)
        if not (self.keyframe_distance > 0 and self.keyframe_turn > 0):
            raise ConfigError(
                "keyframe_distance [m] and keyframe_turn [rad]: expected positive numbers, got "
                f"{self.keyframe_distance}, {self.keyframe_turn}"
            )

    def _reset_state(self) -> None:
        assert self.setup is not None
        require_sensor_frame(self.setup, type(self).__name__)
        ranges = sorted({sensor.max_range for sensor in self.setup.sensors})
        if len(ranges) != 1:
            raise EstimatorInputError(
                f"{type(self).__name__}: expected Lidars of one max range (the scan images "
                f"share one geometry), got max ranges {ranges} [m]")
        self._matcher = ScanMatcher(ranges[0], self.image_size, self.resolution,
                                    self.icp_iterations)
        self._held = HeldKeyframeScans(self.setup.mounts, [
            sensor.beam_angles for sensor in self.setup.sensors], self._matcher, self.held_scans)
        self._mounts = self.setup.mounts
        self._mount_inverses = inverse(self._mounts)
        self._mount_floats = [tuple(mount) for mount in self._mounts.tolist()]
        self._mount_inverse_floats = [tuple(mount) for mount in self._mount_inverses.tolist()]
        # the main mount's inverse as se2.inverse makes it of one pose (motion_from_sensor_match)
        self._main_mount_inverse = inverse_floats(self._mount_floats[0])
        self._keyframes = []
        self._edges = []
        self._n_keyframes = 0
        self._velocity = np.zeros(3)
        self._recent = deque()
        self._clock = ScanClock(CLOCK_HISTORY, CLOCK_HISTORY)
        self._bunched = False

    def _prepare(self, scans: dict[str, FloatArray]) -> tuple[PreparedScan, ...]:
        assert self._matcher is not None and self.setup is not None
        return tuple(self._matcher.prepare(scans[key], sensor.beam_angles)
                     for key, sensor in zip(self.setup.keys, self.setup.sensors, strict=True))

    def _start(self, scans: dict[str, FloatArray], t: float) -> None:
        assert self._held is not None
        current = self._prepare(scans)
        self._held.restart(current, tuple(self._initial_pose.tolist()))
        self._add_keyframe(Keyframe(self._initial_pose.copy(), current))

    def _weights(self) -> dict[str, float]:
        return {
            "sigma_translation": self.sigma_translation,
            "sigma_heading": self.sigma_heading,
            "robust_scale": self.robust_scale,
        }

    def _step(self, scans: dict[str, FloatArray], t: float) -> FloatArray:
        assert self.setup is not None and self._held is not None
        # the poses on Python floats (compose_floats), arrays only where the matcher reads them
        current = self._prepare(scans)
        latest = self._keyframes[-1]
        stamped = t - self._times[-1]
        dt, typical = self._scan_timing(stamped)
        # past the prediction horizon (a clock gap) the velocity says nothing: no prior; the
        # guess then moves the car one typical interval on (the least time that passed, all
        # of it when only the stamp jumped), not none (a weak prior at a standstill holds a
        # corridor's axis back by a step's share)
        predicted = within_prediction_horizon(dt, typical)
        previous = self.pose.tolist()
        information = self._prediction_information(stamped, dt, predicted)
        step = (self._velocity * (dt if predicted else min(typical, default=0.0))).tolist()
        from_latest, edges, score = self._solve(latest, current, previous, step, information)
        intervals = intervals_since_used(self.skipped_before, self.clock_jumped, dt,
                                         min(typical, default=0.0))
        recovering = not predicted and intervals > 1 and bool(typical)
        if recovering:
            # or the car kept its speed over every interval since the last scan used
            # (estimators.odometry.fusion_recovery), with one interval's turn
            turning = (self._velocity * (intervals * typical[0])).tolist()
            longer = [turning[0], turning[1], step[2]]
            blind = None if not self.skipped_before else BlindScans.of(
                self._mounts, latest.scans, current, np.array(relative_floats(
                    latest.pose.tolist(), compose_floats(previous, longer))), intervals, dt)
            (from_latest, edges, score), lost = recovered(
                lambda guess: self._solve(latest, current, previous, guess, information),
                (from_latest, edges, score), step, longer, intervals, bool(self.skipped_before),
                lambda motion: list(relative_floats(previous, compose_floats(
                    latest.pose.tolist(), motion.tolist()))), blind)
            if not self.skipped_before and score < POOR_SCORE:
                # over a clock gap no search turns the car: where neither guess's match
                # explains the scans, it may have kept its turn rate too (a turn on the spot)
                turned = self._solve(latest, current, previous, turning, information)
                if turned[2] > score + SCORE_TOLERANCE:
                    from_latest, edges, score = turned
            if lost:  # the scans cannot tell where the car is: the guess, a fresh window
                self.health.note_lost(len(self._observations))
                pose = np.array(compose_floats(previous, longer))
                self._held.restart(current, tuple(pose.tolist()))
                self._restart_window(Keyframe(pose, current))
                return pose
            if blind is not None and blind.unplaced(score):  # the best placement, unvouched
                self.health.note_lost(len(self._observations))
        pose = np.array(compose_floats(latest.pose.tolist(), from_latest.tolist()))
        here = tuple(pose.tolist())
        self._held.hold(current, here, 1.0 + self.skipped_before)
        if (
            np.hypot(from_latest[0], from_latest[1]) >= self.keyframe_distance
            or abs(from_latest[2]) >= self.keyframe_turn
        ):
            pose = self._insert_keyframe(current, pose, edges, self._held.keyframe(current, here))
        else:
            latest.scans = self._held.refill(latest.scans, tuple(latest.pose.tolist()))
        motion = list(relative_floats(previous, pose.tolist()))
        if recovering:
            # a car turning over the gap moved along the chord of its turn: straight ahead
            # in the frame halfway through the turn, as it drives on from the end of it
            motion = midpoint_velocity(motion).tolist()
        speed = math.hypot(self._velocity[0], self._velocity[1])
        self._update_velocity(motion, evident_time_step(math.hypot(motion[0], motion[1]), speed,
                                                        dt, min(typical, default=0.0)))
        return pose

    def _solve(self, latest: Keyframe, current: tuple[PreparedScan, ...],
               previous: list[float], step: list[float],
               information: FloatArray) -> tuple[FloatArray, list[SensorEdge], float]:
        """The car motion from ``latest`` to ``current`` (3,), its four edges and their mean
        share of points explained, guessing the car moved ``step`` (car frame) from the
        ``previous`` pose, held by the prior ``information``."""
        assert self._matcher is not None
        mounts, mount_inverses = self._mount_floats, self._mount_inverse_floats
        to_latest = inverse_floats(latest.pose.tolist())
        guess = compose_floats(to_latest, compose_floats(previous, step))
        correlated = self._matcher.correlate(
            latest.scans[0], current[0],
            np.array(compose_floats(mount_inverses[0], compose_floats(guess, mounts[0]))))
        seed = self._motion_from_sensor_match(correlated.pose)
        # A constant twist moves the car along the chord of its turn: with the turn the
        # correlation measured (far better than the mean rate's), the predicted translation
        # turns by half the difference. Where the scans leave the translation open (a
        # corridor), this keeps a weaving car's speed instead of bending its path.
        # (on Python floats: wrap_angle's and rotate's operations, a tenth of their cost)
        x, y, heading = step
        turn = wrap_float(float(latest.pose[2]) + seed[2] - previous[2])
        if abs(wrap_float(turn - heading)) < PRIOR_SIGMA[2]:
            c, s = math.cos(0.5 * (turn - heading)), math.sin(0.5 * (turn - heading))
            step = [c * x - s * y, s * x + c * y, turn]
            guess = compose_floats(to_latest, compose_floats(previous, step))
        edges = self._match_all(latest, current, guess, seed, information)
        # Start the solver at the main Lidar's own match (edges[0]): closer than the prediction
        # (and from the others' where they disagree, estimators.odometry.edge_consensus).
        start = compose_floats(compose_floats(mounts[0], edges[0].pose.tolist()), mount_inverses[0])
        from_latest = fuse_from_consensus(self._mounts, edges, start, **self._weights())
        return from_latest, edges, sum(edge.confidence for edge in edges) / len(edges)
