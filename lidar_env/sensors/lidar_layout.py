"""Several Lidars of their own geometry scanned in one compiled call: the one sensor kernel.

:class:`LidarLayout` holds K Lidars (:class:`~lidar_env.sensors.lidar_config.LidarConfig`: mount,
beams over a field of view, max range, noise, dropouts, self-occlusion) and :meth:`LidarLayout.scan`
returns their K float32 scans from one call of :func:`scan_packed_kernel`. Every scan of the
package goes through :func:`lidar_env.sensors.layout_kernels.cast_packed` (exact ranges, movers, the
car's own outline) and :func:`lidar_env.sensors.layout_kernels.readings` (noise, clipping, dropouts,
float32); :class:`lidar_env.sensors.lidar.Lidar` and :func:`lidar_env.sensors.lidar.cast_rays` pack
their identical sensors the same way (:func:`lidar_env.sensors.lidar_config.pack_sensors`). The
kernels differ only in how the world comes: :func:`scan_packed_kernel` takes the world and the
layout packed together once per world (:meth:`LidarLayout.pack`: the world as
:func:`lidar_env.world.primitive_grid.pack_scan_world` packs it, the edges' free sides for back-face
culling, the beams, and room for the car and the draws), so numba is handed five arrays;
:func:`lidar_env.sensors.layout_kernels.scan_layout_body_kernel` takes it as arrays and a grid.

Random numbers: if any Lidar is noisy, one standard normal per beam of every Lidar (in sensor
order), then, if any has dropouts, one uniform per beam; so a layout of identical Lidars
consumes the stream exactly as :meth:`lidar_env.sensors.lidar.Lidar.scan` does, and the same seed
gives the same scans bit for bit.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from functools import cached_property

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from lidar_env.core.errors import ArgumentTypeError, ConfigError
from lidar_env.sensors.edge_facing import edge_facing
from lidar_env.sensors.layout_kernels import (
    car_outline,
    cast_packed,
    exact_ranges_kernel,
    fresh_seen,
    readings,
    scan_layout_body_kernel,
    scan_layout_kernel,
)
from lidar_env.sensors.lidar_config import PARAM_COLUMNS, LidarConfig, pack_sensors
from lidar_env.world.primitive_grid import STAMP, pack_scan_world, unpack_scan_world
from lidar_env.world.world import World

__all__ = ["Geometry", "LidarLayout", "as_poses", "as_world", "car_outline", "cast_packed",
           "exact_ranges_kernel", "fresh_seen", "readings", "scan_layout_body_kernel",
           "scan_layout_kernel", "scan_packed_kernel"]

Geometry = World | tuple[ArrayLike, ArrayLike]

_NO_MOVERS = np.empty((0, 3))
_NO_WORLD = (None,) * 6  # LidarLayout._world_of before the first scan
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
        raise ArgumentTypeError(
            "world_or_arrays: expected a World or a (circles (N,3), segments (M,4)) tuple, "
            f"got {type(world_or_arrays).__name__}"
        )
    world = World(*world_or_arrays, bounds=(0.0, 0.0, 1.0, 1.0))
    return world, len(world.segments)


#: The last ints of :meth:`LidarLayout.pack`: where the beam table, the params, the car and
#: the Gaussian and uniform draws start in the floats, where the beam order starts in the ints
#: (the segments' free sides end there), the car's length (5 or 0) and which draws are made
#: (bit 0 Gaussians, bit 1 uniforms).
TABLE_AT, PARAMS_AT, CAR_AT, GAUSSIANS_AT, UNIFORMS_AT, ORDER_AT, CAR_SIZE, DRAWN = range(8)
_TAIL = 8


@njit(cache=True, fastmath=False)
def scan_packed_kernel(floats: NDArray[np.float64], ints: NDArray[np.int64],
                       sensor_poses: NDArray[np.float64], movers: NDArray[np.float64],
                       out: NDArray[np.float32]) -> None:
    """:func:`lidar_env.sensors.layout_kernels.scan_layout_body_kernel` into ``out`` (float32, one
    per packed beam) for a world and layout packed by :meth:`LidarLayout.pack`, whose seen
    marks it keeps using (nothing world-sized is zeroed) and whose polygon edges facing away
    from a sensor it skips. Five arrays: numba takes each ~0.04 us, a tuple ~0.4 us."""
    circles, segments, first_polygon_edge, grid, seen, stamp = unpack_scan_world(floats, ints)
    tail = ints[ints.shape[0] - _TAIL:]
    total, k = out.shape[0], sensor_poses.shape[0]
    order_at = tail[ORDER_AT]
    table = floats[tail[TABLE_AT]:tail[TABLE_AT] + 6 * total].reshape((6, total))
    params = floats[tail[PARAMS_AT]:tail[PARAMS_AT] + PARAM_COLUMNS * k].reshape(
        (k, PARAM_COLUMNS))
    gaussians = floats[tail[GAUSSIANS_AT]:tail[GAUSSIANS_AT] + total * (tail[DRAWN] & 1)]
    uniforms = floats[tail[UNIFORMS_AT]:tail[UNIFORMS_AT] + total * (tail[DRAWN] >> 1)]
    exact = cast_packed(circles, segments, first_polygon_edge, grid, sensor_poses,
                        (table, ints[order_at:order_at + total]), params, movers,
                        floats[tail[CAR_AT]:tail[CAR_AT] + tail[CAR_SIZE]], seen, stamp,
                        ints[order_at - segments.shape[0]:order_at])
    ints[STAMP] = stamp + k
    readings(exact, params, gaussians, uniforms, out)


class LidarLayout:
    """K planar Lidars with no hidden state: ``scan(world, sensor_poses, rng)``.

    Args:
        lidars: 1 or more :class:`LidarConfig`, each with its mount, beams, range, noise and
            dropout (:meth:`exact`: the same without noise and dropout).
        car_size: ``(length, width)`` [m] of the car's rectangle, needed when a Lidar has
            ``self_occlusion``.
    """

    def __init__(
        self, lidars: Sequence[LidarConfig], car_size: tuple[float, float] | None = None,
    ) -> None:
        self.lidars = tuple(lidars)
        self.noise_std = np.array([lidar.range_noise_std for lidar in self.lidars])
        self.dropout_prob = np.array([lidar.dropout_prob for lidar in self.lidars])
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

    @classmethod
    def exact(cls, lidars: Sequence[LidarConfig],
              car_size: tuple[float, float] | None = None) -> LidarLayout:
        """The layout of ``lidars`` without range noise or dropouts: the exact ranges (what
        pymunk's ray queries give, to float32)."""
        return cls([dataclasses.replace(lidar, range_noise_std=0.0, dropout_prob=0.0)
                    for lidar in lidars], car_size)

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
              lidar.housing_radius if lidar.self_occlusion else -1.0, lidar.min_range)
             for lidar, noise, drop in zip(self.lidars, self.noise_std, self.dropout_prob,
                                           strict=True)])

    @cached_property
    def _call(self) -> tuple:
        """What :meth:`scan` needs besides the world, in one lookup: the beam count, the poses'
        shape, and each scan's slice of the packed readings (none for one Lidar: all)."""
        slices = tuple(slice(a, b) for a, b in self._slices) if len(self._slices) > 1 else ()
        return self._slices[-1][1], self.mounts.shape, slices

    def pack(self, world: Geometry) -> tuple:
        """``(world, floats, ints, gaussians, uniforms, car)``: ``world`` and this layout as
        :func:`scan_packed_kernel` takes them (kept until another world comes), and the views
        of ``floats`` that :meth:`scan` fills with the draws and the car's pose and half sizes.

        ``floats``: the world's floats (:func:`lidar_env.world.primitive_grid.pack_scan_world`), the
        beam table (6, n) and params (K, ``PARAM_COLUMNS``) of
        :func:`lidar_env.sensors.lidar_config.pack_sensors`, the car (5 or none), the Gaussians and
        the uniforms (n each, or none). ``ints``: the
        world's ints, the segments' free sides (:func:`lidar_env.sensors.edge_facing.edge_facing`),
        the beam order (n) and the tail (see :data:`TABLE_AT`)."""
        if self._world_of[0] is not world:  # a tuple of arrays becomes a new World each time
            scanned, first_polygon_edge = as_world(world)
            world_floats, world_ints = pack_scan_world(
                scanned.circles, scanned.segments, first_polygon_edge, scanned.grid)
            facing = edge_facing(scanned.segments, first_polygon_edge, tuple(scanned.grid))
            (table, order), params = self._packed
            total = table.shape[1]
            sizes = [len(world_floats), table.size, params.size, 5 * self.self_occluded,
                     total * self._noisy, total * self._dropping]
            starts = np.cumsum([0, *sizes])
            floats = np.concatenate([world_floats, table.ravel(), params.ravel(),
                                     np.zeros(sum(sizes[3:]))])
            order_at = len(world_ints) + len(facing)
            tail = [*starts[1:6], order_at, sizes[3], self._noisy + 2 * self._dropping]
            ints = np.concatenate([world_ints, facing, order, tail]).astype(np.int64)
            car, gaussians, uniforms = (floats[starts[i]:starts[i + 1]] for i in (3, 4, 5))
            self._world_of = (scanned, floats, ints, gaussians, uniforms, car)
        return self._world_of

    def scan(
        self, world: Geometry, sensor_poses: ArrayLike, rng: np.random.Generator,
        movers: NDArray[np.float64] | None = None, car_pose: ArrayLike | None = None,
    ) -> list[NDArray[np.float32]]:
        """The K scans (float32 ``(n_k,)`` ranges [m]) from sensors at world ``sensor_poses``
        (K, 3); every call returns new arrays. ``movers`` (M, 3) are moving circles x, y,
        radius [m] seen like the world's (None: none; the same draws either way).
        ``car_pose`` (x, y, yaw) places the car's outline for Lidars with ``self_occlusion``
        (required then, ignored otherwise)."""
        known, floats, ints, gaussians, uniforms, car = self._world_of
        if world is not known:  # the env's case is the same World step after step
            known, floats, ints, gaussians, uniforms, car = self.pack(world)
        total, shape, slices = self._call
        poses = sensor_poses
        if not (type(poses) is np.ndarray and poses.dtype is _FLOAT64 and poses.shape == shape
                and poses.flags.c_contiguous):
            poses = as_poses(sensor_poses)
            if len(poses) != len(self.lidars):
                raise ConfigError(f"sensor_poses: expected {len(self.lidars)} poses (one per "
                                  f"Lidar), got {len(poses)}")
        if not isinstance(rng, np.random.Generator):
            raise ArgumentTypeError(
                f"rng: expected a numpy.random.Generator, got {type(rng).__name__}")
        if self.self_occluded:
            car[:] = self._car(car_pose)
        if self._noisy:
            rng.standard_normal(out=gaussians)
        if self._dropping:
            rng.random(out=uniforms)
        movers = _NO_MOVERS if movers is None else np.ascontiguousarray(movers, dtype=np.float64)
        packed = np.empty(total, np.float32)
        scan_packed_kernel(floats, ints, poses, movers, packed)
        return [packed[part] for part in slices] if slices else [packed]

    def _car(self, car_pose: ArrayLike | None) -> NDArray[np.float64]:
        pose = None if car_pose is None else np.asarray(car_pose, dtype=np.float64)
        if pose is None or pose.shape != (3,) or not np.all(np.isfinite(pose)):
            raise ConfigError("car_pose: expected the car's finite world pose (x, y, yaw) for "
                              f"a Lidar with self_occlusion, got {car_pose!r}")
        assert self.car_size is not None
        return np.array([*pose, 0.5 * self.car_size[0], 0.5 * self.car_size[1]])
