"""Several Lidars of their own geometry scanned in one compiled call: the one sensor kernel.

:class:`LidarLayout` holds K Lidars (:class:`~lidar_env.lidar_config.LidarConfig`: mount, beams
over a field of view, max range, noise, dropouts, self-occlusion) and :meth:`LidarLayout.scan`
returns their K float32 scans from one call of :func:`scan_packed_kernel`. Every scan of the
package goes through :func:`cast_packed` (exact float64 ranges of K sensors, each cast by
:func:`lidar_env.ray_casting.cast_sensor`, then the moving circles by :func:`cast_movers` and
the car's own outline by :func:`cast_body`) and :func:`readings` (noise, clipping, dropouts,
float32). :class:`lidar_env.lidar.Lidar` and :func:`lidar_env.lidar.cast_rays` pack their
identical sensors the same way (:func:`lidar_env.lidar_config.pack_sensors`: beams end to end,
sensor ``k`` owning positions ``[first, end)`` of its ``params`` row). The kernels differ only
in how the world comes: :func:`scan_packed_kernel` takes it packed once per world
(:func:`lidar_env.primitive_grid.pack_scan_world`, with the edges' free sides for back-face
culling); :func:`scan_layout_body_kernel` takes it as arrays and a grid, and
:func:`scan_layout_kernel` (the vector env's) the same without movers or the car.

Self-occlusion (``LidarConfig.self_occlusion``, for a Lidar at body level): the four edges of
the car's ``car_length x car_width`` rectangle are walls to that Lidar, except where they pass
within ``housing_radius`` of its mount (its window, where the scanner head pokes out of the
body). A beam that meets the outline farther out reads the distance to it: it is blocked by the
car, at a point of the car's known shape. A Lidar that is not flagged sees over the car.

Random numbers: if any Lidar is noisy, one standard normal per beam of every Lidar (in sensor
order), then, if any has dropouts, one uniform per beam; so a layout of identical Lidars
consumes the stream exactly as :meth:`lidar_env.lidar.Lidar.scan` does, and the same seed gives
the same scans bit for bit.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import cached_property

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from lidar_env.edge_facing import edge_facing
from lidar_env.errors import ConfigError
from lidar_env.lidar_config import (
    BELOW_MAX,
    DROPOUT,
    END,
    FIRST,
    HOUSING,
    MAX_RANGE,
    NOISE,
    OFFSET,
    STEP,
    LidarConfig,
    pack_sensors,
)
from lidar_env.primitive_grid import (
    STAMP,
    pack_scan_world,
    point_segment_distance2,
    unpack_scan_world,
)
from lidar_env.ray_casting import (
    beam_directions,
    cast_sensor,
    segment_hit,
    sweep_circle,
)
from lidar_env.world import World

Geometry = World | tuple[ArrayLike, ArrayLike]

_NO_DRAWS = np.empty(0)
_NO_CAR = np.empty(0)
_NO_MOVERS = np.empty((0, 3))
_NO_WORLD = (None, (None, None))  # LidarLayout._world_of before the first scan
_FLOAT64 = np.dtype(np.float64)  # numpy's one instance (another float64 dtype is converted)


def as_poses(sensor_poses: ArrayLike) -> NDArray[np.float64]:
    """``sensor_poses`` as a contiguous float64 ``(K, 3)`` array (a single pose becomes K = 1)."""
    poses = np.ascontiguousarray(sensor_poses, dtype=np.float64)
    if poses.ndim == 1:
        poses = poses[None, :]
    if poses.ndim != 2 or poses.shape[1] != 3:
        raise ConfigError(
            f"sensor_poses: expected finite (K, 3) poses (x, y, heading), got shape {poses.shape}"
        )
    return poses


def as_world(world_or_arrays: Geometry) -> tuple[World, int]:
    """The world to scan and the index of its first polygon edge in ``world.segments``."""
    if isinstance(world_or_arrays, World):
        return world_or_arrays, len(world_or_arrays.walls)
    if not isinstance(world_or_arrays, tuple) or len(world_or_arrays) != 2:
        raise TypeError(
            "world_or_arrays: expected a World or a (circles (N,3), segments (M,4)) tuple, "
            f"got {type(world_or_arrays).__name__}"
        )
    world = World(*world_or_arrays, bounds=(0.0, 0.0, 1.0, 1.0))
    return world, len(world.segments)


@njit(cache=True, fastmath=False)
def cast_movers(ranges: NDArray[np.float64], ox: float, oy: float, heading: float,
                movers: NDArray[np.float64], own: tuple, max_range: float) -> None:
    """Lower ``ranges`` (n,) of one sensor at world ``(ox, oy)`` (heading [rad] in [0, 2 pi))
    to the exact hits on the moving circles ``movers`` (M, 3: x, y, radius [m]); all 0 when
    the sensor is inside one. ``own`` is the sensor's beams from
    :func:`lidar_env.ray_casting.beam_directions`; each circle updates only the beams within
    the angle it subtends."""
    sorted_angles, order, step, dir_x, dir_y = own
    for i in range(movers.shape[0]):
        if not sweep_circle(ranges, ox, oy, heading, movers[i, 0], movers[i, 1], movers[i, 2],
                            sorted_angles, order, step, dir_x, dir_y, max_range):
            return


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


@njit(cache=True, fastmath=False)
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
    :func:`lidar_env.ray_casting.cast_sensor` (sensor ``k`` uses ``first_stamp + k``), and
    ``facing`` the segments' free sides (:func:`lidar_env.edge_facing.edge_facing`) or empty."""
    table, order = beams
    total = table.shape[1]
    rows = table.ravel()  # 1-D row slices stay contiguous for numba (2-D ones would not)
    exact = rows[3 * total:4 * total]
    outline = car_outline(car) if car.shape[0] == 5 else np.empty((0, 4))
    for k in range(sensor_poses.shape[0]):
        a, b = int(params[k, FIRST]), int(params[k, END])
        max_range, housing = params[k, MAX_RANGE], params[k, HOUSING]
        pose = (sensor_poses[k, 0], sensor_poses[k, 1], sensor_poses[k, 2] + params[k, OFFSET])
        own = beam_directions(pose[2], rows[a:b], order[a:b], params[k, STEP],
                              rows[total + a:total + b], rows[2 * total + a:2 * total + b],
                              rows[4 * total + a:4 * total + b], rows[5 * total + a:5 * total + b])
        ranges = exact[a:b]
        cast_sensor(ranges, pose, circles, segments, first_polygon_edge, grid, seen,
                    first_stamp + k, own, max_range, facing)
        heading = pose[2] % (2.0 * math.pi)
        if movers.shape[0] > 0:
            cast_movers(ranges, pose[0], pose[1], heading, movers, own, max_range)
        if housing >= 0.0:
            if outline.shape[0] == 0:
                raise ConfigError("car: a self-occluded Lidar needs the car's pose and size "
                                  "(LidarLayout.scan(..., car_pose=...)), got none")
            cast_body(ranges, pose[0], pose[1], outline, housing, own, max_range)
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


@njit(cache=True, fastmath=False)
def readings(exact: NDArray[np.float64], params: NDArray[np.float64],
             gaussians: NDArray[np.float64], uniforms: NDArray[np.float64],
             out: NDArray[np.float32]) -> NDArray[np.float32]:
    """``out`` filled with the float32 readings of packed exact ranges: a hit gets
    ``noise_std * gaussians[j]`` (when drawn and the sensor is noisy) and is clipped to
    ``[0, below_max]``; then a beam with ``uniforms[j] < dropout_prob`` (when drawn) reads
    ``max_range``."""
    noisy, dropping = gaussians.size > 0, uniforms.size > 0
    for k in range(params.shape[0]):
        max_range, below_max = params[k, MAX_RANGE], params[k, BELOW_MAX]
        noise_std, dropout = params[k, NOISE], params[k, DROPOUT]
        for j in range(int(params[k, FIRST]), int(params[k, END])):
            r = exact[j]
            if r < max_range:
                if noisy and noise_std > 0.0:
                    r += noise_std * gaussians[j]
                r = min(max(r, 0.0), below_max)
            if dropping and uniforms[j] < dropout:
                r = max_range
            out[j] = r
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
def scan_packed_kernel(
    world_floats: NDArray[np.float64], world_ints: NDArray[np.int64],
    sensor_poses: NDArray[np.float64], table: NDArray[np.float64], order: NDArray[np.int64],
    params: NDArray[np.float64], gaussians: NDArray[np.float64], uniforms: NDArray[np.float64],
    movers: NDArray[np.float64], car: NDArray[np.float64], out: NDArray[np.float32],
) -> None:
    """:func:`scan_layout_body_kernel` into ``out`` on a world packed by
    :func:`lidar_env.primitive_grid.pack_scan_world` with the segments'
    :func:`lidar_env.edge_facing.edge_facing` codes appended to its ints, whose seen marks it
    keeps using; ``table, order`` are the ``beams`` pair. Numba is handed plain arrays (a
    tuple costs it ~0.4 us, returning an array ~0.5 us), nothing world-sized is zeroed, and
    edges facing away from a sensor are skipped."""
    circles, segments, first_polygon_edge, grid, seen, stamp = unpack_scan_world(
        world_floats, world_ints)
    facing = world_ints[world_ints.shape[0] - segments.shape[0]:]
    exact = cast_packed(circles, segments, first_polygon_edge, grid, sensor_poses,
                        (table, order), params, movers, car, seen, stamp, facing)
    world_ints[STAMP] = stamp + sensor_poses.shape[0]
    readings(exact, params, gaussians, uniforms, out)


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


class LidarLayout:
    """K planar Lidars with no hidden state: ``scan(world, sensor_poses, rng)``.

    Args:
        lidars: 1 or more :class:`LidarConfig` (their mounts are used by the env).
        noise_std, dropout_prob: ``(K,)`` noise [m] and dropout probability per Lidar (the
            env passes each LidarConfig's ``range_noise_std`` and ``dropout_prob``).
        car_size: ``(length, width)`` [m] of the car's rectangle, needed when a Lidar has
            ``self_occlusion``.
    """

    def __init__(
        self, lidars: Sequence[LidarConfig], noise_std: ArrayLike, dropout_prob: ArrayLike,
        car_size: tuple[float, float] | None = None,
    ) -> None:
        self.lidars = tuple(lidars)
        k = len(self.lidars)
        self.noise_std = np.asarray(noise_std, dtype=np.float64).reshape(k)
        self.dropout_prob = np.asarray(dropout_prob, dtype=np.float64).reshape(k)
        self.mounts = np.array([lidar.mount for lidar in self.lidars], dtype=np.float64)
        self.sizes = tuple(lidar.n_beams for lidar in self.lidars)
        ends = np.cumsum(self.sizes).tolist()
        self._slices = tuple(zip([0, *ends[:-1]], ends, strict=True))
        self._noisy = bool(np.any(self.noise_std > 0))
        self._dropping = bool(np.any(self.dropout_prob > 0))
        self.self_occluded = any(lidar.self_occlusion for lidar in self.lidars)
        self.car_size = None if car_size is None else (float(car_size[0]), float(car_size[1]))
        if self.self_occluded and self.car_size is None:
            raise ConfigError("car_size: expected the car's (length, width) [m] for a Lidar "
                              "with self_occlusion, got None")
        self._world_of: tuple = _NO_WORLD

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state.pop("_packed", None)  # numba-friendly arrays, rebuilt on demand
        state.pop("_call", None)
        state["_world_of"] = _NO_WORLD
        return state

    @property
    def beam_angles(self) -> tuple[NDArray[np.float64], ...]:
        """Each Lidar's ``(n_k,)`` beam directions [rad] from its forward axis."""
        return tuple(lidar.beam_angles for lidar in self.lidars)

    @cached_property
    def _packed(self) -> tuple[tuple, NDArray[np.float64]]:
        """``(beams, params)`` as :func:`scan_layout_kernel` takes them."""
        return pack_sensors(
            [lidar.sweep_angles for lidar in self.lidars],
            [(lidar.beam_offset, lidar.max_range, noise, drop,
              lidar.housing_radius if lidar.self_occlusion else -1.0)
             for lidar, noise, drop in zip(self.lidars, self.noise_std, self.dropout_prob,
                                           strict=True)])

    @cached_property
    def _call(self) -> tuple:
        """What :meth:`scan` hands the kernel besides the world and the draws, in one lookup:
        the beam count, the poses' shape, ``beams``, ``params``, and each scan's slice of the
        packed readings (none for one Lidar: it gets them all)."""
        (table, order), params = self._packed
        slices = tuple(slice(a, b) for a, b in self._slices) if len(self._slices) > 1 else ()
        return self._slices[-1][1], self.mounts.shape, table, order, params, slices

    def _packed_world(self, world: World, first_polygon_edge: int) -> tuple:
        """``world`` packed for :func:`scan_packed_kernel` (kept until another world comes)."""
        if self._world_of[0] is not world:
            floats, ints = pack_scan_world(world.circles, world.segments, first_polygon_edge,
                                           world.grid)
            facing = edge_facing(world.segments, first_polygon_edge, tuple(world.grid))
            self._world_of = (world, (floats, np.concatenate([ints, facing])))
        return self._world_of[1]

    def scan(
        self, world: Geometry, sensor_poses: ArrayLike, rng: np.random.Generator,
        movers: NDArray[np.float64] | None = None, car_pose: ArrayLike | None = None,
    ) -> list[NDArray[np.float32]]:
        """The K scans (float32 ``(n_k,)`` ranges [m]) from sensors at world ``sensor_poses``
        (K, 3); every call returns new arrays. ``movers`` (M, 3) are moving circles x, y,
        radius [m] seen like the world's (None: none; the same draws either way).
        ``car_pose`` (x, y, yaw) places the car's outline for Lidars with ``self_occlusion``
        (required then, ignored otherwise)."""
        known, (world_floats, world_ints) = self._world_of
        if world is not known:  # the env's case is the same World step after step
            world_floats, world_ints = self._packed_world(*as_world(world))
        total, shape, table, order, params, slices = self._call
        poses = sensor_poses
        if not (type(poses) is np.ndarray and poses.dtype is _FLOAT64 and poses.shape == shape
                and poses.flags.c_contiguous):
            poses = as_poses(sensor_poses)
            if len(poses) != len(self.lidars):
                raise ConfigError(f"sensor_poses: expected {len(self.lidars)} poses (one per "
                                  f"Lidar), got {len(poses)}")
        if not isinstance(rng, np.random.Generator):
            raise TypeError(f"rng: expected a numpy.random.Generator, got {type(rng).__name__}")
        car = self._car(car_pose) if self.self_occluded else _NO_CAR
        gaussians = rng.standard_normal(total) if self._noisy else _NO_DRAWS
        uniforms = rng.random(total) if self._dropping else _NO_DRAWS
        movers = _NO_MOVERS if movers is None else np.ascontiguousarray(movers, dtype=np.float64)
        packed = np.empty(total, np.float32)
        scan_packed_kernel(world_floats, world_ints, poses, table, order, params, gaussians,
                           uniforms, movers, car, packed)
        return [packed[part] for part in slices] if slices else [packed]

    def _car(self, car_pose: ArrayLike | None) -> NDArray[np.float64]:
        pose = None if car_pose is None else np.asarray(car_pose, dtype=np.float64)
        if pose is None or pose.shape != (3,) or not np.all(np.isfinite(pose)):
            raise ConfigError("car_pose: expected the car's finite world pose (x, y, yaw) for "
                              f"a Lidar with self_occlusion, got {car_pose!r}")
        assert self.car_size is not None
        return np.array([*pose, 0.5 * self.car_size[0], 0.5 * self.car_size[1]])
