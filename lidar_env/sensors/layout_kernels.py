"""The compiled sensor model of :mod:`lidar_env.sensors.lidar_layout`: K Lidars' exact ranges and
readings.

:func:`cast_packed` gives the exact float64 ranges of K sensors packed end to end (each cast by
:func:`lidar_env.sensors.ray_casting.cast_sensor`, then the moving circles by :func:`cast_movers`
and the car's own outline by :func:`cast_body`); :func:`readings` turns them into float32 readings
(noise, clipping, dropouts). Sensors come as :func:`lidar_env.sensors.lidar_config.pack_sensors`
packs them: ``beams`` = ``(table, order)`` and one ``params`` row per sensor, sensor ``k`` owning
positions ``[first, end)``. :func:`scan_layout_body_kernel` takes the world as arrays and a grid
(:func:`scan_layout_kernel`, the vector env's, without movers or the car;
:func:`exact_ranges_kernel`, :func:`lidar_env.sensors.lidar.cast_rays`'s, the exact ranges only).

Self-occlusion (``LidarConfig.self_occlusion``, for a Lidar at body level): the four edges of
the car's ``car_length x car_width`` rectangle are walls to that Lidar, except where they pass
within ``housing_radius`` of its mount (its window, where the scanner head pokes out of the
body). A beam that meets the outline farther out reads the distance to it: it is blocked by the
car, at a point of the car's known shape. A Lidar that is not flagged sees over the car.

Units: metres, radians, world frame.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from lidar_env.core.errors import ConfigError
from lidar_env.sensors.lidar_config import (
    BELOW_MAX,
    DROPOUT,
    END,
    FIRST,
    HOUSING,
    IN_ORDER,
    MAX_RANGE,
    MIN_RANGE,
    NOISE,
    OFFSET,
    STEP,
)
from lidar_env.sensors.ray_casting import (
    beam_directions,
    cast_sensor,
    inline_into_scan_loops,
    segment_hit,
    sweep_circles,
)
from lidar_env.world.primitive_grid import point_segment_distance2


@njit(cache=True, fastmath=False)
def cast_movers(ranges: NDArray[np.float64], ox: float, oy: float, heading: float,
                movers: NDArray[np.float64], own: tuple, max_range: float) -> None:
    """Lower ``ranges`` (n,) of one sensor at world ``(ox, oy)`` (heading [rad] in [0, 2 pi))
    to the exact hits on the moving circles ``movers`` (M, 3: x, y, radius [m]); all 0 when
    the sensor is inside one. ``own`` is the sensor's beams from
    :func:`lidar_env.sensors.ray_casting.beam_directions`; each circle updates only the beams within
    the angle it subtends."""
    near = np.empty((6, movers.shape[0]))
    near[:3] = movers.T
    if not sweep_circles(ranges, near, movers.shape[0], ox, oy, heading, own, max_range, False):
        ranges.fill(0.0)


@njit(cache=True, fastmath=False)
def car_outline(car: NDArray[np.float64]) -> NDArray[np.float64]:
    """The four edges (4, 4) [m] of the car's rectangle ``car`` = (x, y, yaw, half_length,
    half_width) in the world frame, corners counter-clockwise from front left."""
    x, y, yaw, hl, hw = car[0], car[1], car[2], car[3], car[4]
    c, s = math.cos(yaw), math.sin(yaw)
    corners = np.empty((4, 2))
    for k, (u, v) in enumerate(((hl, hw), (-hl, hw), (-hl, -hw), (hl, -hw))):
        corners[k, 0] = x + c * u - s * v
        corners[k, 1] = y + s * u + c * v
    edges = np.empty((4, 4))
    for k in range(4):
        edges[k, :2] = corners[k]
        edges[k, 2:] = corners[(k + 1) % 4]
    return edges


@njit(cache=True, fastmath=False)
def cast_body(ranges: NDArray[np.float64], ox: float, oy: float,
              outline: NDArray[np.float64], housing: float, own: tuple,
              max_range: float) -> None:
    """Lower ``ranges`` to the hits on the car's ``outline`` (4, 4) farther than ``housing``
    [m] from the sensor at ``(ox, oy)``: a self-occluded Lidar's view of its own car."""
    dir_x, dir_y = own[3], own[4]
    for k in range(4):  # a line meets a ray once: a hit within the window is simply dropped
        x1, y1, x2, y2 = outline[k, 0], outline[k, 1], outline[k, 2], outline[k, 3]
        if point_segment_distance2(ox, oy, x1, y1, x2, y2) >= max_range * max_range:
            continue
        for j in range(ranges.shape[0]):
            t = segment_hit(ox, oy, dir_x[j], dir_y[j], x1, y1, x2, y2, ranges[j])
            if housing < t < ranges[j]:
                ranges[j] = t


@njit(cache=True, fastmath=False, inline=inline_into_scan_loops)
def cast_packed(
    circles: NDArray[np.float64],
    segments: NDArray[np.float64],
    first_polygon_edge: int,
    grid: tuple,
    sensor_poses: NDArray[np.float64],
    beams: tuple,
    params: NDArray[np.float64],
    movers: NDArray[np.float64],
    car: NDArray[np.float64],
    seen: tuple,
    first_stamp: int,
    facing: NDArray[np.int64],
) -> NDArray[np.float64]:
    """Packed exact ranges [m] (float64, a view of the work rows of ``beams``) of K sensors
    whose beam 0 is at world pose ``sensor_poses[k]`` turned by ``params[k, OFFSET]``;
    ``movers`` (M, 3) moving circles; ``car`` (5,) the car's pose and half sizes, or empty
    (then no Lidar may self-occlude). ``seen`` and stamps from ``first_stamp`` on as for
    :func:`lidar_env.sensors.ray_casting.cast_sensor` (sensor ``k`` uses ``first_stamp + k``), and
    ``facing`` the segments' free sides (:func:`lidar_env.sensors.edge_facing.edge_facing`) or
    empty."""
    table, order = beams
    total = table.shape[1]
    rows = table.ravel()  # 1-D row slices stay contiguous for numba (2-D ones would not)
    exact = rows[3 * total:4 * total]
    for k in range(sensor_poses.shape[0]):
        a, b = int(params[k, FIRST]), int(params[k, END])
        max_range, housing = params[k, MAX_RANGE], params[k, HOUSING]
        pose = (sensor_poses[k, 0], sensor_poses[k, 1], sensor_poses[k, 2] + params[k, OFFSET])
        own = beam_directions(pose[2], rows[a:b], order[a:b], params[k, STEP],
                              rows[total + a:total + b], rows[2 * total + a:2 * total + b],
                              rows[4 * total + a:4 * total + b], rows[5 * total + a:5 * total + b])
        ranges = exact[a:b]
        cast_sensor(ranges, pose, circles, segments, first_polygon_edge, grid, seen,
                    first_stamp + k, own, max_range, facing, params[k, IN_ORDER] > 0.0)
        if movers.shape[0] > 0:
            cast_movers(ranges, pose[0], pose[1], pose[2] % (2.0 * math.pi), movers, own,
                        max_range)
        if housing >= 0.0:
            if car.shape[0] != 5:
                raise ConfigError("car: a self-occluded Lidar needs the car's pose and size "
                                  "(LidarLayout.scan(..., car_pose=...)), got none")
            cast_body(ranges, pose[0], pose[1], car_outline(car), housing, own, max_range)
    return exact


@njit(cache=True, fastmath=False)
def fresh_seen(circles: NDArray[np.float64], segments: NDArray[np.float64]) -> tuple:
    """Zeroed ``seen`` marks for :func:`cast_packed` (stamps from 1 on)."""
    return (np.zeros(circles.shape[0], dtype=np.int64),
            np.zeros(segments.shape[0], dtype=np.int64))


@njit(cache=True, fastmath=False)
def exact_ranges_kernel(circles: NDArray[np.float64], segments: NDArray[np.float64],
                        first_polygon_edge: int, grid: tuple, sensor_poses: NDArray[np.float64],
                        beams: tuple, params: NDArray[np.float64]) -> NDArray[np.float64]:
    """A copy of :func:`cast_packed`'s exact ranges, without movers or the car."""
    return cast_packed(circles, segments, first_polygon_edge, grid, sensor_poses, beams, params,
                       np.empty((0, 3)), np.empty(0), fresh_seen(circles, segments), 1,
                       np.empty(0, dtype=np.int64)).copy()


@njit(cache=True, fastmath=False, inline=inline_into_scan_loops)
def readings(exact: NDArray[np.float64], params: NDArray[np.float64],
             gaussians: NDArray[np.float64], uniforms: NDArray[np.float64],
             out: NDArray[np.float32]) -> NDArray[np.float32]:
    """``out`` filled with the float32 readings of packed exact ranges: a hit gets
    ``noise_std * gaussians[j]`` (when drawn and the sensor is noisy) and is clipped to
    ``[0, below_max]``; a reading below the sensor's ``min_range`` (when > 0) is invalid and
    reads ``max_range``, as does a beam with ``uniforms[j] < dropout_prob`` (when drawn).

    Each sensor's beams are taken as slices from 0 with the noise and dropout choices made
    once per sensor, so the loops over beams have no bounds to wrap and no branch but the
    hit test, and numba vectorises them (about 0.2 against 1.1 us for 720 beams).
    """
    noisy, dropping = gaussians.size > 0, uniforms.size > 0
    for k in range(params.shape[0]):
        max_range, below_max = params[k, MAX_RANGE], params[k, BELOW_MAX]
        noise_std, dropout = params[k, NOISE], params[k, DROPOUT]
        first, end = int(params[k, FIRST]), int(params[k, END])
        ranges, sensor_out = exact[first:end], out[first:end]
        if noisy and noise_std > 0.0:
            noise = gaussians[first:end]
            for j in range(ranges.shape[0]):
                r = ranges[j]
                if r < max_range:
                    r = min(max(r + noise_std * noise[j], 0.0), below_max)
                sensor_out[j] = r
        else:
            for j in range(ranges.shape[0]):
                r = ranges[j]
                if r < max_range:
                    r = min(max(r, 0.0), below_max)
                sensor_out[j] = r
        min_range = params[k, MIN_RANGE]
        if min_range > 0.0:
            for j in range(ranges.shape[0]):
                if sensor_out[j] < min_range:
                    sensor_out[j] = max_range
        if dropping:
            draws = uniforms[first:end]
            for j in range(ranges.shape[0]):
                if draws[j] < dropout:
                    sensor_out[j] = max_range
    return out


@njit(cache=True, fastmath=False)
def scan_layout_body_kernel(
    circles: NDArray[np.float64], segments: NDArray[np.float64], first_polygon_edge: int,
    grid: tuple, sensor_poses: NDArray[np.float64], beams: tuple, params: NDArray[np.float64],
    gaussians: NDArray[np.float64], uniforms: NDArray[np.float64],
    movers: NDArray[np.float64], car: NDArray[np.float64],
) -> NDArray[np.float32]:
    """Packed float32 readings of K sensors (:func:`cast_packed`, then :func:`readings`);
    ``gaussians`` and ``uniforms`` hold one draw per packed beam, or are empty when no sensor
    needs them."""
    exact = cast_packed(circles, segments, first_polygon_edge, grid, sensor_poses, beams,
                        params, movers, car, fresh_seen(circles, segments), 1,
                        np.empty(0, dtype=np.int64))
    return readings(exact, params, gaussians, uniforms, np.empty(exact.shape[0], np.float32))


@njit(cache=True, fastmath=False)
def scan_layout_kernel(
    circles: NDArray[np.float64], segments: NDArray[np.float64], first_polygon_edge: int,
    grid: tuple, sensor_poses: NDArray[np.float64], beams: tuple, params: NDArray[np.float64],
    gaussians: NDArray[np.float64], uniforms: NDArray[np.float64],
) -> NDArray[np.float32]:
    """:func:`scan_layout_body_kernel` without movers and without the car."""
    return scan_layout_body_kernel(circles, segments, first_polygon_edge, grid, sensor_poses,
                                   beams, params, gaussians, uniforms, np.empty((0, 3)),
                                   np.empty(0))
