"""The keyframe window of ``pc_fusion`` (:class:`~estimators.odometry.fusion.FusionEstimator`):
its keyframes, the four same- and cross-sensor matches of new scans against one, and the
window re-solved on SE(2) when a keyframe joins (:class:`KeyframeMatching`, a mixin). Car poses
[m, m, rad] in the trajectory frame; a match ``z_ij`` is the pose of sensor ``j`` at ``t`` in
the frame of sensor ``i`` at ``t-1``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from estimators.base import SensorSetup
from estimators.matching.curve_refinement import PRIOR_INFORMATION
from estimators.matching.rotation_pc import PreparedScan, ScanMatcher, refinement_starts
from estimators.odometry.sensor_graph import SensorEdge, optimize_poses
from lidar_env.core.se2 import PoseFloats, compose_floats, relative_floats

FloatArray = NDArray[np.float64]


@dataclass
class Keyframe:
    """A car pose [m, m, rad] in the trajectory frame and its scans prepared for matching."""

    pose: FloatArray
    scans: tuple[PreparedScan, ...]


class KeyframeMatching:
    """The keyframe window of :class:`~estimators.odometry.fusion.FusionEstimator`, a mixin:
    it reads the estimator's settings (``window``, the sigmas through ``_weights``) and state
    (``setup``, ``_matcher``, the mounts made once per reset)."""

    window: int
    setup: SensorSetup | None
    _matcher: ScanMatcher | None
    _mounts: FloatArray
    _mount_inverses: FloatArray
    _mount_floats: list[PoseFloats]
    _mount_inverse_floats: list[PoseFloats]
    _main_mount_inverse: PoseFloats
    _keyframes: list[Keyframe]
    _edges: list[tuple[int, int, SensorEdge]]
    _n_keyframes: int
    _weights: Callable[[], dict[str, float]]  # optimize_poses's sigmas and robust scale

    def _add_keyframe(self, keyframe: Keyframe) -> None:
        self._keyframes.append(keyframe)
        self._n_keyframes += 1
        if len(self._keyframes) > self.window:
            self._keyframes.pop(0)
        first = self._n_keyframes - len(self._keyframes)
        self._edges = [(a, b, e) for a, b, e in self._edges if a >= first]

    def _restart_window(self, keyframe: Keyframe) -> None:
        """Start the window again from ``keyframe`` alone: no match ties it to the older
        keyframes (the car lost its place while blind), so none may pull it."""
        self._keyframes.clear()
        self._edges.clear()
        self._add_keyframe(keyframe)

    def _match_all(
        self,
        keyframe: Keyframe,
        scans: tuple[PreparedScan, ...],
        motion_guess: Sequence[float],
        seed: Sequence[float] | None = None,
        prior_information: FloatArray = PRIOR_INFORMATION,
    ) -> list[SensorEdge]:
        """The matches of ``scans`` against ``keyframe`` (nodes 0 and 1) by refinement.
        ``motion_guess``: predicted car motion between them, which each match gets as its prior
        ``mount_i⁻¹ ⊕ guess ⊕ mount_j`` (held about the car's centre, with
        ``prior_information``, see :func:`estimators.matching.rotation_pc.refine_on_curves`).

        ``seed``: the car motion the main Lidar's phase correlation found (the correlation's
        FFTs are the dearest part of a match; one finds the basin for all); then the main
        pair is refined from it, and the other same- and cross-sensor pairs from that.
        Without, every pair starts from the guess and only the same-sensor pairs are matched
        (these are the extra edges to older keyframes, where the cross pairs would add cost,
        not coverage). A refinement also starts from the prior where that disagrees with its
        first start.
        """
        assert self._matcher is not None and self.setup is not None
        mounts, mount_inverses = self._mount_floats, self._mount_inverse_floats
        sensors = range(len(scans))
        # guess ⊕ mount_j per target sensor j, shared by the pairs onto it
        guess_at = [compose_floats(motion_guess, mount) for mount in mounts]
        start_at = guess_at if seed is None else [compose_floats(seed, mount) for mount in mounts]
        edges = []
        for i, j in [(i, j) for i in sensors for j in sensors if seed is not None or i == j]:
            # relative(mount_i, guess ⊕ mount_j), the mount's inverse made once
            prior = np.array(compose_floats(mount_inverses[i], guess_at[j]))
            start = prior if start_at is guess_at else np.array(
                compose_floats(mount_inverses[i], start_at[j]))
            match = self._matcher.refine(
                keyframe.scans[i],
                scans[j],
                refinement_starts(start, prior),
                prior,
                self._mount_inverses[j][:2],
                prior_information,
            )
            edges.append(SensorEdge(0, i, 1, j, match.pose, match.confidence))
            if seed is not None and i == j == 0:
                # The main pair, refined, is a closer start for the others than the correlation.
                start_motion = self._motion_from_sensor_match(match.pose)
                start_at = [compose_floats(start_motion, mount) for mount in mounts]
        return edges


    def _motion_from_sensor_match(self, sensor_motion: FloatArray) -> PoseFloats:
        """:func:`estimators.matching.rotation_pc.motion_from_sensor_match` of the main Lidar,
        on floats: the car motion ``mount ⊕ z ⊕ mount⁻¹`` from its match ``z``."""
        return compose_floats(compose_floats(self._mount_floats[0], sensor_motion.tolist()),
                              self._main_mount_inverse)


    def _insert_keyframe(
        self, scans: tuple[PreparedScan, ...], pose: FloatArray, latest_edges: list[SensorEdge],
        reference: tuple[PreparedScan, ...],
    ) -> FloatArray:
        """Make ``scans`` a keyframe with ``reference``, the scans later ones are matched
        onto (``scans`` with held returns, :mod:`estimators.odometry.fusion_held`); match
        ``scans`` to the older keyframes that stay in the window and re-solve the window;
        return its solved pose."""
        assert self.setup is not None
        new_id = self._n_keyframes
        # The oldest keyframe leaves a full window now: matching against it would be wasted.
        leaving = max(len(self._keyframes) + 1 - self.window, 0)
        first_staying = new_id - len(self._keyframes) + leaving
        self._edges.extend((new_id - 1, new_id, e) for e in latest_edges)
        older = self._keyframes[leaving:-1]
        for offset, keyframe in enumerate(older):
            guess = relative_floats(keyframe.pose.tolist(), pose.tolist())
            ids = (first_staying + offset, new_id)
            self._edges.extend((*ids, e) for e in self._match_all(keyframe, scans, guess))
        self._add_keyframe(Keyframe(pose, reference))
        if older:
            # Without older edges, the window's graph is the four edges just fused: nothing to
            # re-solve.
            first = self._n_keyframes - len(self._keyframes)
            graph = [
                SensorEdge(
                    a - first, e.source_sensor, b - first, e.target_sensor, e.pose, e.confidence
                )
                for a, b, e in self._edges
            ]
            start = np.array([k.pose for k in self._keyframes])
            solved = optimize_poses(start, self.setup.mounts, graph, n_fixed=1, **self._weights())
            for keyframe, solved_pose in zip(self._keyframes, solved, strict=True):
                keyframe.pose = solved_pose
        return self._keyframes[-1].pose.copy()

