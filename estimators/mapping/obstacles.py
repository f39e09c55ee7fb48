"""Obstacles from single scans: range breakpoints, clusters, round obstacles.

Detection (:func:`detect_obstacles`): the returns of a scan are cut into clusters where two
angular neighbours are farther apart than the adaptive breakpoint distance of Borges & Aldon
("Line extraction in 2D range images for mobile robotics", J. Intell. Robot. Syst. 2004)::

    D_max = r_prev * sin(dphi) / sin(lambda - dphi) + 3 sigma_r

i.e. the gap a surface seen at the grazing angle ``lambda`` would leave between two beams
``dphi`` apart, plus three range-noise sigmas. Each cluster is reported in the world frame at
the (estimated) sensor pose with its centroid and extent (along and across its principal axis);
a cluster that an algebraic circle fit (Kåsa, "A circle fitting procedure and its error
analysis", IEEE Trans. Instrum. Meas. 1976) explains to within the range noise, better than two
line segments would (a corner), convex towards the sensor and no larger than ``max_radius``, is
a round obstacle with a centre and a radius. A cluster that is not round as a whole may hold
one: a cylinder touching a wall joins the wall's cluster, as the wall meets its arc without a
range jump. The detector cuts out of it the longest run of returns that a circle of at most
``max_radius`` explains to within two range sigmas while a line does not (found in one pass with
prefix sums of the moments), less the end returns that lie within noise of the line of the rest
of the cluster on that side (a wall is tangent to the cylinder it touches), and keeps the cut if
the run passes the roundness test above; the rest is searched again. The per-cluster fits are
compiled (numba): detection and tracking together cost ~0.9 ms per step of two 360-beam scans
in ``open_cylinders`` (CPU time, ``benchmarks/bench_mapping.py``).

Tracking across steps is :mod:`estimators.mapping.tracking`; the compiled fits are
:mod:`estimators.mapping.circle_fit`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimators.base import SensorSetup
from estimators.mapping.circle_fit import (
    AXIS,
    CORNER_RMS,
    CX,
    CY,
    FIT_R,
    FIT_RMS,
    FIT_X,
    FIT_Y,
    LENGTH,
    SPREAD,
    WIDTH,
    CircleFit,
    cluster_statistics,
    longest_arc,
)
from estimators.mapping.occupancy import sensor_poses
from lidar_env.core import ConfigError, EstimatorInputError
from lidar_env.core.se2 import transform_points


@dataclass(frozen=True)
class Obstacle:
    """One cluster of returns, in the world frame.

    Attributes:
        points: ``(m, 2)`` world positions [m] of the returns, in scan order.
        beams: ``(m,)`` indices of the beams (into the scan) that produced them.
        centroid: ``(2,)`` [m] mean of ``points``.
        extent: ``(length, width)`` [m] spread of the points along and across their principal
            axis.
        axis_angle: [rad] world direction of the principal axis.
        circle: the fitted circle if the cluster is round, else ``None``.
        circle_tested: whether the cluster had enough returns to be tested for roundness.
        spread: [m] largest distance of a point from the centroid.
    """

    points: NDArray[np.float64]
    beams: NDArray[np.int64]
    centroid: NDArray[np.float64]
    extent: NDArray[np.float64]
    axis_angle: float
    circle: CircleFit | None
    circle_tested: bool
    spread: float

    @property
    def position(self) -> NDArray[np.float64]:
        """``(2,)`` [m]: the circle centre of a round obstacle, else the centroid."""
        return self.circle.centre if self.circle is not None else self.centroid


def placed(obstacle: Obstacle, car_pose: ArrayLike) -> Obstacle:
    """``obstacle``, detected in the car frame (car pose ``(0, 0, 0)``), in the world frame of
    car pose ``car_pose`` (3,): its points, centroid, principal axis and circle centre moved
    rigidly. The detector is equivariant under rigid moves, so this is what detecting at
    ``car_pose`` finds, to rounding: one detection serves every estimate of a run's poses."""
    pose = np.asarray(car_pose, dtype=np.float64)
    cos, sin = math.cos(pose[2]), math.sin(pose[2])
    circle = obstacle.circle
    if circle is not None:
        circle = CircleFit(pose[0] + cos * circle.cx - sin * circle.cy,
                           pose[1] + sin * circle.cx + cos * circle.cy, circle.radius,
                           circle.rms)
    axis = (obstacle.axis_angle + pose[2] + 0.5 * math.pi) % math.pi - 0.5 * math.pi
    return Obstacle(transform_points(pose, obstacle.points), obstacle.beams,
                    transform_points(pose, obstacle.centroid[None])[0], obstacle.extent,
                    float(axis), circle, obstacle.circle_tested, obstacle.spread)


@dataclass(frozen=True)
class DetectorParams:
    """Parameters of :func:`detect_obstacles`, with the reasons for their defaults.

    Attributes:
        range_sigma: [m] 1-sigma range noise of the Lidar (0.01: a typical time-of-flight
            planar Lidar, and the env's default noise); set it to your sensor's.
        grazing_angle: [rad] ``lambda`` of the breakpoint detector: a surface seen at a shallower
            angle than this is split (10 degrees, Borges & Aldon's value).
        min_points: returns a cluster needs to be reported (3: fewer cannot show an extent).
        min_circle_points: returns a circle fit needs to be trusted (5: two more than the three
            that always fit a circle exactly, so the fit residual means something).
        max_radius: [m] largest round obstacle (1.0: posts, pillars, trees, people, barrels;
            larger curved things are mapped as extended obstacles).
        max_circle_rms: [m] largest rms residual of a round cluster, in units of
            ``range_sigma`` (3: generous for noise, far below the misfit of a corner).
    """

    range_sigma: float = 0.01
    grazing_angle: float = math.radians(10.0)
    min_points: int = 3
    min_circle_points: int = 5
    max_radius: float = 1.0
    max_circle_rms: float = 3.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.range_sigma) and self.range_sigma >= 0):
            raise ConfigError(f"range_sigma: expected a number >= 0 [m], got {self.range_sigma!r}")
        if not 0.0 < self.grazing_angle < math.pi / 2:
            raise ConfigError(f"grazing_angle: expected an angle in (0, pi/2) [rad], "
                             f"got {self.grazing_angle!r}")
        if self.min_points < 1 or self.min_circle_points < 4:
            raise ConfigError(f"expected min_points >= 1 and min_circle_points >= 4, got "
                             f"{self.min_points} and {self.min_circle_points}")
        if not (self.max_radius > 0 and self.max_circle_rms > 0):
            raise ConfigError(f"expected max_radius > 0 and max_circle_rms > 0, got "
                             f"{self.max_radius} and {self.max_circle_rms}")


def split_scan(
    ranges: ArrayLike, beam_angles: ArrayLike, max_range: float, params: DetectorParams
) -> list[NDArray[np.int64]]:
    """Clusters of one scan as arrays of beam indices, each ordered by angle.

    Beams reading ``>= max_range`` (no return) separate clusters; so does a gap between two
    angular neighbours wider than the adaptive breakpoint distance ``D_max`` (module doc). When
    the beams cover the full circle, the clusters at both ends of the angle order are joined if
    they touch across 0 rad."""
    ranges = np.asarray(ranges, dtype=np.float64)
    angles = np.asarray(beam_angles, dtype=np.float64)
    if angles.ndim != 1 or ranges.shape != angles.shape:
        raise EstimatorInputError(f"ranges: expected shape {angles.shape} like beam_angles, "
                         f"got {ranges.shape}")
    order = np.argsort(np.mod(angles, 2 * np.pi), kind="stable")
    r = ranges[order]
    phi = np.mod(angles[order], 2 * np.pi)
    valid = r < max_range
    n = len(r)
    # gap between each beam and its predecessor (circularly): beam 0's predecessor is beam n-1
    step = np.mod(phi - np.roll(phi, 1), 2 * np.pi)
    x, y = r * np.cos(phi), r * np.sin(phi)
    gap = np.hypot(x - np.roll(x, 1), y - np.roll(y, 1))
    lam = params.grazing_angle
    limit = np.roll(r, 1) * np.sin(step) / np.sin(np.maximum(lam - step, 1e-12))
    limit = np.where(step < lam, limit, 0.0) + 3.0 * params.range_sigma
    joined = valid & np.roll(valid, 1) & (gap <= limit)  # beam i continues beam i-1's cluster
    starts = np.flatnonzero(valid & ~joined)
    if len(starts) == 0:
        # no start: either nothing returned, or one closed ring of returns around the sensor
        return [order[valid]] if np.all(valid) and n > 0 else []
    clusters = []
    for begin, end in zip(starts, np.append(starts[1:], starts[0] + n), strict=True):
        members = np.arange(begin, end) % n
        members = members[valid[members]]
        clusters.append(members)
    return [order[c] for c in clusters]


def _round_clusters(
    statistics: NDArray[np.float64], sizes: NDArray[np.int64],
    sensor_position: NDArray[np.float64], params: DetectorParams,
) -> NDArray[np.bool_]:
    """Which clusters (rows of :func:`cluster_statistics`, ``sizes`` points each) are round
    obstacles seen from ``sensor_position`` (2,) [m] (module doc)."""
    fit_rms = statistics[:, FIT_RMS]
    centre_range = np.hypot(statistics[:, FIT_X] - sensor_position[0],
                            statistics[:, FIT_Y] - sensor_position[1])
    centroid_range = np.hypot(statistics[:, CX] - sensor_position[0],
                              statistics[:, CY] - sensor_position[1])
    return (
        (sizes >= params.min_circle_points)
        & (statistics[:, FIT_R] <= params.max_radius)  # NaN (no circle) compares False
        & (fit_rms <= params.max_circle_rms * max(params.range_sigma, 1e-6))
        # convex towards the sensor: the centre lies beyond the arc, not in front of it
        & (centre_range > centroid_range)
        # a circle with fewer degrees of freedom (3) than two lines (4) must still fit better:
        # the convex corner of a box or of two walls is not a cylinder
        & (fit_rms < statistics[:, CORNER_RMS])
    )


def _trim_against_lines(
    points: NDArray[np.float64], begin: int, arc_begin: int, arc_end: int, end: int,
    min_points: int, tolerance: float,
) -> tuple[int, int]:
    """Shrink the arc ``points[arc_begin:arc_end]`` cut out of the cluster
    ``points[begin:end]``: drop from each of its ends the points that lie within ``tolerance``
    [m] of the line fitted to the rest of the cluster on that side (if it has ``min_points``).
    Where a wall touches a cylinder it is tangent to it, so the wall's first returns past the
    contact are within noise of the circle too, and would pull its centre towards the wall."""
    for side_begin, side_end, step in ((begin, arc_begin, 1), (arc_end, end, -1)):
        if side_end - side_begin < max(min_points, 2):
            continue
        side = points[side_begin:side_end]
        centre = side.mean(axis=0)
        normal = np.linalg.svd(side - centre, full_matrices=False)[2][1]
        while arc_end - arc_begin > 0:
            index = arc_begin if step == 1 else arc_end - 1
            if abs(float((points[index] - centre) @ normal)) > tolerance:
                break
            if step == 1:
                arc_begin += 1
            else:
                arc_end -= 1
    return arc_begin, arc_end


def _cut_out_arcs(
    points: NDArray[np.float64], begins: NDArray[np.int64], ends: NDArray[np.int64],
    sensor_position: NDArray[np.float64], params: DetectorParams,
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64], NDArray[np.bool_]]:
    """The clusters ``points[begins[c]:ends[c]]`` after cutting a round arc out of each one
    that is not round as a whole (a cylinder touching a wall is one cluster with the wall),
    until none is left to cut; pieces of fewer than ``params.min_points`` are dropped. Returns
    the new ``begins, ends``, their statistics and roundness."""
    # the arc is searched for within 2 sigma rms (pure noise exceeds it with a chance < 1e-4 at
    # 5 points), not the acceptance limit, so the wall points next to the contact, which the
    # circle misses by a little more than the noise, are left out of it
    tolerance = 2.0 * max(params.range_sigma, 1e-6)
    searched = np.zeros(len(begins), dtype=bool)
    while True:
        statistics = cluster_statistics(points, begins, ends)
        round_ = _round_clusters(statistics, ends - begins, sensor_position, params)
        todo = np.flatnonzero(~round_ & ~searched & (ends - begins > params.min_circle_points))
        searched[todo] = True
        cuts = {}
        for k in todo:
            begin, end = longest_arc(points[begins[k]:ends[k]], params.min_circle_points,
                                      params.max_radius, tolerance)
            if begin < 0:
                continue
            arc = _trim_against_lines(points, begins[k], begins[k] + begin, begins[k] + end,
                                      ends[k], params.min_points, tolerance)
            if arc[1] - arc[0] >= params.min_circle_points:
                cuts[k] = arc
        if cuts:  # keep only the arcs that pass the full roundness test
            arcs = np.array(list(cuts.values()), dtype=np.int64).reshape(-1, 2)
            arc_round = _round_clusters(cluster_statistics(points, arcs[:, 0], arcs[:, 1]),
                                        arcs[:, 1] - arcs[:, 0], sensor_position, params)
            cuts = {k: cut for (k, cut), keep in zip(cuts.items(), arc_round, strict=True)
                    if keep}
        if not cuts:
            return begins, ends, statistics, round_
        pieces = []  # (begin, end, searched)
        for k, (begin, end) in enumerate(zip(begins, ends, strict=True)):
            if k not in cuts:
                pieces.append((begin, end, searched[k]))
                continue
            arc_begin, arc_end = cuts[k]
            pieces += [(begin, arc_begin, False), (arc_begin, arc_end, True),
                       (arc_end, end, False)]
        pieces = [p for p in pieces if p[1] - p[0] >= params.min_points]
        begins = np.array([p[0] for p in pieces], dtype=np.int64)
        ends = np.array([p[1] for p in pieces], dtype=np.int64)
        searched = np.array([p[2] for p in pieces], dtype=bool)


def detect_obstacles(
    ranges: ArrayLike,
    beam_angles: ArrayLike,
    sensor_pose: ArrayLike,
    max_range: float,
    params: DetectorParams | None = None,
) -> list[Obstacle]:
    """The obstacles in one scan ``ranges`` (n,) [m] taken at world ``sensor_pose`` (3,), beam
    ``i`` at ``beam_angles[i]`` [rad] CCW from the sensor's forward axis, in the world frame."""
    params = DetectorParams() if params is None else params
    pose = np.asarray(sensor_pose, dtype=np.float64)
    if pose.shape != (3,) or not np.all(np.isfinite(pose)):
        raise EstimatorInputError(
            f"sensor_pose: expected 3 finite numbers (x, y, heading), got {pose}")
    ranges = np.asarray(ranges, dtype=np.float64)
    angles = np.asarray(beam_angles, dtype=np.float64)
    clusters = [c for c in split_scan(ranges, angles, max_range, params)
                if len(c) >= params.min_points]
    if not clusters:
        return []
    beams = np.concatenate(clusters)
    local = np.column_stack([ranges[beams] * np.cos(angles[beams]),
                             ranges[beams] * np.sin(angles[beams])])
    points = transform_points(pose, local)
    ends = np.cumsum([len(c) for c in clusters]).astype(np.int64)
    begins = ends - np.array([len(c) for c in clusters], dtype=np.int64)
    begins, ends, statistics, round_ = _cut_out_arcs(points, begins, ends, pose[:2], params)
    obstacles = []
    for begin, end, row, is_round in zip(begins, ends, statistics, round_, strict=True):
        circle = CircleFit(*(float(v) for v in row[FIT_X:FIT_RMS + 1])) if is_round else None
        obstacles.append(Obstacle(
            points[begin:end], beams[begin:end], row[CX:CY + 1].copy(),
            row[LENGTH:WIDTH + 1].copy(), float(row[AXIS]), circle,
            circle_tested=bool(end - begin >= params.min_circle_points),
            spread=float(row[SPREAD]),
        ))
    return obstacles


def detect_in_observation(
    observation: Mapping[str, ArrayLike],
    car_pose: ArrayLike,
    setup: SensorSetup,
    params: DetectorParams | None = None,
) -> list[Obstacle]:
    """The obstacles in every scan of one env observation (keyed by ``setup.keys``) taken at
    the (estimated) car pose ``car_pose`` (3,), each Lidar at car pose ⊕ its mount."""
    return [obstacle for found in detect_per_lidar(observation, car_pose, setup, params).values()
            for obstacle in found]


def detect_per_lidar(
    observation: Mapping[str, ArrayLike],
    car_pose: ArrayLike,
    setup: SensorSetup,
    params: DetectorParams | None = None,
) -> dict[str, list[Obstacle]]:
    """:func:`detect_in_observation`, the obstacles of each Lidar's scan by its key."""
    scans = setup.check_observation(observation)
    return {key: detect_obstacles(scans[key], sensor.beam_angles, pose, sensor.max_range, params)
            for key, sensor, pose in zip(setup.keys, setup.sensors,
                                         sensor_poses(car_pose, setup)[0], strict=True)}
