"""Keyframes matched against each other for :class:`~estimators.slam.graph_slam.GraphSlam`:
each odometry step checked against the two keyframes' scans (:meth:`_checked_step`: a turn
the front end lost is replaced by an all-heading match), and loop closure: which old
keyframes a new one may revisit or overlap (:meth:`KeyframeMatching.loop_candidates`, by path
behind, distance and place descriptor), whether the graph can have drifted to a match
(:meth:`KeyframeMatching.loop_mahalanobis`, ``loop_gate``), and the verified matches that
become loop edges, near the estimate (:meth:`KeyframeMatching._close_loops`) or over all
headings for large drift (:meth:`KeyframeMatching._close_global_loops`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from estimators.matching.point_to_line import PointToLineReference
from estimators.slam.keyframe_table import largest_shift
from estimators.slam.loop_closure import (
    MIN_POINTS,
    LoopVerification,
    PlaceMap,
    verify_loop,
)
from estimators.slam.match_uncertainty import match_information
from estimators.slam.place_descriptor import descriptor_distances
from estimators.slam.pose_graph import chain_covariance
from lidar_env.core.se2 import compose, inverse, relative, transform_points


class KeyframeMatching:
    """Keyframe-to-keyframe matching for :class:`~estimators.slam.graph_slam.GraphSlam`, a
    mixin: odometry steps checked against the two keyframes' scans, and loop closure. It
    reads the graph slam's settings (``loop_params``, ``min_loop_separation``,
    ``place_tolerance``, ...) and state (``graph``, ``keyframes``, ``_table``, ``_places``,
    ``_optimizations``, ``_pending``, ``loop_attempts``, ``_pyramid_buffer``: one for all its
    searches, which run one after another) and adds loop edges to its graph."""

    def _submap(self, index: int, before: int, after: int) -> NDArray[np.float64]:
        """Points (M, 2) of keyframes ``index - before .. index + after`` in the frame of
        keyframe ``index``, placed by the graph's current poses."""
        return self._placed_points(max(0, index - before),
                                   self._submap_poses(index, before, after))

    def _query(self, index: int, old: int) -> NDArray[np.float64]:
        """Points (M, 2) keyframe ``index`` is matched with against the place of keyframe
        ``old`` (:meth:`_place`), in its frame: its own, and where they are fewer than
        ``min_query_points``, those of the keyframes before it (up to
        ``loop_query_keyframes``, none of the place's own) until they are not, placed by the
        graph's current poses. A scan of walls pins a match by itself; a scan of a few posts
        leaves its heading loose by a degree or two, which the posts passed just before fix.
        A keyframe in both the query and the place would match itself: the edge would repeat
        the graph's estimate instead of measuring it."""
        last = max(0, index - self.loop_query_keyframes, old + self.submap_neighbours + 1)
        first = index
        count = len(self.keyframes[index].points)
        while count < self.min_query_points and first > last:
            first -= 1
            count += len(self.keyframes[first].points)
        return self._submap(index, index - first, 0)

    def _placed_points(self, first: int, poses: NDArray[np.float64]) -> NDArray[np.float64]:
        """Points (M, 2) of keyframes ``first, first + 1, ...``, each placed at its row of
        ``poses`` (n, 3)."""
        return np.concatenate([transform_points(pose, self.keyframes[first + k].points)
                               for k, pose in enumerate(poses)])

    def _submap_poses(self, index: int, before: int, after: int) -> NDArray[np.float64]:
        """``(n, 3)`` poses of keyframes ``index - before .. index + after`` (clipped to the
        graph) in the frame of keyframe ``index``, by the graph's current poses."""
        poses = self.graph.poses
        lo, hi = max(0, index - before), min(len(self.keyframes), index + after + 1)
        return compose(inverse(poses[index])[None], poses[lo:hi])

    def _place(self, index: int, neighbours: int | None = None) -> PlaceMap:
        """The old place around keyframe ``index``: its points and its ``neighbours`` on each
        side (default ``submap_neighbours``), in its frame. Kept across optimisations while
        no point of it has moved by more than ``place_tolerance`` (:func:`largest_shift`; the
        ``max_places`` used last are kept)."""
        neighbours = self.submap_neighbours if neighbours is None else neighbours
        key = (index, neighbours)
        placed = self._submap_poses(index, neighbours, neighbours)
        kept = self._places.get(key)
        lo = max(0, index - neighbours)
        if kept is not None and len(kept[1]) == len(placed) and largest_shift(
                kept[1], placed, self._table.reach[lo:lo + len(placed)]) <= self.place_tolerance:
            self._places.move_to_end(key)
            if kept[2] != self._optimizations:  # as a map built anew would, after one
                kept[0].forget_levels()
                self._places[key] = (kept[0], kept[1], self._optimizations)
            return kept[0]
        seen = np.repeat(placed[:, :2], [len(self.keyframes[lo + k].points)
                                         for k in range(len(placed))], axis=0)
        place = PlaceMap(self._placed_points(lo, placed), self.loop_params, self._pyramid_buffer,
                         seen)
        self._places[key] = (place, placed, self._optimizations)
        self._places.move_to_end(key)
        while len(self._places) > self.max_places:
            self._places.popitem(last=False)
        return place

    @property
    def revisits(self) -> NDArray[np.bool_]:
        """``(E,)`` which graph edges are revisits: loop edges between keyframes at least
        ``min_loop_separation`` of path apart (the others are odometry or overlap edges)."""
        if not self.graph.n_edges:
            return np.zeros(0, dtype=bool)
        path = self._table.path_lengths
        edges = self.graph.edges
        return self.graph.is_loop & (path[edges[:, 1]] - path[edges[:, 0]]
                                     >= self.min_loop_separation)

    @property
    def n_loops(self) -> int:
        """Loop edges in the graph now (accepted and kept)."""
        return int(self.graph.is_loop.sum()) if self.graph.n_edges else 0

    def loop_candidates(self, index: int) -> list[tuple[int, float]]:
        """Old keyframes keyframe ``index`` may revisit or overlap, with their search window
        [m]: revisits first, then overlaps, each best place descriptor first; at most
        ``max_candidates``, one per stretch of old path."""
        current = self.keyframes[index]
        if index == 0:
            return []
        behind = current.path_length - self._table.path_lengths[:index]
        poses = self.graph.poses
        distance = np.hypot(*(poses[:index, :2] - poses[index, :2]).T)
        eligible = np.flatnonzero((behind >= self.min_overlap_separation)
                                  & (distance <= self.overlap_radius + self.loop_drift * behind))
        if len(eligible) == 0:
            return []
        similarity = descriptor_distances(current.descriptor, self._table.descriptors[eligible])
        window = np.minimum(self.loop_radius + self.loop_drift * behind, self.max_search_window)
        chosen: list[tuple[int, float]] = []
        for k in eligible[np.lexsort((similarity, behind[eligible] < self.min_loop_separation))]:
            # one candidate per stretch of old path: neighbours share a submap anyway
            if all(abs(k - other) > 2 * self.submap_neighbours for other, _ in chosen):
                chosen.append((int(k), float(window[k])))
            if len(chosen) == self.max_candidates:
                break
        return chosen

    def loop_mahalanobis(self, old: int, new: int, pose: NDArray[np.float64],
                         information: NDArray[np.float64]) -> float:
        """Mahalanobis distance of a loop measurement (keyframe ``new``'s pose (3,) in keyframe
        ``old``'s frame, ``information`` (3, 3)) from the graph's current estimate of it, under
        the covariance of the front end's error along the odometry chain from ``old`` to
        ``new`` plus the measurement's own.

        The chain's error is the front end's error model (:meth:`_odometry_error`): its noise,
        and its drift measured from its scan matches (errors correlated within one of its
        maps, :mod:`~estimators.slam.frontend_drift`), add up independently from edge to edge;
        the distance model's drift, used where the front end reports no scan matches, is
        bounded for any correlation (:func:`~estimators.slam.pose_graph.chain_covariance` with
        ``correlated=True``: a front end may err the same way all along a featureless
        stretch), so that bound grows with the distance driven. The chain ignores loop edges
        already in the graph, which only shrink the uncertainty: both err on the side of
        accepting a true loop after a long, drifting drive."""
        poses = self.graph.poses
        table = self._table
        chain = (chain_covariance(poses[old:new + 1], table.noise_covariances[old + 1:new + 1])
                 + chain_covariance(poses[old:new + 1], table.drift_covariances[old + 1:new + 1],
                                    correlated=True))
        residual = compose(inverse(pose), relative(poses[old], poses[new]))  # the graph residual
        covariance = chain + np.linalg.inv(information)
        return float(np.sqrt(residual @ np.linalg.solve(covariance, residual)))

    def _odometry_information(self, step: NDArray[np.float64]) -> NDArray[np.float64]:
        """``(3, 3)`` information of an odometry edge over ``step`` (3,) by the distance model
        (the ``odometry_*`` settings)."""
        distance = float(np.hypot(step[0], step[1]))
        sigma_xy = self.odometry_sigma + self.odometry_drift * distance
        sigma_th = self.odometry_sigma_rotation + self.odometry_drift_rotation * distance
        return np.diag([sigma_xy**-2, sigma_xy**-2, sigma_th**-2])

    def _odometry_error(self, step: NDArray[np.float64],
                        matched: NDArray[np.float64] | None = None,
                        measured: NDArray[np.float64] | None = None
                        ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The front end's error over one keyframe ``step`` (3,) as the loop gate models it:
        the covariances (3, 3) of what adds up independently from edge to edge (its noise,
        ``odometry_sigma`` and ``odometry_sigma_rotation``, plus ``measured``, the drift
        :class:`~estimators.slam.frontend_drift.FrontEndDrift` found in its scan matches over
        the step) and of its drift that may be correlated all along the chain (without
        ``measured``: ``odometry_drift``, ``odometry_drift_rotation`` times the distance).
        A front end's drift measured from its matches is tight where hundreds of returns
        pinned each scan (a depot's shelves: millimetres and hundredths of a degree per map
        keyframe, so the next aisle, one pitch over, is out of reach) and loose where a few
        posts did; the distance model allows metres and tens of degrees after 50 m anywhere.
        Where the front end flagged its match of the keyframe's scan as poor, the drift is
        ``matched`` (the edge's covariance from the two keyframes' match, see
        :meth:`_matched_information`) instead. The keyframe match alone does not bound a
        step the front end matched: where two keyframes share one post, it leaves the turn
        about the post free (a covariance of metres and radians) while the front end, which
        matched its whole map, errs by centimetres."""
        distance = float(np.hypot(step[0], step[1]))
        noise = np.diag([self.odometry_sigma**2, self.odometry_sigma**2,
                         self.odometry_sigma_rotation**2])
        if matched is not None:
            return noise, matched
        if measured is not None:
            return noise + measured, np.zeros((3, 3))
        drift = np.diag([(self.odometry_drift * distance)**2] * 2
                        + [(self.odometry_drift_rotation * distance)**2])
        return noise, drift

    def _gate(self, old: int, new: int, result: LoopVerification) -> LoopVerification:
        """``result``, rejected if the graph cannot have drifted to it (``loop_gate``)."""
        if not result.accepted:
            return result
        distance = self.loop_mahalanobis(old, new, result.pose, result.information)
        if distance <= self.loop_gate:
            return result
        return replace(result, accepted=False,
                       reason=f"unreachable from the graph's estimate: Mahalanobis distance "
                              f"{distance:.1f} > loop_gate {self.loop_gate}")

    def _close_loops(self, index: int) -> bool:
        """Verify the candidates of keyframe ``index`` (its points and, where they are few, the
        keyframes' before it: :meth:`_query`) and add the accepted ones as loop edges; return
        whether one of them is a revisit (at least ``min_loop_separation`` back)."""
        revisited = False
        poses = self.graph.poses
        for old, window in self.loop_candidates(index):
            guess = relative(poses[old], poses[index])
            result = self._gate(old, index, verify_loop(
                self._place(old), self._query(index, old), guess, window, self.loop_params,
                measure_rejected=False))
            self.loop_attempts.append((old, index, result))
            if result.accepted:
                self.graph.add_edge(old, index, result.pose, result.edge_information,
                                    is_loop=True)
                self._dirty = True
                behind = self.keyframes[index].path_length - self.keyframes[old].path_length
                revisited |= behind >= self.min_loop_separation
        return revisited

    def _close_global_loops(self, index: int) -> None:
        """Match keyframe ``index`` over all headings against look-alike old keyframes (at
        least ``min_loop_separation`` of path behind it) (:meth:`_match_globally`)."""
        current = self.keyframes[index]
        path = self._table.path_lengths[:index]
        old = np.flatnonzero(current.path_length - path >= self.min_loop_separation)
        self._match_globally(index, old, self.global_submap_keyframes)

    def _match_globally(self, index: int, old: NDArray[np.int64], query_keyframes: int,
                        last_placed: int | None = None) -> bool:
        """Match keyframe ``index`` with the ``query_keyframes`` before it over all headings
        against the look-alikes among keyframes ``old`` (K,), each with up to
        ``global_submap_keyframes`` on either side (none past ``last_placed``, the last
        keyframe the graph places relative to them, where given); add loop edges once two matches
        of different queries agree on the correction (then optimise at once, trusting them:
        the robust kernel would otherwise refuse a correction of many metres) and return
        whether they did. Two candidates of one query (neighbouring old keyframes, whose
        places share most points) are one piece of evidence: the look-alike fits both alike."""
        if len(old) == 0:
            return False
        current = self.keyframes[index]
        distance = descriptor_distances(current.descriptor, self._table.descriptors[old])
        order = np.argsort(distance, kind="stable")[: self.global_candidates]
        self._pending = [p for p in self._pending if index - p[1] <= self.global_confirmation]
        poses = self.graph.poses
        # A few keyframes of the recent path on both sides: more walls, fewer look-alikes.
        query = self._submap(index, query_keyframes, 0)
        for k in old[order][distance[order] <= self.max_descriptor_distance]:
            neighbours = (self.global_submap_keyframes if last_placed is None
                          else min(self.global_submap_keyframes, last_placed - int(k)))
            result = self._gate(int(k), index, verify_loop(
                self._place(int(k), neighbours), query, np.zeros(3),
                self.global_window, self._global_params, measure_rejected=False))
            self.loop_attempts.append((int(k), index, result))
            if not result.accepted:
                continue
            # where the match puts this keyframe, as a correction of the whole graph
            correction = compose(compose(poses[k], result.pose), inverse(poses[index]))
            for old_k, new_k, other in self._pending:
                if new_k == index:  # the same query's other candidate: the same evidence
                    continue
                predicted = relative(poses[old_k], compose(correction, poses[new_k]))
                error = relative(predicted, other.pose)
                if (np.hypot(error[0], error[1]) <= self.consistency_distance
                        and abs(error[2]) <= self.consistency_angle):
                    self.graph.add_edge(old_k, new_k, other.pose, other.edge_information, True)
                    self.graph.add_edge(int(k), index, result.pose, result.edge_information,
                                        True)
                    trusted = np.zeros(self.graph.n_edges, dtype=bool)
                    trusted[-2:] = True
                    self.optimize(trusted=trusted)
                    self._pending.clear()
                    self._last_loop = index
                    return True
            self._pending.append((int(k), index, result))
        return False

    def add_loop_closure(self, old: int, new: int, pose: NDArray[np.float64],
                         information: NDArray[np.float64]) -> None:
        """Add a loop edge by hand (keyframe ``new``'s pose in keyframe ``old``'s frame); it
        is treated like a detected one: robust kernel, dropped if irreconcilable."""
        self.graph.add_edge(old, new, pose, information, is_loop=True)
        self._dirty = True

    def _odometry_edge(self, reference: PointToLineReference | None, points: NDArray[np.float64],
                       step: NDArray[np.float64], poor: bool,
                       measured: NDArray[np.float64] | None
                       ) -> tuple[NDArray[np.float64], tuple[NDArray[np.float64],
                                                             NDArray[np.float64]]]:
        """Information (3, 3) of the odometry edge over ``step`` (3,) and the front end's error
        over it (:meth:`_odometry_error`). The distance model, plus the keyframes' match
        covariance where ``reference`` (the previous keyframe's lines) is given
        (``match_odometry``, :meth:`_matched_information`), and, where the front end measured
        its drift over the step from its scan matches (``measured``, (3, 3)) and did not flag
        the scan poor, plus the information of that error (noise plus measured drift). Both
        bound the same step's error, so the edge is at least as tight as either (and up to
        sqrt(2) tighter in sigma where they agree): two keyframes that share a few posts
        leave their match loose, but not the step the front end pinned on its whole local
        map, which a wrong loop edge must then not bend by more than the front end can have
        erred; where the front end's measure is loose (its bound over a map's span), the
        distance model keeps the edge tight."""
        information = self._odometry_information(step)
        if self.match_odometry and reference is not None:
            information = self._matched_information(reference, points, step, information)
        if measured is not None and not poor:
            error = self._odometry_error(step, measured=measured)
            return information + np.linalg.inv(error[0]), error
        return information, self._odometry_error(step, np.linalg.inv(information) if poor
                                                 else None, measured)

    def _matched_information(self, reference: PointToLineReference, points: NDArray[np.float64],
                             step: NDArray[np.float64], prior: NDArray[np.float64]
                             ) -> NDArray[np.float64]:
        """Odometry edge information that also knows the scene: the covariance of the
        distance model plus that of the keyframe-to-keyframe match Hessian at the front
        end's step, so a step along a featureless corridor (where front ends drift) is
        a weak edge in that direction and absorbs the loop corrections."""
        matched = match_information(reference, points, step, self.loop_params)
        return np.linalg.inv(np.linalg.inv(prior) + np.linalg.inv(matched))

    def _checked_step(self, reference: PointToLineReference, previous: NDArray[np.float64],
                      points: NDArray[np.float64], step: NDArray[np.float64]
                      ) -> NDArray[np.float64]:
        """The front end's step (3,) between two keyframes, or, if it leaves fewer than
        ``min_quality`` of the new keyframe's points on the previous one's walls, the step
        found by matching the two keyframes over all headings when that match is accepted
        and explains more. A front end can lose a fast turn (tens of degrees of a corner in a
        second or two); left in the edge, the loop closures cannot localise the error and
        spread it over tens of metres of corridor, bending them into arcs. A match farther
        from the step than ``ambiguity_distance`` or ``angular_window`` is another place, not
        a refinement: it must put at least :data:`~estimators.slam.loop_closure.MIN_POINTS`
        points on the walls, and the step must explain less than ``ambiguity_ratio`` of its
        share (where a scan sees a few posts, the all-heading match often puts a few more
        points on them turned by 90 or 180 degrees than the right step does). The match
        replaces the step only where the step lies more than ``loop_gate`` Mahalanobis
        distances from it, under the match's covariance plus the front end's error model
        (:meth:`_odometry_error`): a lost turn is many sigmas off, while a step the match
        merely disagrees with within their uncertainties (along a corridor, or where walkers
        hide the walls both scans share) was matched against the front end's whole local
        map and is the better of the two."""
        world = transform_points(step, points)
        share = len(reference.correspond(world, self.loop_params.inlier_distance).index)
        share /= len(points)
        if share >= self.loop_params.min_quality:
            return step
        place = PlaceMap(previous, self.loop_params, self._pyramid_buffer)
        result = verify_loop(place, points, step, self.keyframe_distance, self._step_params,
                             measure_rejected=False)
        self.step_checks.append((len(self.keyframes), share, result))
        params, change = self.loop_params, relative(step, result.pose)
        near = (np.hypot(change[0], change[1]) < params.ambiguity_distance
                and abs(change[2]) < params.angular_window)
        clear = near or (result.quality * len(points) >= MIN_POINTS
                         and share < params.ambiguity_ratio * result.quality)
        if not (result.accepted and result.quality > share and clear):
            return step
        noise, drift = self._odometry_error(step)
        covariance = noise + drift + np.linalg.inv(result.edge_information)
        lost = float(np.sqrt(change @ np.linalg.solve(covariance, change))) > self.loop_gate
        return result.pose if lost else step
