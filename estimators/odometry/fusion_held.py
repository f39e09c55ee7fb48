"""The keyframe scans of ``pc_fusion`` (:class:`~estimators.odometry.fusion.FusionEstimator`)
with the beams they lack filled from the last few scans.

A keyframe is the reference that every scan until the next one is refined onto, along the
curves its returns chain into (:class:`~estimators.matching.curve_refinement.CurveReference`:
a return links to the next beam's when they lie within a few decimetres). With beams lost at
random (a dirty window, dark or glancing surfaces), half of a keyframe's beams are missing:
a third of its returns stand alone, without a curve, and the refinement slides along what
is left. Each Lidar's returns of the last ``max_age`` scans are kept with the car's
estimated pose, and a keyframe's beam without a return takes the return of the latest of
those scans that falls into it (the nearest one of that scan, as a beam sees the nearest
surface), seen from where the Lidar is now: with half the beams lost at random, all but
1 in 2^8 of them return within 8 scans, a few centimetres away. A beam that returns keeps its
own return. A filled beam keeps the bearing of its point, so the scan's image and curves see
it where the world holds it. A keyframe made with fewer scans before it (the first one, or
the first after the car lost its place) is filled from the scans after it too. A keyframe
takes its filled beams only where they make up :data:`LOST_SHARE` of its returns: beams that
turn into the open as the car moves leave it as measured. Scans age by the scans that came
(skipped ones counted), not by the clock: each loses its beams on its own.

Poses [m, m, rad] are in the trajectory frame; ranges [m] and bearings [rad] in each Lidar's
frame.
"""

from __future__ import annotations

from collections import deque

import numpy as np
from numpy.typing import NDArray

from estimators.matching.curve_refinement import covers_full_turn
from estimators.matching.held_returns import MAX_AGE, check_max_age
from estimators.matching.rotation_pc import PreparedScan, ScanMatcher
from estimators.matching.scan_matching import DEFAULT_MIN_RANGE
from lidar_env.core.se2 import PoseFloats, compose_floats, inverse_floats, transform_points

FloatArray = NDArray[np.float64]

#: Share of a keyframe scan's beams with a return after filling that must come from the held
#: scans for the keyframe to take them: a Lidar losing beams at random (half of them: ~0.5)
#: rather than beams turning into the open as the car moves (on the real logs and simulated
#: drives 0-0.19 of a keyframe's beams, 0.01 in the median), which leaves its keyframes
#: as measured.
LOST_SHARE = 0.25


class BeamLookup:
    """The beam of a Lidar whose direction is nearest a bearing: ``beam_angles`` (n,) [rad]
    increasing in beam order, about evenly spaced (a beam covers half the spacing on each
    side; a Lidar covering a full turn wraps around)."""

    def __init__(self, beam_angles: FloatArray) -> None:
        self._first = float(beam_angles[0])
        grid = beam_angles - self._first
        self._half = 0.5 * float(np.median(np.diff(beam_angles))) if len(grid) > 1 else 0.0
        self._n = len(grid)
        # the first beam again a full turn on, when the beams cover one
        self._grid = np.append(grid, 2.0 * np.pi) if covers_full_turn(beam_angles) else grid

    def __call__(self, bearings: FloatArray) -> tuple[NDArray[np.intp], FloatArray]:
        """Each bearing's (K,) [rad] beam (-1: none covers it) and its offset [rad] from the
        beam's direction."""
        relative = np.remainder(bearings - self._first, 2.0 * np.pi)
        above = np.minimum(np.searchsorted(self._grid, relative), len(self._grid) - 1)
        below = np.maximum(above - 1, 0)
        nearer = np.where(relative - self._grid[below] <= self._grid[above] - relative,
                          below, above)
        offset = relative - self._grid[nearer]
        index = np.where(np.abs(offset) <= self._half, nearer % self._n, -1)
        return index, offset


def returned(scan: PreparedScan) -> NDArray[np.bool_]:
    """Which beams (n,) of ``scan`` returned (the test :class:`ScanMatcher` prepares with)."""
    return (scan.ranges < scan.max_range) & (scan.ranges > DEFAULT_MIN_RANGE)


def returns(scan: PreparedScan) -> FloatArray:
    """The returns (M, 2) [m] of ``scan`` in its Lidar's frame, in beam order."""
    if scan.reference is not None:  # made of them
        return scan.reference.points
    hit = returned(scan)
    return np.column_stack([scan.ranges[hit] * np.cos(scan.beam_angles[hit]),
                            scan.ranges[hit] * np.sin(scan.beam_angles[hit])])


class HeldKeyframeScans:
    """The returns of the last ``max_age`` scans (``0``: none) of Lidars at ``mounts``
    (K, 3) with ``beam_angles`` (one (n,) array per Lidar), and the keyframe scans they fill
    (prepared by ``matcher``)."""

    def __init__(self, mounts: FloatArray, beam_angles: list[FloatArray], matcher: ScanMatcher,
                 max_age: int = MAX_AGE) -> None:
        self.max_age = check_max_age(max_age)
        self._matcher = matcher
        self._mounts = [tuple(mount) for mount in np.asarray(mounts, dtype=np.float64).tolist()]
        self._beams_of = [BeamLookup(np.asarray(angles, dtype=np.float64))
                          for angles in beam_angles]
        #: per scan: its age [scan intervals], the car pose, each Lidar's returns (M, 2) [m]
        self._scans: deque[tuple[float, PoseFloats, list[FloatArray]]] = deque()
        #: the latest keyframe's scans as measured, and the held scans it is filled from
        self._measured: tuple[PreparedScan, ...] = ()
        self._sources: list[tuple[float, PoseFloats, list[FloatArray]]] = []

    def hold(self, scans: tuple[PreparedScan, ...], pose: PoseFloats,
             scans_since: float) -> None:
        """Keep ``scans`` (one per Lidar) taken at car ``pose``, ``scans_since`` scan
        intervals after the last ones (those further back than ``max_age`` go)."""
        if not self.max_age:
            return
        aged = [(age + scans_since, *rest) for age, *rest in self._scans]
        self._scans = deque(entry for entry in aged if entry[0] <= self.max_age)
        self._scans.append((0.0, pose, [returns(scan) for scan in scans]))

    def restart(self, scans: tuple[PreparedScan, ...], pose: PoseFloats) -> None:
        """Drop every scan kept and keep ``scans`` at car ``pose`` alone (the start, or the car
        lost its place: the poses of the scans before say nothing now)."""
        self._scans.clear()
        self._measured, self._sources = (), []
        self.hold(scans, pose, 0.0)

    def keyframe(self, scans: tuple[PreparedScan, ...], pose: PoseFloats
                 ) -> tuple[PreparedScan, ...]:
        """``scans`` (prepared, one per Lidar, the latest held), a new keyframe at car
        ``pose``, each filled from the scans kept before them (:meth:`_filled`)."""
        self._measured = scans
        self._sources = list(self._scans)[-2::-1]  # newest first, without the latest
        return self._filled(pose)

    def refill(self, keyframe: tuple[PreparedScan, ...], pose: PoseFloats
               ) -> tuple[PreparedScan, ...]:
        """The latest ``keyframe`` (its scans, at car ``pose``) filled from the latest scan
        held too, while it is filled from fewer than ``max_age`` scans (one made with few
        scans before it: the first, or the first after the car lost its place)."""
        if not self._measured:  # the first keyframe, or the first after restart()
            self._measured = keyframe
        if len(self._sources) >= self.max_age or len(self._scans) < 2:
            return keyframe
        self._sources.append(self._scans[-1])
        return self._filled(pose)

    def _filled(self, pose: PoseFloats) -> tuple[PreparedScan, ...]:
        """The latest keyframe's measured scans at car ``pose``, each whose Lidar lost at
        least :data:`LOST_SHARE` of its beams with each beam without a return given the
        nearest return of the first of the held scans it is filled from that has one in it,
        prepared again."""
        filled = []
        for k, scan in enumerate(self._measured):
            hit = returned(scan)
            # too few beams without a return to reach LOST_SHARE, however many are filled
            if not self._sources or np.count_nonzero(~hit) < LOST_SHARE * len(hit):
                filled.append(scan)
                continue
            to_sensor = inverse_floats(compose_floats(pose, self._mounts[k]))
            local = np.concatenate([transform_points(
                compose_floats(to_sensor, compose_floats(held_pose, self._mounts[k])), points[k])
                for _, held_pose, points in self._sources])
            source = np.concatenate([np.full(len(points[k]), rank)
                                     for rank, (_, _, points) in enumerate(self._sources)])
            distance = np.hypot(local[:, 0], local[:, 1])
            index, offset = self._beams_of[k](np.arctan2(local[:, 1], local[:, 0]))
            usable = np.flatnonzero((index >= 0) & ~hit[np.maximum(index, 0)]
                                    & (distance < scan.max_range)
                                    & (distance > DEFAULT_MIN_RANGE))
            # per beam, the first source's nearest point, as the beam would see it
            usable = usable[np.lexsort((distance[usable], source[usable], index[usable]))]
            usable = usable[np.diff(index[usable], prepend=-1) != 0]
            if len(usable) < LOST_SHARE * (np.count_nonzero(hit) + len(usable)):
                filled.append(scan)
                continue
            ranges, angles = scan.ranges.copy(), scan.beam_angles.copy()
            ranges[index[usable]] = distance[usable]
            angles[index[usable]] += offset[usable]
            filled.append(self._matcher.prepare(ranges, angles))
        return tuple(filled)
