"""Obstacles from single scans, and a tracker that keeps one id per static obstacle.

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
a round obstacle with a centre and a radius.

Tracking (:class:`ObstacleTracker`): nearest-neighbour association with a gate. A detection
joins the track whose position (circle centre for round obstacles, else centroid) is nearest,
if it lies within ``gate`` [m], or, if it is extended, the track whose latest returns come
within ``surface_gate`` [m] of its own (a wall's centroid moves with the car, its surface does
not); several detections may join one track in one step, which is how the same obstacle seen
by both Lidars gets one id. The gate must exceed how far a static
obstacle's reported position moves between steps (pose-estimate drift per step, and for a round
obstacle the jump from arc centroid to fitted centre, at most its radius) and stay below the
distance between distinct obstacles. A round track's circle is the joint Kåsa fit of every point
it was given, so its centre sharpens as the arc is seen from more sides.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from estimators.base import SensorSetup
from estimators.occupancy import sensor_poses
from lidar_env.se2 import transform_points


@dataclass(frozen=True)
class CircleFit:
    """An algebraic circle fit: centre ``(cx, cy)`` [m], ``radius`` [m], and ``rms`` [m] of the
    geometric residuals ``|p - c| - r`` of the points it was fitted to."""

    cx: float
    cy: float
    radius: float
    rms: float

    @property
    def centre(self) -> NDArray[np.float64]:
        return np.array([self.cx, self.cy])


def kasa_normal_equations(points: NDArray[np.float64]) -> tuple[NDArray, NDArray]:
    """The normal equations ``(A^T A (3, 3), A^T b (3,))`` of Kåsa's linear least squares
    ``x^2 + y^2 + D x + E y + F = 0`` over ``points`` (N, 2); sums of them fit several point
    sets jointly."""
    design = np.column_stack([points, np.ones(len(points))])
    target = -np.sum(points * points, axis=1)
    return design.T @ design, design.T @ target


def solve_kasa(
    normal: NDArray[np.float64], rhs: NDArray[np.float64], points: NDArray[np.float64]
) -> CircleFit | None:
    """The circle of Kåsa's normal equations; ``None`` when they are singular (collinear or
    too few points). ``rms`` is measured on ``points``."""
    try:
        d, e, f = np.linalg.solve(normal, rhs)
    except np.linalg.LinAlgError:
        return None
    cx, cy = -d / 2.0, -e / 2.0
    radius_squared = cx * cx + cy * cy - f
    if not np.isfinite(radius_squared) or radius_squared <= 0.0:
        return None
    radius = math.sqrt(radius_squared)
    residuals = np.hypot(points[:, 0] - cx, points[:, 1] - cy) - radius
    return CircleFit(float(cx), float(cy), radius, float(np.sqrt(np.mean(residuals**2))))


def fit_circle(points: ArrayLike) -> CircleFit | None:
    """Kåsa's algebraic circle fit of ``points`` (N >= 3, 2) [m]; ``None`` if degenerate.

    Example:
        >>> angles = np.linspace(0, 2, 9)
        >>> fit = fit_circle(np.column_stack([1 + 2 * np.cos(angles), 2 * np.sin(angles)]))
        >>> round(fit.cx, 6), round(fit.cy, 6), round(fit.radius, 6)
        (1.0, 0.0, 2.0)
    """
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 2 or len(points) < 3:
        raise ValueError(f"points: expected shape (N >= 3, 2), got {points.shape}")
    origin = points.mean(axis=0)  # centring keeps the normal equations well conditioned
    fit = solve_kasa(*kasa_normal_equations(points - origin), points - origin)
    if fit is None:
        return None
    return CircleFit(fit.cx + origin[0], fit.cy + origin[1], fit.radius, fit.rms)


@dataclass(frozen=True)
class Obstacle:
    """One cluster of returns, in the world frame.

    Attributes:
        points: ``(m, 2)`` world positions [m] of the returns.
        beams: ``(m,)`` indices of the beams (into the scan) that produced them.
        centroid: ``(2,)`` [m] mean of ``points``.
        extent: ``(length, width)`` [m] spread of the points along and across their principal
            axis.
        axis_angle: [rad] world direction of the principal axis.
        circle: the fitted circle if the cluster is round, else ``None``.
        circle_tested: whether the cluster had enough returns to be tested for roundness.
    """

    points: NDArray[np.float64]
    beams: NDArray[np.int64]
    centroid: NDArray[np.float64]
    extent: NDArray[np.float64]
    axis_angle: float
    circle: CircleFit | None
    circle_tested: bool

    @property
    def position(self) -> NDArray[np.float64]:
        """``(2,)`` [m]: the circle centre of a round obstacle, else the centroid."""
        return self.circle.centre if self.circle is not None else self.centroid


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
            raise ValueError(f"range_sigma: expected a number >= 0 [m], got {self.range_sigma!r}")
        if not 0.0 < self.grazing_angle < math.pi / 2:
            raise ValueError(f"grazing_angle: expected an angle in (0, pi/2) [rad], "
                             f"got {self.grazing_angle!r}")
        if self.min_points < 1 or self.min_circle_points < 4:
            raise ValueError(f"expected min_points >= 1 and min_circle_points >= 4, got "
                             f"{self.min_points} and {self.min_circle_points}")
        if not (self.max_radius > 0 and self.max_circle_rms > 0):
            raise ValueError(f"expected max_radius > 0 and max_circle_rms > 0, got "
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
        raise ValueError(f"ranges: expected shape {angles.shape} like beam_angles, "
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


def line_rms(points: NDArray[np.float64]) -> float:
    """rms [m] of the perpendicular distances of ``points`` (m >= 2, 2) to their total least
    squares line."""
    offsets = points - points.mean(axis=0)
    singular_values = np.linalg.svd(offsets, compute_uv=False)
    return float(singular_values[-1] / math.sqrt(len(points)))


def corner_rms(points: NDArray[np.float64]) -> float:
    """rms [m] of the best two-segment fit of ``points`` (m >= 3, 2), ordered along the scan:
    split at the point farthest from the chord of the ends (as in Douglas-Peucker), one
    total least squares line per side, the split point on both."""
    chord = points[-1] - points[0]
    normal = np.array([-chord[1], chord[0]]) / max(float(np.hypot(*chord)), 1e-12)
    split = int(np.argmax(np.abs((points - points[0]) @ normal)))
    split = min(max(split, 1), len(points) - 2)
    first, second = points[: split + 1], points[split:]
    squares = line_rms(first) ** 2 * len(first) + line_rms(second) ** 2 * len(second)
    return float(math.sqrt(squares / (len(points) + 1)))


def describe_cluster(
    points: NDArray[np.float64],
    beams: NDArray[np.int64],
    sensor_position: NDArray[np.float64],
    params: DetectorParams,
) -> Obstacle:
    """An :class:`Obstacle` from a cluster's world ``points`` seen from ``sensor_position``."""
    centroid = points.mean(axis=0)
    offsets = points - centroid
    if len(points) >= 2:
        _, _, axes = np.linalg.svd(offsets, full_matrices=False)
        axis = axes[0]
    else:
        axis = np.array([1.0, 0.0])
    along = offsets @ axis
    across = offsets @ np.array([-axis[1], axis[0]])
    extent = np.array([np.ptp(along), np.ptp(across)])
    circle = None
    if len(points) >= params.min_circle_points:
        fit = fit_circle(points)
        if (
            fit is not None
            and fit.radius <= params.max_radius
            and fit.rms <= params.max_circle_rms * max(params.range_sigma, 1e-6)
            # convex towards the sensor: the centre lies beyond the arc, not in front of it
            and np.linalg.norm(fit.centre - sensor_position)
            > np.linalg.norm(centroid - sensor_position)
            # a circle with fewer degrees of freedom (3) than two lines (4) must still fit
            # better: the convex corner of a box or of two walls is not a cylinder
            and fit.rms < corner_rms(points)
        ):
            circle = fit
    return Obstacle(points, beams, centroid, extent, float(math.atan2(axis[1], axis[0])), circle,
                    circle_tested=len(points) >= params.min_circle_points)


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
        raise ValueError(f"sensor_pose: expected 3 finite numbers (x, y, heading), got {pose}")
    ranges = np.asarray(ranges, dtype=np.float64)
    angles = np.asarray(beam_angles, dtype=np.float64)
    obstacles = []
    for beams in split_scan(ranges, angles, max_range, params):
        if len(beams) < params.min_points:
            continue
        local = np.column_stack(
            [ranges[beams] * np.cos(angles[beams]), ranges[beams] * np.sin(angles[beams])]
        )
        obstacles.append(describe_cluster(transform_points(pose, local), beams, pose[:2], params))
    return obstacles


def detect_in_observation(
    observation: Mapping[str, ArrayLike],
    car_pose: ArrayLike,
    setup: SensorSetup,
    params: DetectorParams | None = None,
) -> list[Obstacle]:
    """The obstacles in every scan of one env observation (keyed by ``setup.keys``) taken at
    the (estimated) car pose ``car_pose`` (3,), each Lidar at car pose ⊕ its mount."""
    scans = setup.check_observation(observation)
    obstacles = []
    for key, pose in zip(setup.keys, sensor_poses(car_pose, setup)[0], strict=True):
        obstacles += detect_obstacles(scans[key], setup.beam_angles, pose, setup.max_range,
                                      params)
    return obstacles


@dataclass
class Track:
    """One obstacle followed across steps.

    Attributes:
        id: stable identifier, unique within its tracker.
        position: ``(2,)`` world position [m]: the circle centre of a round track, else the
            latest centroid.
        circle: joint circle fit of all round detections, or ``None``.
        points: ``(m, 2)`` world returns [m] of the latest step it was detected in.
        hits: detections joined so far.
        round_hits, circle_tests: detections found round, and tested for roundness.
        first_step, last_step: steps of the first and the latest detection.
    """

    id: int
    position: NDArray[np.float64]
    circle: CircleFit | None
    points: NDArray[np.float64]
    hits: int
    first_step: int
    last_step: int
    _origin: NDArray[np.float64] = field(repr=False)
    round_hits: int = 0
    circle_tests: int = 0
    _reach: tuple[NDArray[np.float64], float] = field(init=False, repr=False)
    _tree: cKDTree | None = field(default=None, init=False, repr=False)
    _normal: NDArray[np.float64] = field(default_factory=lambda: np.zeros((3, 3)), repr=False)
    _rhs: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3), repr=False)

    def __post_init__(self) -> None:
        self._reach = _bounding_circle(self.points)

    @property
    def reach(self) -> tuple[NDArray[np.float64], float]:
        """Centre (2,) [m] and radius [m] of a circle holding :attr:`points`."""
        return self._reach

    def surface_distance(self, points: NDArray[np.float64]) -> float:
        """Smallest distance [m] from ``points`` (m, 2) to this track's latest returns."""
        if self._tree is None:
            self._tree = cKDTree(self.points)
        return float(np.min(self._tree.query(points)[0]))

    def add(self, obstacle: Obstacle, step: int) -> None:
        """Join ``obstacle`` (detected at ``step``) to this track."""
        same_step = self.hits > 0 and step == self.last_step  # e.g. seen by both Lidars
        self.points = np.vstack([self.points, obstacle.points]) if same_step else obstacle.points
        self._reach = _bounding_circle(self.points)
        self._tree = None
        self.hits += 1
        self.last_step = step
        self.circle_tests += obstacle.circle_tested
        if obstacle.circle is None:
            if self.circle is None:
                self.position = obstacle.centroid.copy()
            return
        self.round_hits += 1
        points = obstacle.points - self._origin
        normal, rhs = kasa_normal_equations(points)
        self._normal += normal
        self._rhs += rhs
        fit = solve_kasa(self._normal, self._rhs, points)
        if fit is not None:
            self.circle = CircleFit(fit.cx + self._origin[0], fit.cy + self._origin[1],
                                    fit.radius, fit.rms)
            self.position = self.circle.centre


def _bounding_circle(points: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]:
    """A circle holding ``points`` (m, 2): their mean and the largest distance from it [m]."""
    centre = points.mean(axis=0)
    return centre, float(np.sqrt(np.max(np.sum((points - centre) ** 2, axis=1))))


@dataclass
class ObstacleTracker:
    """Gives each static obstacle one id across steps (nearest neighbour within a gate).

    A detection joins the nearest track by position (circle centre or centroid) within
    ``gate`` [m]; an extended (not round) detection may instead join the track whose latest
    returns come within ``surface_gate`` [m] of its own, so a wall whose centroid wanders as
    the car drives along it keeps its id.

    ``gate`` defaults to 0.5 m: several times the per-step drift of a usable pose estimate and
    larger than the radius of the round obstacles we fit (so an arc's centroid and its fitted
    centre fall in one gate), yet below the spacing of obstacles a car can pass between
    (its width, 0.5 m here, plus margins). ``surface_gate`` defaults to 0.2 m: the returns of
    one surface in consecutive scans lie within one beam spacing of each other (0.17 m at 10 m
    for 1-degree beams), while distinct obstacles this close are one obstacle to a car."""

    gate: float = 0.5
    surface_gate: float = 0.2
    tracks: list[Track] = field(default_factory=list)
    _step: int = field(default=-1, repr=False)

    def __post_init__(self) -> None:
        for name in ("gate", "surface_gate"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name}: expected a positive distance [m], got {value!r}")

    def update(self, obstacles: list[Obstacle]) -> list[int]:
        """Associate one step's detections (from any number of Lidars); return their track ids."""
        self._step += 1
        ids = []
        for obstacle in obstacles:
            track = self.nearest(obstacle)
            if track is None:
                track = Track(
                    id=len(self.tracks), position=obstacle.position.copy(), circle=None,
                    points=obstacle.points, hits=0, first_step=self._step,
                    last_step=self._step, _origin=obstacle.centroid.copy(),
                )
                self.tracks.append(track)
            track.add(obstacle, self._step)
            ids.append(track.id)
        return ids

    def nearest(self, obstacle: Obstacle) -> Track | None:
        """The track ``obstacle`` belongs to (see the class doc), or ``None``."""
        if not self.tracks:
            return None
        positions = np.array([t.position for t in self.tracks])
        distances = np.hypot(*(positions - obstacle.position).T)
        distances[distances > self.gate] = np.inf
        if obstacle.circle is None:
            # only tracks whose returns could be within surface_gate: bounding circles first
            centre, radius = _bounding_circle(obstacle.points)
            centres = np.array([t.reach[0] for t in self.tracks])
            radii = np.array([t.reach[1] for t in self.tracks])
            near = np.hypot(*(centres - centre).T) <= radius + radii + self.surface_gate
            for i in np.flatnonzero(near):
                surface = self.tracks[i].surface_distance(obstacle.points)
                if surface <= self.surface_gate:
                    distances[i] = min(distances[i], surface)
        best = int(np.argmin(distances))
        return self.tracks[best] if np.isfinite(distances[best]) else None

    def cylinders(self, min_hits: int = 3, min_round_share: float = 0.1) -> NDArray[np.float64]:
        """``(M, 3)`` rows ``cx, cy, r`` [m] of the round tracks detected at least ``min_hits``
        times (one detection may be a coincidence of noise) and found round in at least
        ``min_round_share`` of their roundness tests. A free-standing cylinder is round in
        most of them; one touching a wall, which merges it into the wall's cluster from many
        viewpoints, in 20 % or more of them in our random worlds; the convex corner of a box
        or of two walls in a few percent (a short arc of returns around it fits a circle)."""
        if not 0.0 <= min_round_share <= 1.0:
            raise ValueError(
                f"min_round_share: expected a share in [0, 1], got {min_round_share!r}"
            )
        rows = [
            (t.circle.cx, t.circle.cy, t.circle.radius)
            for t in self.tracks
            if t.circle is not None and t.hits >= min_hits
            and t.round_hits >= min_round_share * t.circle_tests
        ]
        return np.array(rows, dtype=np.float64).reshape(-1, 3)
