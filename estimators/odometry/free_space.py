"""Points in space a scan saw as free: how the odometry tells moving things from the map.

A planar Lidar's beam says more than where it ended: the space along it, up to the return, was
empty when it was cast. A point that lies well inside that free space cannot be a static
surface: either it was recorded earlier on something that has moved away since (a trail in the
local map), or it is on something that moved in after (a pedestrian now standing where the
previous scan looked through). :func:`seen_through` finds such points; the scan-to-map odometry
(:mod:`estimators.odometry.local_map`) drops the current scan's points that the previous scan
saw through, and the map points the current scan sees through. (The same visibility argument
removes dynamic points from 3D maps, e.g. Kim & Kim, "Remove, then Revert", IROS 2020; here it
runs per scan, on the scans themselves.) :class:`~estimators.odometry.moving_points.
MovingPointFilter` applies it to a stream of scans.

A point counts as seen through by one sensor when it lies within the sensor's field of view and
range, and the beam nearest its bearing and both that beam's neighbours all read more than its
distance plus ``margin``. Asking the neighbours too keeps the edges of obstacles and walls
seen at grazing incidence, where one beam may slip past a point the next one hits. Readings
at or beyond ``max_range`` (no return) count as free up to ``max_range``; readings below
``min_range`` say nothing.

Where it helps and where not: in simulation a reading of ``max_range`` means exactly "nothing
there", and with pedestrians the filter keeps the odometry's static accuracy. The odometry
judges the points at the pose it matched (then matches again without the moving ones): judged
at the predicted pose, a fast turn's error makes static points look seen through. The new scan
judges earlier points only where its beams lie close enough to hit a thin object
(``MovingPointFilter``'s ``stale_resolution``). No-return beams count as seeing free space:
in the open, space behind a walker is seen free only by beams that return nothing. But a
no-return beam among returns (within :data:`DROPOUT_WINDOW` of one, or more beams on a scan
that drops many: :func:`~estimators.odometry.dropped_beams.dropout_window`) is a dropped return,
not a look into the open: it counts as free only as far as the nearer of the nearest
returns on either side (a Lidar dropping half its beams otherwise sees through the walls it
measures, and the odometry loses them from its map).

Units: metres, radians; points and sensor poses in one common frame (the world, or the car's).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimators.odometry.dropped_beams import DROPOUT_WINDOW, bound_dropped_returns
from lidar_env.core import ConfigError, EstimatorInputError

_TWO_PI = 2.0 * math.pi


@numba.njit(cache=True, error_model="numpy")
def _bearing(y: float, x: float) -> float:
    """``atan2(y, x)`` [rad] to within 2e-6 rad (an octant-reduced polynomial): enough to pick
    the nearest beam, and several times cheaper than libm's. (numpy's error model: its one
    division, guarded, needs no zero check, so a loop of it compiles to SIMD.)"""
    ax, ay = abs(x), abs(y)
    if ax == 0.0 and ay == 0.0:
        return 0.0
    a = min(ax, ay) / max(ax, ay)
    q = a * a
    r = a * (0.99997726 + q * (-0.33262347 + q * (0.19354346 + q * (
        -0.11643287 + q * (0.05265332 - q * 0.0117212)))))
    if ay > ax:
        r = 0.5 * math.pi - r
    if x < 0.0:
        r = math.pi - r
    return -r if y < 0.0 else r


@numba.njit(cache=True)
def _nearest_beam(bearing: float, relative_angles: NDArray[np.float64], a: int, n: int,
                  step: float, full_turn: bool, last: float, half_spacing: float) -> int:
    """The index (0..n-1) of the beam nearest ``bearing`` [rad] from beam 0 of the sensor whose
    sorted relative angles start at ``relative_angles[a]`` (:func:`_seen_through_kernel`'s
    packing), or -1 outside its field of view."""
    while bearing < 0.0:
        bearing += _TWO_PI
    while bearing >= _TWO_PI:
        bearing -= _TWO_PI
    if step > 0.0:  # uniform beams: the nearest by arithmetic
        j = int(bearing / step + 0.5)
        if j >= n:
            if full_turn:
                j = 0 if j * step >= _TWO_PI - 0.5 * step else n - 1
            elif bearing - last <= half_spacing:
                j = n - 1
            else:
                return -1
        return j
    j = np.searchsorted(relative_angles[a:a + n], bearing)
    if j == n:  # past the last beam: it, or (on a full turn) beam 0 a turn on
        if full_turn and _TWO_PI - bearing < bearing - last:
            return 0
        if full_turn or bearing - last <= half_spacing:
            return n - 1
        return -1
    if j > 0 and (bearing - relative_angles[a + j - 1] < relative_angles[a + j] - bearing):
        j -= 1
    return j


@numba.njit(cache=True)
def _seen_through_kernel(
    points: NDArray[np.float64],
    poses: NDArray[np.float64],
    ranges: NDArray[np.float64],
    starts: NDArray[np.int64],
    relative_angles: NDArray[np.float64],
    order: NDArray[np.int64],
    sensor_params: NDArray[np.float64],
    margin: float,
    min_range: float,
    resolution: float,
) -> NDArray[np.bool_]:
    """``(n,)`` True where one of K sensors at ``poses`` (K, 3) saw through ``points[i]``.

    Sensor ``k`` owns the packed positions ``[starts[k], starts[k + 1])`` of ``ranges`` (its
    readings, beam order), ``relative_angles`` (its beam angles minus beam 0's, wrapped to
    [0, 2 pi) and sorted: a field of view narrower than a turn is then one unbroken interval
    from 0, whichever way it is centred) and ``order`` (the beam index of each sorted angle).
    ``sensor_params[k]`` = (beam 0's angle [rad], max range [m], uniform step [rad] or 0, full
    turn 1/0). A full turn's neighbours wrap around; a narrower one's do not. Points where
    a sensor's beams lie more than ``resolution`` [m] apart are not judged by it.

    The plain form, beam by beam: :func:`_seen_through_free` gives the same booleans faster
    (the tests hold it to this one).
    """
    out = np.zeros(points.shape[0], dtype=np.bool_)
    for k in range(poses.shape[0]):
        a, b = starts[k], starts[k + 1]
        n = b - a
        first_angle, max_range, step, full = sensor_params[k]
        full_turn = full > 0.5
        last = relative_angles[b - 1] - relative_angles[a]
        half_spacing = 0.5 * last / max(n - 1, 1)
        c, s = math.cos(poses[k, 2]), math.sin(poses[k, 2])
        for i in range(points.shape[0]):
            if out[i]:
                continue
            dx, dy = points[i, 0] - poses[k, 0], points[i, 1] - poses[k, 1]
            distance = math.sqrt(dx * dx + dy * dy)
            if (distance + margin >= max_range or distance < min_range
                    or 2.0 * half_spacing * distance > resolution):
                continue
            bearing = _bearing(-s * dx + c * dy, c * dx + s * dy) - first_angle
            j = _nearest_beam(bearing, relative_angles, a, n, step, full_turn, last,
                              half_spacing)
            if j < 0:
                continue  # outside the field of view: this sensor says nothing
            free = True
            for offset in (-1, 0, 1):
                m = j + offset
                if full_turn:
                    if m < 0:
                        m += n
                    elif m >= n:
                        m -= n
                elif m < 0 or m >= n:
                    free = False
                    break
                reading = ranges[a + order[a + m]]
                if not (reading >= min_range and min(reading, max_range) > distance + margin):
                    free = False
                    break
            out[i] = free
    return out


@numba.njit(cache=True)
def _free_ranges(ranges: NDArray[np.float64], starts: NDArray[np.int64],
                 order: NDArray[np.int64], sensor_params: NDArray[np.float64],
                 min_range: float) -> NDArray[np.float64]:
    """How far [m] each beam and both its neighbours saw free, packed as ``relative_angles``
    (sorted): the least of the three readings, each capped at the max range, -inf where one
    is below ``min_range`` (or NaN) or missing (a narrower field of view's end beams).

    :func:`_seen_through_kernel`'s three-reading test at distance d is then one comparison,
    ``free > d + margin``: the least of three is exact, so the booleans are the same.
    """
    free = np.empty(len(ranges))
    for k in range(len(starts) - 1):
        a, b = starts[k], starts[k + 1]
        n = b - a
        max_range, full_turn = sensor_params[k, 1], sensor_params[k, 3] > 0.5
        seen = np.empty(n)
        for m in range(n):
            reading = ranges[a + order[a + m]]
            seen[m] = min(reading, max_range) if reading >= min_range else -np.inf
        for j in range(n):
            before, after = j - 1, j + 1
            if full_turn:
                before, after = (before + n) % n, after % n
            elif before < 0 or after >= n:
                free[a + j] = -np.inf
                continue
            free[a + j] = min(seen[before], min(seen[j], seen[after]))
    return free


@numba.njit(cache=True, error_model="numpy")
def _polar(points: NDArray[np.float64], x: float, y: float, c: float, s: float,
           distance: NDArray[np.float64], bearing: NDArray[np.float64]) -> None:
    """Each of ``points`` (n, 2)' distance [m] and raw bearing [rad] (before beam 0's angle
    is taken off) from a sensor at ``(x, y)`` heading ``atan2(s, c)``, into ``distance`` and
    ``bearing`` (n,): the operations of :func:`_seen_through_kernel`, with no branch to stop
    SIMD."""
    for i in range(points.shape[0]):
        dx, dy = points[i, 0] - x, points[i, 1] - y
        distance[i] = math.sqrt(dx * dx + dy * dy)
        bearing[i] = _bearing(-s * dx + c * dy, c * dx + s * dy)


@numba.njit(cache=True, error_model="numpy")
def _seen_through_free(
    points: NDArray[np.float64],
    poses: NDArray[np.float64],
    free: NDArray[np.float64],
    starts: NDArray[np.int64],
    relative_angles: NDArray[np.float64],
    sensor_params: NDArray[np.float64],
    margin: float,
    min_range: float,
    resolution: float,
) -> NDArray[np.bool_]:
    """:func:`_seen_through_kernel`'s booleans from the sensors' :func:`_free_ranges`
    ``free``: every point's distance and bearing from a sensor in one SIMD pass, then the
    nearest beam and one comparison; points beyond the sensor's farthest free reach are
    passed over before that (they fail the comparison anyway)."""
    count = points.shape[0]
    out = np.zeros(count, dtype=np.bool_)
    distances, bearings = np.empty(count), np.empty(count)
    for k in range(poses.shape[0]):
        a, b = starts[k], starts[k + 1]
        n = b - a
        first_angle, max_range, step, full = sensor_params[k]
        full_turn = full > 0.5
        last = relative_angles[b - 1] - relative_angles[a]
        half_spacing = 0.5 * last / max(n - 1, 1)
        reach = max_range
        if n:
            reach = min(reach, free[a:b].max())
        _polar(points, poses[k, 0], poses[k, 1], math.cos(poses[k, 2]), math.sin(poses[k, 2]),
               distances, bearings)
        for i in range(count):
            distance = distances[i]
            if (out[i] or distance + margin >= reach or distance < min_range
                    or 2.0 * half_spacing * distance > resolution):
                continue
            bearing = bearings[i] - first_angle
            j = _nearest_beam(bearing, relative_angles, a, n, step, full_turn, last,
                              half_spacing)
            if j < 0:
                continue  # outside the field of view: this sensor says nothing
            out[i] = free[a + j] > distance + margin
    return out


class BeamGeometry:
    """K sensors' beams packed for :func:`_seen_through_kernel` (built once per setup).

    Args:
        beam_angles: K arrays of beam directions [rad], CCW from each sensor's forward axis.
        max_ranges: K max ranges [m]; readings at or beyond are free space up to there.
    """

    def __init__(self, beam_angles: Sequence[ArrayLike], max_ranges: Sequence[float]) -> None:
        if len(beam_angles) != len(max_ranges) or not beam_angles:
            raise EstimatorInputError(
                f"beam_angles, max_ranges: expected one per sensor (>= 1), got "
                f"{len(beam_angles)} and {len(max_ranges)}")
        relative, order, params = [], [], []
        for angles, max_range in zip(beam_angles, max_ranges, strict=True):
            angles = np.asarray(angles, dtype=np.float64).ravel()
            wrapped = (angles - angles[0]) % _TWO_PI
            sort = np.argsort(wrapped, kind="stable")
            sorted_angles = wrapped[sort]
            n = len(angles)
            # a full turn: the gap from the last beam back round to beam 0 is one spacing
            full_turn = _TWO_PI - sorted_angles[-1] <= 1.5 * _TWO_PI / n
            step = sorted_angles[-1] / (n - 1) if n > 1 else 0.0
            uniform = step > 0 and np.allclose(sorted_angles, step * np.arange(n), rtol=0.0,
                                               atol=1e-9)
            relative.append(sorted_angles)
            order.append(sort)
            params.append((angles[0], float(max_range), step if uniform else 0.0,
                           float(full_turn)))
        spacings = [max(r[-1] / (len(r) - 1), 1e-9) if len(r) > 1 else _TWO_PI
                    for r in relative]
        self.windows = np.array([max(1, round(DROPOUT_WINDOW / spacing))
                                 for spacing in spacings], dtype=np.int64)
        self.sizes = [len(r) for r in relative]
        self.starts = np.concatenate([[0], np.cumsum(self.sizes)]).astype(np.int64)
        self.relative_angles = np.concatenate(relative)
        self.order = np.concatenate(order).astype(np.int64)
        self.params = np.array(params, dtype=np.float64)

    def seen_through(
        self, points: ArrayLike, sensor_poses: ArrayLike, scans: Sequence[ArrayLike],
        margin: float = 0.2, min_range: float = 0.0, resolution: float = math.inf,
    ) -> NDArray[np.bool_]:
        """``(n,)`` True where any sensor's scan saw through ``points`` (n, 2) (see the
        module docstring); ``sensor_poses`` (K, 3) in the frame of the points, ``scans`` K
        range arrays [m] in beam order; a sensor judges only points where its beams lie at
        most ``resolution`` [m] apart."""
        poses = np.ascontiguousarray(sensor_poses, dtype=np.float64).reshape(-1, 3)
        if len(poses) != len(self.sizes) or len(scans) != len(self.sizes):
            raise EstimatorInputError(f"sensor_poses, scans: expected {len(self.sizes)} (one per "
                             f"sensor), got {len(poses)} and {len(scans)}")
        if not (math.isfinite(margin) and margin >= 0):
            raise ConfigError(f"margin: expected a distance >= 0 [m], got {margin!r}")
        return self.judge(np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2), poses,
                          self.pack(scans, min_range), float(margin), float(min_range),
                          float(resolution))

    def pack(self, scans: Sequence[ArrayLike], min_range: float = 0.0) -> NDArray[np.float64]:
        """The K sensors' readings ``scans`` [m] as one float64 array, checked for length, each
        no-return reading within its dropout window of a return (readings from
        ``min_range`` [m] up) bounded by the nearest returns on either side (module
        docstring)."""
        ranges = np.concatenate([np.asarray(r, dtype=np.float64).ravel() for r in scans])
        if len(ranges) != self.starts[-1]:
            raise EstimatorInputError(f"scans: expected {self.sizes} readings, got "
                                      f"{[np.size(r) for r in scans]}")
        return bound_dropped_returns(ranges, self.starts, self.order, self.params, self.windows,
                                   float(min_range))

    def judge(self, points: NDArray[np.float64], poses: NDArray[np.float64],
              ranges: NDArray[np.float64], margin: float, min_range: float,
              resolution: float) -> NDArray[np.bool_]:
        """:meth:`seen_through` of inputs already checked and packed: ``points`` (n, 2) and
        ``poses`` (K, 3) C-contiguous float64, ``ranges`` every sensor's readings in one
        float64 array."""
        return self.judge_free(points, poses, self.free(ranges, min_range), margin, min_range,
                               resolution)

    def free(self, ranges: NDArray[np.float64], min_range: float) -> NDArray[np.float64]:
        """The packed readings ``ranges`` (float64, beam order) as :func:`_free_ranges`: how far
        [m] each beam and its neighbours saw free, for :meth:`judge_free` (a scan judged more
        than once is packed once)."""
        return _free_ranges(ranges, self.starts, self.order, self.params, min_range)

    def judge_free(self, points: NDArray[np.float64], poses: NDArray[np.float64],
                   free: NDArray[np.float64], margin: float, min_range: float,
                   resolution: float) -> NDArray[np.bool_]:
        """:meth:`judge` of readings packed by :meth:`free` (with the same ``min_range``)."""
        return _seen_through_free(points, poses, free, self.starts, self.relative_angles,
                                  self.params, margin, min_range, resolution)


def seen_through(
    points: ArrayLike,
    sensor_poses: ArrayLike,
    scans: Sequence[ArrayLike],
    beam_angles: Sequence[ArrayLike],
    max_ranges: Sequence[float],
    margin: float = 0.2,
    min_range: float = 0.0,
) -> NDArray[np.bool_]:
    """``(n,)`` True where any sensor's scan saw through ``points`` (n, 2) (module docstring).

    Args:
        points: ``(n, 2)`` positions [m] in the frame of ``sensor_poses``.
        sensor_poses: ``(K, 3)`` poses (x [m], y [m], heading [rad]) the scans were taken at.
        scans: K range arrays [m], sensor ``k``'s beam ``j`` along ``beam_angles[k][j]``
            [rad] CCW from its forward axis.
        max_ranges: K max ranges [m]; readings at or beyond are free space up to there.
        margin: [m] how far inside the free space a point must lie (0.2: ten range-noise
            sigmas of a 1-2 cm Lidar, yet under a pedestrian's 10 Hz step plus its size).
        min_range: [m] readings below it say nothing.
    """
    return BeamGeometry(beam_angles, max_ranges).seen_through(points, sensor_poses, scans,
                                                              margin, min_range)
