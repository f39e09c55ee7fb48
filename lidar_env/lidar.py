"""Exact planar Lidar: analytic ray casting against circles and segments, compiled with numba.

:func:`cast_rays` computes the scans of several sensors in one call with an analytic sweep of
the primitives near each sensor (see :mod:`lidar_env.ray_casting`, which holds the compiled
kernels), so large maps (thousands of edges traced from an image) cost little more than small
ones. :class:`Lidar` is the sensor model (beams, range, noise, dropouts) on top of it, and
:func:`pymunk_cast_rays` the slow independent reference.

Speed (``python benchmarks/bench_lidar.py``, one AMD EPYC core): ~13 us per dual 360-beam scan
on 144 primitives and ~20 us on 304, 85-120x faster than a per-beam pymunk ray query loop.
:meth:`Lidar.scan` adds noise, clipping, dropouts and the float32 conversion in the same compiled
pass; with noise, its main extra cost is numpy drawing the Gaussian numbers (~6 us for 2 x 360).

Conventions: a pose is ``(x [m], y [m], heading [rad])`` in the world; beam ``j`` of sensor
``k`` points at world angle ``sensor_poses[k, 2] + beam_angles[j]``; a beam that hits nothing
within ``max_range`` reads ``max_range``. A sensor inside a circle or a polygon, or touching a
wall, reads ``0.0`` on every beam (it is blind, and the reading is unambiguous).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lidar_env.errors import ConfigError
from lidar_env.ray_casting import beam_geometry, cast_rays_kernel, scan_kernel
from lidar_env.world import World

Geometry = World | tuple[ArrayLike, ArrayLike]

#: Stands in for the random draws of a Lidar without noise or dropout (the kernel skips them).
#: Writeable like real draws, so the kernel compiles once for every combination; being empty,
#: it cannot be written to.
_NO_DRAWS = np.empty((0, 0))


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


def cast_rays(
    world_or_arrays: Geometry,
    sensor_poses: ArrayLike,
    beam_angles: ArrayLike,
    max_range: float,
) -> NDArray[np.float64]:
    """Exact range [m] of every beam of every sensor.

    Args:
        world_or_arrays: a :class:`World`, or a tuple ``(circles (N,3), segments (M,4))`` whose
            segments are all treated as walls (no polygon interiors).
        sensor_poses: ``(K, 3)`` (or ``(3,)``) world pose of each sensor.
        beam_angles: ``(n,)`` beam directions [rad], counter-clockwise from sensor forward.
        max_range: [m], positive; beams that hit nothing closer read exactly ``max_range``.

    Returns:
        ``(K, n)`` float64 ranges [m] in ``[0, max_range]``; all ``0.0`` for a sensor inside an
        obstacle or touching a wall.

    Pass a :class:`World` when scanning repeatedly: a tuple is turned into one (validated, with
    its grid built) on every call.

    Example:
        >>> world = World(circles=[[5.0, 0.0, 1.0]])
        >>> cast_rays(world, [0.0, 0.0, 0.0], np.array([0.0, np.pi / 2]), 10.0)
        array([[ 4., 10.]])
    """
    world, first_polygon_edge = as_world(world_or_arrays)
    poses = as_poses(sensor_poses)
    angles = np.asarray(beam_angles, dtype=np.float64)
    if angles.ndim != 1:
        raise ConfigError(
            f"beam_angles: expected a non-empty finite 1-D array [rad], got shape {angles.shape}"
        )
    max_range = float(max_range)
    if not (math.isfinite(max_range) and max_range > 0):
        raise ConfigError(f"max_range: expected a positive finite number [m], got {max_range}")
    beams = beam_geometry(angles.tobytes())
    # The kernel itself rejects non-finite poses: checking here would cost more than a scan.
    return cast_rays_kernel(
        world.circles, world.segments, first_polygon_edge, world.grid, poses, beams, max_range
    )


def pymunk_cast_rays(
    space: Any, sensor_poses: ArrayLike, beam_angles: ArrayLike, max_range: float
) -> NDArray[np.float64]:
    """The slow reference for :func:`cast_rays`: one pymunk ``segment_query_first`` per beam.

    ``space`` is a ``pymunk.Space`` (e.g. ``World.build_space()``); arguments and result are as
    in :func:`cast_rays`. Tests use it as the independent oracle, benchmarks as the baseline.
    """
    import pymunk

    every_shape = pymunk.ShapeFilter()
    poses = as_poses(sensor_poses)
    angles = np.asarray(beam_angles, dtype=np.float64)
    out = np.full((len(poses), len(angles)), float(max_range))
    for k, (x, y, heading) in enumerate(poses):
        for j, angle in enumerate(angles):
            direction = heading + angle
            end = (x + max_range * math.cos(direction), y + max_range * math.sin(direction))
            hit = space.segment_query_first((x, y), end, 0.0, every_shape)
            if hit is not None:
                out[k, j] = hit.alpha * max_range
    return out


@dataclass(frozen=True)
class Lidar:
    """A planar Lidar model with no hidden state.

    Attributes:
        n_beams: beams per revolution; beam ``i`` points at ``2 pi i / n_beams`` [rad] CCW from
            the sensor's forward axis.
        max_range: [m]; a beam that hits nothing (or drops out) reads ``max_range``.
        noise_std: standard deviation [m] of the Gaussian noise added to each hit.
        dropout_prob: probability that a beam returns nothing.
    """

    n_beams: int = 360
    max_range: float = 10.0
    noise_std: float = 0.0
    dropout_prob: float = 0.0

    def __post_init__(self) -> None:
        if isinstance(self.n_beams, bool) or int(self.n_beams) != self.n_beams or self.n_beams < 1:
            raise ConfigError(f"n_beams: expected a positive integer, got {self.n_beams!r}")
        if not (np.isfinite(self.max_range) and self.max_range > 0):
            raise ConfigError(
                f"max_range: expected a positive finite number [m], got {self.max_range}"
            )
        if not (np.isfinite(self.noise_std) and self.noise_std >= 0):
            raise ConfigError(f"noise_std: expected a finite number >= 0 [m], got {self.noise_std}")
        if not 0.0 <= self.dropout_prob <= 1.0:
            raise ConfigError(
                f"dropout_prob: expected a probability in [0, 1], got {self.dropout_prob}"
            )
        object.__setattr__(self, "n_beams", int(self.n_beams))
        # plain floats, so the compiled kernel sees one signature whatever numbers were given
        for name in ("max_range", "noise_std", "dropout_prob"):
            object.__setattr__(self, name, float(getattr(self, name)))

    @cached_property
    def beam_angles(self) -> NDArray[np.float64]:
        """``(n_beams,)`` beam directions [rad] in the sensor frame, ``2 pi i / n``."""
        angles = 2.0 * math.pi * np.arange(self.n_beams) / self.n_beams
        angles.flags.writeable = False
        return angles

    @cached_property
    def _beams(self) -> tuple:
        """The kernel's beam geometry (see :func:`beam_geometry`), looked up once."""
        return beam_geometry(self.beam_angles.tobytes())

    @cached_property
    def _below_max(self) -> float:
        """The largest float32 below ``max_range``: a hit must never round up to "no return"."""
        return float(np.nextafter(np.float32(self.max_range), np.float32(0.0)))

    def scan(
        self, world: Geometry, sensor_poses: ArrayLike, rng: np.random.Generator
    ) -> NDArray[np.float32]:
        """``(K, n_beams)`` float32 ranges [m] from sensors at world poses ``(K, 3)``.

        Exact ranges, then (only if ``noise_std > 0``) Gaussian noise on the hits, clipped to
        ``[0, max_range)``, then (only if ``dropout_prob > 0``) dropouts set to ``max_range``.
        Random numbers are drawn for every beam in that fixed order (all ``K x n`` standard
        normals, then all ``K x n`` uniforms), so the stream consumed depends only on the shape;
        a noiseless Lidar consumes none. Every call returns a new array.
        """
        world, first_polygon_edge = as_world(world)
        poses = as_poses(sensor_poses)
        shape = (poses.shape[0], self.n_beams)
        # Drawn by numpy from the caller's generator (numba would take it only at a cost of
        # several microseconds per call), then applied in the same compiled pass as the cast.
        gaussians = _check_rng(rng).standard_normal(shape) if self.noise_std > 0 else _NO_DRAWS
        uniforms = _check_rng(rng).random(shape) if self.dropout_prob > 0 else _NO_DRAWS
        return scan_kernel(
            world.circles, world.segments, first_polygon_edge, world.grid, poses, self._beams,
            self.max_range, self._below_max, self.noise_std, gaussians, self.dropout_prob,
            uniforms,
        )


def _check_rng(rng: object) -> np.random.Generator:
    if not isinstance(rng, np.random.Generator):
        raise TypeError(f"rng: expected a numpy.random.Generator, got {type(rng).__name__}")
    return rng
