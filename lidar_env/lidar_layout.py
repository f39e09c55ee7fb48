"""Several Lidars of their own geometry scanned in one compiled call (the env's sensor layout).

:class:`LidarLayout` holds K Lidars (:class:`~lidar_env.lidar_config.LidarConfig`: mount, beams
over a field of view, max range, noise, dropouts) and :meth:`LidarLayout.scan` returns their K
float32 scans from one call of :func:`scan_layout_kernel`, which casts every sensor with
:func:`lidar_env.ray_casting.cast_sensor` and applies noise, clipping and dropouts in the same
pass. The beams of all sensors are packed end to end (sensor ``k`` owns positions
``[beam_start[k], beam_start[k + 1])``). Moving obstacles (circles that change every step, so
they are not in the world's grid) are passed to :func:`scan_layout_movers_kernel` as an
``(M, 3)`` array and cast by :func:`cast_movers` with the static circles' subtended-interval
sweep, exactly; :func:`scan_layout_kernel` is that kernel without movers.

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

from lidar_env.errors import ConfigError
from lidar_env.lidar import Geometry, as_poses, as_world
from lidar_env.lidar_config import LidarConfig
from lidar_env.primitive_grid import PrimitiveGrid
from lidar_env.ray_casting import beam_geometry, cast_sensor, new_scratch, sweep_circle

_NO_DRAWS = np.empty(0)


@njit(cache=True, fastmath=False)
def cast_movers(
    ranges: NDArray[np.float64],
    pose: tuple[float, float, float],
    movers: NDArray[np.float64],
    beams: tuple,
    max_range: float,
) -> None:
    """Lower ``ranges`` (n,) of one sensor at world ``pose`` to the exact hits on the moving
    circles ``movers`` (M, 3: x, y, radius [m]); all 0 when the sensor is inside one.

    ``beams`` is ``(sorted_angles, order, step, cos, sin)`` as for
    :func:`lidar_env.ray_casting.cast_sensor`. Each circle updates only the beams within the
    angle it subtends (the static circles' sweep), so M circles cost about M beams each.
    """
    ox, oy, heading = pose
    sorted_angles, order, step, cos_beam, sin_beam = beams
    ch, sh = math.cos(heading), math.sin(heading)
    heading = heading % (2.0 * math.pi)
    for i in range(movers.shape[0]):
        if not sweep_circle(ranges, ox, oy, ch, sh, heading, movers[i, 0], movers[i, 1],
                            movers[i, 2], sorted_angles, order, step, cos_beam, sin_beam,
                            max_range):
            return


@njit(cache=True, fastmath=False)
def scan_layout_kernel(
    circles: NDArray[np.float64],
    segments: NDArray[np.float64],
    first_polygon_edge: int,
    grid: PrimitiveGrid,
    sensor_poses: NDArray[np.float64],
    beams: tuple,
    sensor_params: NDArray[np.float64],
    gaussians: NDArray[np.float64],
    uniforms: NDArray[np.float64],
) -> NDArray[np.float32]:
    """Packed float32 readings of K sensors at world ``sensor_poses`` (K, 3).

    ``beams`` is ``(beam_start (K+1,), sorted_angles, order, steps (K,), cos, sin)``, each
    sensor's part as :func:`lidar_env.ray_casting.beam_geometry` gives it; ``sensor_params``
    (K, 5) holds per sensor: angle of beam 0 from forward [rad], max range [m], the largest
    float32 below it, noise std [m], dropout probability. ``gaussians`` and ``uniforms`` hold
    one draw per packed beam, or are empty when no sensor needs them.
    """
    return scan_layout_movers_kernel(circles, segments, first_polygon_edge, grid, sensor_poses,
                                     beams, sensor_params, gaussians, uniforms,
                                     np.empty((0, 3)))


@njit(cache=True, fastmath=False)
def scan_layout_movers_kernel(
    circles: NDArray[np.float64],
    segments: NDArray[np.float64],
    first_polygon_edge: int,
    grid: PrimitiveGrid,
    sensor_poses: NDArray[np.float64],
    beams: tuple,
    sensor_params: NDArray[np.float64],
    gaussians: NDArray[np.float64],
    uniforms: NDArray[np.float64],
    movers: NDArray[np.float64],
) -> NDArray[np.float32]:
    """:func:`scan_layout_kernel` in a world that also holds the moving circles ``movers``
    (M, 3: x, y, radius [m]), seen exactly like static ones (:func:`cast_movers`)."""
    beam_start, sorted_angles, order, steps, cos_beam, sin_beam = beams
    exact = np.empty(beam_start[-1])
    out = np.empty(beam_start[-1], dtype=np.float32)
    scratch = new_scratch(circles, segments)
    noisy, dropping = gaussians.size > 0, uniforms.size > 0
    for k in range(sensor_poses.shape[0]):
        a, b = beam_start[k], beam_start[k + 1]
        offset, max_range, below_max, noise_std, dropout = sensor_params[k]
        pose = (sensor_poses[k, 0], sensor_poses[k, 1], sensor_poses[k, 2] + offset)
        own = (sorted_angles[a:b], order[a:b], steps[k], cos_beam[a:b], sin_beam[a:b])
        cast_sensor(exact[a:b], pose, circles, segments, first_polygon_edge, grid, scratch,
                    k + 1, own, max_range)
        if movers.shape[0] > 0:
            cast_movers(exact[a:b], pose, movers, own, max_range)
        for j in range(a, b):
            r = exact[j]
            if r < max_range:
                if noisy and noise_std > 0.0:
                    r += noise_std * gaussians[j]
                r = min(max(r, 0.0), below_max)
            if dropping and uniforms[j] < dropout:
                r = max_range
            out[j] = r
    return out


class LidarLayout:
    """K planar Lidars with no hidden state: ``scan(world, car_pose_or_sensor_poses, rng)``.

    Args:
        lidars: 1 or more :class:`LidarConfig` (their mounts are used by :meth:`sensor_poses`).
        noise_std, dropout_prob: ``(K,)`` noise [m] and dropout probability per Lidar (the
            config's per-Lidar values resolved against its env-wide defaults).
    """

    def __init__(
        self, lidars: Sequence[LidarConfig], noise_std: ArrayLike, dropout_prob: ArrayLike
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

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state.pop("_packed", None)  # numba-friendly arrays, rebuilt on demand
        return state

    @property
    def beam_angles(self) -> tuple[NDArray[np.float64], ...]:
        """Each Lidar's ``(n_k,)`` beam directions [rad] from its forward axis."""
        return tuple(lidar.beam_angles for lidar in self.lidars)

    @cached_property
    def _packed(self) -> tuple[tuple, NDArray[np.float64]]:
        parts = [beam_geometry(np.ascontiguousarray(lidar.sweep_angles).tobytes())
                 for lidar in self.lidars]
        beam_start = np.concatenate([[0], np.cumsum(self.sizes)]).astype(np.int64)
        beams = (beam_start,
                 np.concatenate([p[0] for p in parts]),
                 np.concatenate([p[1] for p in parts]).astype(np.int64),
                 np.array([p[2] for p in parts], dtype=np.float64),
                 np.concatenate([p[3] for p in parts]),
                 np.concatenate([p[4] for p in parts]))
        params = np.array([
            (lidar.beam_offset, lidar.max_range,
             float(np.nextafter(np.float32(lidar.max_range), np.float32(0.0))), noise, drop)
            for lidar, noise, drop in zip(self.lidars, self.noise_std, self.dropout_prob,
                                          strict=True)], dtype=np.float64)
        return beams, params

    def scan(
        self, world: Geometry, sensor_poses: ArrayLike, rng: np.random.Generator,
        movers: NDArray[np.float64] | None = None,
    ) -> list[NDArray[np.float32]]:
        """The K scans (float32 ``(n_k,)`` ranges [m]) from sensors at world ``sensor_poses``
        (K, 3); every call returns new arrays. ``movers`` (M, 3) are moving circles x, y,
        radius [m] seen like the world's (None: none; the same draws either way)."""
        world, first_polygon_edge = as_world(world)
        poses = as_poses(sensor_poses)
        if len(poses) != len(self.lidars):
            raise ConfigError(f"sensor_poses: expected {len(self.lidars)} poses (one per Lidar), "
                             f"got {len(poses)}")
        if not isinstance(rng, np.random.Generator):
            raise TypeError(f"rng: expected a numpy.random.Generator, got {type(rng).__name__}")
        total = self._slices[-1][1]
        gaussians = rng.standard_normal(total) if self._noisy else _NO_DRAWS
        uniforms = rng.random(total) if self._dropping else _NO_DRAWS
        beams, params = self._packed
        if movers is None:
            packed = scan_layout_kernel(world.circles, world.segments, first_polygon_edge,
                                        world.grid, poses, beams, params, gaussians, uniforms)
        else:
            packed = scan_layout_movers_kernel(
                world.circles, world.segments, first_polygon_edge, world.grid, poses, beams,
                params, gaussians, uniforms, np.ascontiguousarray(movers, dtype=np.float64))
        return [packed[a:b] for a, b in self._slices]
