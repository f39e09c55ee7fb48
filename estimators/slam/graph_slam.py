"""Graph SLAM: a Lidar odometry front end, loop closure, and pose-graph optimisation
(the ``slam`` estimator).

The front end (any registered estimator, by name) turns every scan into an odometry pose.
Every ``keyframe_distance`` of travel (or ``keyframe_angle`` of turn) the scan becomes a
keyframe: a node of a :class:`~estimators.slam.pose_graph.PoseGraph`, linked to the previous one
by an odometry edge whose uncertainty grows with the distance driven (no looser than the front
end's own error, where it measures it from its scan matches); a step that leaves most
of the new keyframe's points off the previous one's walls (a turn the front end lost) is
replaced by an all-heading match of the two keyframes when that explains more. Each new
keyframe looks for old keyframes it may revisit (at least ``min_loop_separation`` of path
behind it) or whose view it shares (at least ``min_overlap_separation`` behind, beyond the
front end's own window), within ``overlap_radius`` plus the drift since then of its current
estimate, ranked by place descriptor; each candidate is verified by a correlative scan match
plus ICP against the old keyframe and its neighbours
(:func:`estimators.slam.loop_closure.verify_loop`) and, if accepted and reachable from the graph's
estimate (within ``loop_gate`` Mahalanobis distance under the front end's drift model since
the old keyframe: a symmetric corridor's far end seen turned around passes every scan test but
not this one), becomes a loop edge. After new loop edges the graph is optimised
(Levenberg–Marquardt, a Cauchy kernel on loop edges); loop edges it still cannot reconcile
(Mahalanobis error above ``max_loop_sigma``) are dropped and the graph optimised again: a
false loop must not bend the map. Where the front end lost its place, the keyframes after
are searched in the map before (:mod:`estimators.slam.relocalization`).

Poses: ``update`` returns the online estimate (the latest keyframe's pose as optimised so
far, plus the front end's motion since it); :attr:`GraphSlam.trajectory` returns the smoothed
trajectory, every scan re-anchored on its keyframe's final pose after a last optimisation.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from estimators.base import Estimator
from estimators.matching.branch_and_bound import PyramidBuffer
from estimators.matching.point_to_line import PointToLineReference
from estimators.matching.scan_matching import DEFAULT_MIN_RANGE, scans_to_car_points
from estimators.registry import make
from estimators.slam.frontend_drift import FrontEndDrift
from estimators.slam.keyframe_matching import KeyframeMatching
from estimators.slam.keyframe_table import Keyframe, KeyframeTable
from estimators.slam.loop_closure import LoopClosureParams, LoopVerification, PlaceMap
from estimators.slam.outputs import SlamOutputs
from estimators.slam.place_descriptor import range_histogram
from estimators.slam.pose_graph import PoseGraph
from estimators.slam.relocalization import Relocalization
from estimators.slam.smoothing import blend_on_keyframes
from estimators.slam.solver import EliminationOrdering, optimize
from lidar_env.core import ConfigError, EstimatorInputError
from lidar_env.core.se2 import compose, relative


@dataclass
class GraphSlam(KeyframeMatching, Relocalization, SlamOutputs, Estimator):
    """Front end + loop closure + pose-graph optimisation. Distances [m], angles [rad].
    Defaults are for 2D Lidars indoors driven at walking speed, not tuned to one log:

    Attributes:
        frontend, frontend_params: the odometry estimator by registry name ("lidar_odometry":
            the most accurate registered one on ACES local relations) and its parameters; it
            decides which scans are usable (``min_returns`` lets through all it may take).
        keyframe_distance, keyframe_angle: a new keyframe every 0.5 m or 20 deg (keyframes
            overlap heavily; a graph of them stays ~10x smaller than one of scans).
        odometry_sigma, odometry_drift, odometry_sigma_rotation, odometry_drift_rotation:
            standard deviation of an odometry edge, ``sigma + drift * distance`` for position
            and ``sigma_rotation + drift_rotation * distance`` for heading (1 cm + 2 %,
            0.2 deg + 0.5 deg/m: a scan-to-map front end's error on local relations, measured
            around 3-4 cm and 0.35 deg per ~1 m on ACES, with a margin).
        loop_radius, loop_drift, max_search_window: a candidate's match is searched within
            ``loop_radius + loop_drift * path`` of the graph's estimate, where ``path`` is the
            distance driven since the candidate (1 m + 5 %, capped at 3 m: the drift of a good
            front end is about 1 % of distance; the search window costs grow with its area).
        overlap_radius: candidates lie within ``overlap_radius + loop_drift * path`` of the
            current estimate (3 m: their scans share most walls with this one).
        min_loop_separation: candidates at least 10 m of path back are revisits (loops).
        min_overlap_separation: candidates between 2.5 and ``min_loop_separation`` m of path
            back are matched too (overlap edges; Cartographer constrains every node to every
            submap in range the same way). They tie each stretch of keyframes together over
            more than one step, so the front end's error stops adding up along it; 2.5 m is
            beyond a scan-to-map front end's own window (``lidar_odometry`` matches the last
            ~2.5 m). Equal to ``min_loop_separation``: revisits only.
        max_candidates: verify at most 4 per keyframe, revisits first, best descriptor first.
        submap_neighbours: the old place is the candidate keyframe plus this many keyframes
            on each side (2: ~2 m of travel, enough walls to match a 180-degree scan).
        min_query_points, loop_query_keyframes: a keyframe with fewer than 100 points is
            loop-matched with up to 4 keyframes before it (placed by the graph, never the old
            place's own): a scan of a few posts pins a loop edge's heading to only 1-2 deg.
        loss_scale: Cauchy kernel scale on loop edges, as a Mahalanobis distance (3).
        loop_gate: a verified match becomes a loop edge only if it is reachable from the
            graph's current estimate: its Mahalanobis distance from it, under the covariance
            of the front end's drift along the chain since the old keyframe plus the match's
            own, is at most this (5, as ``max_loop_sigma``). The drift of a step is the front
            end's own, from its scan matches' information where it reports them
            (:mod:`estimators.slam.frontend_drift`), else the ``odometry_*`` model. A look-alike
            place the front end cannot have drifted to (a corridor's far end seen turned round,
            the next aisle of a depot, a grid of pillars one period along) fails it.
        max_loop_sigma: loop edges whose Mahalanobis error after optimisation exceeds this
            are dropped (5: far outside any honest measurement's spread).
        optimize_every: after a loop closure, optimise again once this many keyframes were
            added (5, i.e. ~2.5 m; the final trajectory is always optimised).
        global_every, global_candidates, global_window, max_descriptor_distance: when the
            drift may exceed any local window, every ``global_every``-th keyframe without a
            recent local loop is matched against the 2 old keyframes with the most similar
            descriptors (closer than 0.3), over all headings (2 deg steps, half the cost of
            1 deg; ICP refines) and +-2 m (true revisits pass within a keyframe spacing plus
            a corridor's width of the old path). Every 6th keyframe (3 m), as many as a
            query spans (``global_submap_keyframes``), so the queries tile the path; 0: off.
        global_submap_keyframes, global_min_quality, global_ambiguity_ratio: a global match
            compares the last 6 keyframes (~3 m of path) with 6 on each side of the old one,
            and must explain 75 % of the points with no other match within 80 % of its score
            (stricter than local matches: nothing but the scans vouches for it).
        global_confirmation: a global match becomes a loop edge only when a second one, of
            another query within this many keyframes, implies the same correction (10; within
            ``consistency_distance`` 0.3 m and ``consistency_angle`` 3 deg): one look-alike
            place is common indoors, two consistent ones in a row rarely are.
        lost_sigma: where the front end lost its place (``Health.lost``), the odometry edge
            across is a place unknown within this [m] (10) and of any heading (relocalization).
        min_range: readings at or below this [m] are "no return".
        match_odometry: add the covariance of a keyframe-to-keyframe match Hessian to the
            distance model of each odometry edge (True: the edge is weak where the scene
            leaves a direction free, which is where front ends drift; measured on ACES it
            kept more true loops and cut 0.005 deg off the local rotation error).
        check_steps: check each odometry step against the two keyframes' scans (True): if it
            leaves less than ``loop_params.min_quality`` of the new keyframe's points within
            ``inlier_distance`` of the previous one's walls, match the two over all headings
            and keep the match if it is unambiguous, explains more points (clearly more, if
            it is another place) and the step lies beyond ``loop_gate`` of it (see
            :meth:`_checked_step`): a corner turn the front end lost is found here, before
            loop edges spread it along a corridor.
        place_tolerance, max_places: an old place's map (likelihood field and lines) is kept
            across optimisations while none of its points moved by more than 1 mm (2 % of a
            field cell, a tenth of 1 cm range noise and of a loop edge's ~1 cm sigma; 0: rebuilt
            whenever a pose changed), the 32 used last.
        loop_params: settings of the loop verification (:class:`LoopClosureParams`); its
            ``normal_neighbours`` and ``denoise_reference`` also shape the previous keyframe's
            lines in the step check and the odometry edges' match information.
    """

    min_returns: ClassVar[int] = 3
    frontend: str = "lidar_odometry"
    frontend_params: dict[str, Any] = field(default_factory=dict)
    keyframe_distance: float = 0.5
    keyframe_angle: float = np.radians(20.0)
    odometry_sigma: float = 0.01
    odometry_drift: float = 0.02
    odometry_sigma_rotation: float = np.radians(0.2)
    odometry_drift_rotation: float = np.radians(0.5)
    loop_radius: float = 1.0
    overlap_radius: float = 3.0
    loop_drift: float = 0.05
    max_search_window: float = 3.0
    min_loop_separation: float = 10.0
    min_overlap_separation: float = 2.5
    max_candidates: int = 4
    submap_neighbours: int = 2
    loop_query_keyframes: int = 4
    min_query_points: int = 100
    loss_scale: float = 3.0
    loop_gate: float = 5.0
    max_loop_sigma: float = 5.0
    optimize_every: int = 5
    global_every: int = 6
    global_candidates: int = 2
    global_angular_step: float = np.radians(2.0)
    global_window: float = 2.0
    max_descriptor_distance: float = 0.3
    global_confirmation: int = 10
    global_submap_keyframes: int = 6
    global_min_quality: float = 0.75
    global_ambiguity_ratio: float = 0.8
    consistency_distance: float = 0.3
    consistency_angle: float = np.radians(3.0)
    lost_sigma: float = 10.0
    min_range: float = DEFAULT_MIN_RANGE
    match_odometry: bool = True
    check_steps: bool = True
    place_tolerance: float = 1e-3
    max_places: int = 32
    loop_params: LoopClosureParams = field(default_factory=LoopClosureParams)

    def __post_init__(self) -> None:
        positive = ("keyframe_distance", "keyframe_angle", "odometry_sigma",
                    "odometry_sigma_rotation", "loop_radius", "max_search_window", "loss_scale",
                    "loop_gate", "max_loop_sigma", "overlap_radius", "lost_sigma")
        lowest = {**dict.fromkeys(("odometry_drift", "odometry_drift_rotation", "loop_drift",
                                   "min_loop_separation", "min_overlap_separation", "global_every",
                                   "submap_neighbours", "loop_query_keyframes", "place_tolerance",
                                   "min_query_points"), 0),
                  **dict.fromkeys(("max_candidates", "optimize_every", "global_candidates",
                                   "global_confirmation", "max_places"), 1)}
        for name in positive:
            if not getattr(self, name) > 0:
                raise ConfigError(f"{name}: expected a positive value, got {getattr(self, name)}")
        for name, least in lowest.items():
            if not getattr(self, name) >= least:
                raise ConfigError(f"{name}: expected >= {least}, got {getattr(self, name)}")
        if self.min_overlap_separation > self.min_loop_separation:
            raise ConfigError("min_overlap_separation: expected at most min_loop_separation "
                              f"({self.min_loop_separation}), got {self.min_overlap_separation}")
        if self.frontend == "slam":
            raise ConfigError("frontend: expected an odometry estimator, got 'slam' itself")
        make(self.frontend, **self.frontend_params)  # unknown names fail here, listing valid ones

    def _reset_state(self) -> None:
        assert self.setup is not None
        self._frontend = make(self.frontend, **self.frontend_params)
        self._frontend.reset(self.setup, self._initial_pose)
        self._start_points: list[NDArray[np.float64]] | None = []  # while the start may change
        self._start_replays = 0  # the front end's start replays the graph was built on
        self._reset_graph()

    def _reset_graph(self) -> None:
        self.graph = PoseGraph()
        self.keyframes: list[Keyframe] = []
        self._table = KeyframeTable()  # their path lengths, descriptors, edge covariances
        self._drift = FrontEndDrift(self._frontend, self.keyframe_distance)  # since a keyframe
        self._scan_keyframe: list[int] = []  # keyframe index each scan hangs from
        self._scan_odometry: list[NDArray[np.float64]] = []
        # (keyframe, neighbours) -> (map, the poses it was built at, optimisations by then)
        self._places: OrderedDict[tuple[int, int], tuple[PlaceMap, NDArray, int]] = OrderedDict()
        self._pyramid_buffer = PyramidBuffer()
        self._ordering = EliminationOrdering()  # the graph's solves, kept as it grows
        self._dirty, self._since_optimized, self._optimizations = False, 0, 0
        self.loop_attempts: list[tuple[int, int, LoopVerification]] = []
        self.dropped_loops: list[tuple[int, int]] = []
        self._pending: list[tuple[int, int, LoopVerification]] = []
        self._last_loop = -(10**9)
        self._reset_relocalization()
        # (keyframe, front-end step's inlier share, the all-heading match) of checked steps
        self.step_checks: list[tuple[int, float, LoopVerification]] = []
        # a checked step's match must be unambiguous and explain more than the step's
        self._step_params = replace(self.loop_params, angular_window=np.pi,
                                    angular_step=self.global_angular_step, min_quality=0.0,
                                    min_score=0.0)
        self._global_params = replace(
            self.loop_params, angular_window=np.pi, angular_step=self.global_angular_step,
            min_quality=max(self.loop_params.min_quality, self.global_min_quality),
            ambiguity_ratio=min(self.loop_params.ambiguity_ratio, self.global_ambiguity_ratio),
        )

    def _start(self, scans: dict[str, NDArray[np.float64]], t: float) -> None:
        self._step(scans, t)

    def _skip(self, scans: dict[str, NDArray[np.float64]], t: float) -> None:
        self._frontend.update(scans, t)  # skipped there too: it sizes its search by the stretch

    def _step(self, scans: dict[str, NDArray[np.float64]], t: float) -> NDArray[np.float64]:
        poor, lost = len(getattr(self._frontend, "poor_matches", ())), self._lost_scans()
        odometry = np.asarray(self._frontend.update(scans, t), dtype=np.float64)
        self._note_lost_since(lost, len(self._observations))
        self._drift.add(float(odometry[2]))
        # a scan the front end could not match (not even by its searches) seeds no loop
        # closure and no keyframe check: on noise those searches cost seconds and find nothing
        self._poor_scan = len(getattr(self._frontend, "poor_matches", ())) > poor
        if self._start_points is None:
            step = self._keyframe_step(odometry)
            if step is not None and not self._is_keyframe(step):
                return self._add_scan(np.zeros((0, 2)), odometry, step)  # points not needed
        points = scans_to_car_points(scans, self.setup, self.min_range)
        if self._start_points is not None:  # the front end may still match its start again
            self._start_points.append(points)
            replays, kept = getattr(self._frontend, "start_replays", 0), self._start_points
            if not getattr(self._frontend, "start_pending", False):
                self._start_points = None
            if replays > self._start_replays:  # it did: build the graph anew
                self._start_replays = replays
                self._reset_graph()
                used = np.delete(self._frontend.trajectory, self._frontend.health.skipped, 0)
                for scan_points, pose in zip(kept, used, strict=True):
                    odometry = self.add_scan(scan_points, pose)
                return odometry
        return self.add_scan(points, odometry)

    def add_scan(self, points: NDArray[np.float64], odometry: NDArray[np.float64]
                 ) -> NDArray[np.float64]:
        """Take one scan's car-frame points (M, 2) and the front end's pose for it; return the
        online pose estimate (3,). Public so a recorded front-end run can be replayed. The
        points are read only when the scan becomes a keyframe (:meth:`_is_keyframe`)."""
        odometry = np.asarray(odometry, dtype=np.float64)
        return self._add_scan(points, odometry, self._keyframe_step(odometry))

    def _add_scan(self, points: NDArray[np.float64], odometry: NDArray[np.float64],
                  step: NDArray[np.float64] | None) -> NDArray[np.float64]:
        """:meth:`add_scan` given the front end's :meth:`_keyframe_step` to this scan."""
        if step is None or self._is_keyframe(step):
            self._add_keyframe(points, odometry, step)
            step = relative(odometry, odometry)  # the keyframe's own pose in its frame
        self._scan_keyframe.append(len(self.keyframes) - 1)
        self._scan_odometry.append(odometry.copy())
        return compose(self.graph.pose(-1), step)

    def _keyframe_step(self, odometry: NDArray[np.float64]) -> NDArray[np.float64] | None:
        """The front end's motion (3,) from the last keyframe (its frame); None before one."""
        return relative(self.keyframes[-1].odometry, odometry) if self.keyframes else None

    def _is_keyframe(self, step: NDArray[np.float64]) -> bool:
        """Whether a scan :meth:`_keyframe_step` ``step`` (3,) from the last keyframe becomes
        one (``keyframe_distance`` or ``keyframe_angle`` from it)."""
        return bool(np.hypot(step[0], step[1]) >= self.keyframe_distance
                    or abs(step[2]) >= self.keyframe_angle)

    def _add_keyframe(self, points: NDArray[np.float64], odometry: NDArray[np.float64],
                      step: NDArray[np.float64] | None) -> None:
        """Make the scan at front-end pose ``odometry`` (3,), ``step`` (3,) from the last
        keyframe (None: the first), a keyframe: a node, its odometry edge, its loops."""
        path_length = 0.0 if step is None else self.keyframes[-1].path_length + np.hypot(*step[:2])
        keyframe = Keyframe(points.copy(), range_histogram(points), odometry.copy(), path_length)
        poor = getattr(self, "_poor_scan", False)  # set by _step (add_scan: never)
        measured = self._drift.take(step)  # the front end's drift over the step
        if not self.keyframes:
            self.graph.add_node(odometry)
            error = (np.zeros((3, 3)), np.zeros((3, 3)))
        else:
            assert step is not None
            previous = self.keyframes[-1]
            reference = (PointToLineReference.with_estimated_normals(
                previous.points, self.loop_params.normal_neighbours,
                self.loop_params.denoise_reference)
                if len(previous.points) >= 3 and len(points) >= 3 else None)
            if reference is not None and self.check_steps and not poor:
                checked = self._checked_step(reference, previous.points, points, step)
                measured = None if checked is not step else measured  # not the front end's step
                step = checked
            index = self.graph.add_node(compose(self.graph.pose(-1), step))
            information, error = self._unless_lost(
                index, *self._odometry_edge(reference, points, step, poor, measured))
            self.graph.add_edge(index - 1, index, step, information)
        self.keyframes.append(keyframe)
        self._table.append(keyframe, *error)
        self._since_optimized += 1
        index = len(self.keyframes) - 1
        if self.lost_from is not None and not poor:  # no other loop until the place is found
            self._relocalize(index)
        elif self.lost_from is None and not poor and self._close_loops(index):
            self._last_loop = index
        elif (not poor and self.global_every and index % self.global_every == 0
              and index - self._last_loop > self.global_confirmation):
            self._close_global_loops(index)
        if self._dirty and self._since_optimized >= self.optimize_every:
            self.optimize()

    def optimize(self, trusted: NDArray[np.bool_] | None = None) -> None:
        """Optimise the graph (Cauchy kernel on loop edges); drop loop edges whose error is
        still above ``max_loop_sigma`` and optimise again without them.

        ``trusted`` (E,) marks loop edges that get plain least squares in a first pass (a
        confirmed global loop that moves the graph by more than the kernel's scale)."""
        if trusted is not None:
            first = optimize(self.graph, loss="cauchy", loss_scale=self.loss_scale,
                             robust_edges=self.graph.is_loop & ~trusted, max_iterations=100,
                             tolerance=1e-8, ordering=self._ordering)
            self.graph.poses = first.poses
        while True:
            loops = self.graph.is_loop
            result = optimize(self.graph, loss="cauchy", loss_scale=self.loss_scale, tolerance=1e-8,
                              robust_edges=loops, max_iterations=50, ordering=self._ordering)
            self.graph.poses = result.poses
            bad = np.flatnonzero(loops & (result.chi2 > self.max_loop_sigma**2))
            if len(bad) == 0:
                break
            edges = self.graph.edges
            self.dropped_loops.extend((int(edges[k, 0]), int(edges[k, 1])) for k in bad)
            self.graph.remove_edges(bad)
        self._dirty, self._since_optimized = False, 0
        self._optimizations += 1

    @property
    def trajectory(self) -> NDArray[np.float64]:
        """``(N, 3)`` smoothed car poses, one per observation: every scan re-anchored on its
        keyframes' optimised poses (:meth:`anchored_trajectory`), a skipped one predicted."""
        if not self._scan_keyframe:
            return np.zeros((0, 3))
        if self._dirty:
            self.optimize()
        return self._observations.all_poses(self.anchored_trajectory(self.graph.poses))

    def anchored_trajectory(self, keyframe_poses: NDArray[np.float64]) -> NDArray[np.float64]:
        """``(N, 3)`` car poses of every scan placed on the given keyframe poses (K, 3),
        blended between its two keyframes (:func:`estimators.slam.smoothing.blend_on_keyframes`):
        a loop correction then changes smoothly along the path instead of jumping at
        keyframes (which would add error to the short relations). Given the true keyframe
        poses it shows the error the front end's motion between keyframes leaves, which no
        correction of the keyframes can remove."""
        keyframe_poses = np.asarray(keyframe_poses, dtype=np.float64)
        if keyframe_poses.shape != (len(self.keyframes), 3):
            raise EstimatorInputError(f"keyframe_poses: expected shape ({len(self.keyframes)}, "
                                      f"3), got {keyframe_poses.shape}")
        return blend_on_keyframes(
            keyframe_poses,
            np.array([k.odometry for k in self.keyframes]).reshape(-1, 3),
            np.array(self._scan_odometry).reshape(-1, 3),
            np.array(self._scan_keyframe, dtype=np.int64),
            self.keyframe_distance / self.keyframe_angle,
        )
