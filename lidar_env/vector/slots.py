"""Each env's scene and random generator, laid out for the compiled step of
:mod:`lidar_env.vector.kernel`.

Env ``i``'s obstacles, their :class:`~lidar_env.world.primitive_grid.PrimitiveGrid`, its trace and
its generator's PCG64 state (:func:`lidar_env.vector.draws.state_words`, a view that keeps the
generator alive) are one tuple, item ``i`` of a numba typed list (numba unboxes a typed list
argument at every call, ~0.8 us, so there is one); the scalars (first polygon edge, closed trace,
trace length [m]) are ``(N,)`` arrays. Items are views of the World's and Trace's own arrays (made
read-only, so every item has one numba type), never copies: N envs in one built-in world hold
one copy of it.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit
from numba.typed import List
from numpy.typing import DTypeLike, NDArray

from lidar_env.routes.trace_geometry import Trace
from lidar_env.vector.draws import state_address, state_words
from lidar_env.world.primitive_grid import PrimitiveGrid
from lidar_env.world.world import World


def _read_only(array: Any, dtype: DTypeLike, columns: int | None = None) -> NDArray:
    """A read-only, C-contiguous view (a copy only if the dtype or layout differs)."""
    view = np.ascontiguousarray(array, dtype=dtype)
    view = view.reshape(-1, columns) if columns is not None else view.view()
    view.flags.writeable = False
    return view


@njit(cache=True)
def _filled_list(item: Any, n: int) -> Any:
    """A numba typed list of ``n`` times ``item``, built compiled: typed-list operations from
    Python are compiled anew in every process (~1 s per item type), these are cached."""
    values = List()
    for _ in range(n):
        values.append(item)
    return values


@njit(cache=True)
def _set_item(values: Any, i: int, item: Any) -> None:
    values[i] = item


def _kernel_grid(grid: PrimitiveGrid) -> PrimitiveGrid:
    """``grid`` with Python scalars and read-only int64 arrays: one numba type for all envs."""
    return PrimitiveGrid(float(grid.x0), float(grid.y0), float(grid.cell), int(grid.nx),
                         int(grid.ny), *(_read_only(a, np.int64) for a in grid[5:]))


class SceneSlots:
    """The scenes and generators of ``n`` envs, as the kernel reads them (``.scene``).

    The typed list is filled once the first env has both a scene (:meth:`set`) and a generator
    (:meth:`set_generator`), every item a copy of that env's until each env's own is set, so
    all ``n`` envs must be set before the kernel runs.
    """

    def __init__(self, n: int) -> None:
        self.n = n
        self.worlds: list[World | None] = [None] * n
        self.traces: list[Trace | None] = [None] * n
        self.generators: list[np.random.Generator | None] = [None] * n
        self.first_edge = np.zeros(n, dtype=np.int64)
        self.closed = np.zeros(n, dtype=np.bool_)
        self.length = np.ones(n, dtype=np.float64)  # [m]
        # which world and trace each env holds (their ids: unique among the live ones), so a
        # kernel takes an item from the typed list (~50 us a thousand) only when it changes
        self.world_key = np.zeros(n, dtype=np.int64)
        self.trace_key = np.zeros(n, dtype=np.int64)
        #: seen marks for the casts (lidar_env.sensors.ray_casting.cast_sensor), as long as the
        #: largest world's circles and segments, and the next free stamp (stamps only grow,
        #: so the marks are never cleared); room for the obstacles near a car [m]
        self.circle_seen = np.zeros(0, dtype=np.int64)
        self.segment_seen = np.zeros(0, dtype=np.int64)
        self.near_circles, self.near_segments = np.zeros((0, 3)), np.zeros((0, 4))
        self.stamp = np.ones(1, dtype=np.int64)
        #: each env's generator state by address (lidar_env.vector.draws.words_at), valid while
        #: ``generators`` holds it
        self.state_addresses = np.zeros(n, dtype=np.uint64)
        self._parts: list[tuple | None] = [None] * n  # each env's item but its generator's
        self._items: Any = None

    def set(self, i: int, world: World, trace: Trace) -> None:
        """Env ``i`` now drives ``trace`` in ``world``."""
        if self.worlds[i] is world and self.traces[i] is trace:
            return
        self._parts[i] = (_read_only(world.circles, np.float64, 3),
                          _read_only(world.segments, np.float64, 4),
                          _kernel_grid(world.grid),
                          _read_only(trace.waypoints, np.float64, 2),
                          _read_only(trace.arc, np.float64))
        self.worlds[i], self.traces[i] = world, trace
        self._store(i)
        if len(world.circles) > len(self.circle_seen):
            self.circle_seen = np.zeros(len(world.circles), dtype=np.int64)
            self.near_circles = np.zeros((len(world.circles), 3))
        if len(world.segments) > len(self.segment_seen):
            self.segment_seen = np.zeros(len(world.segments), dtype=np.int64)
            self.near_segments = np.zeros((len(world.segments), 4))
        self.first_edge[i] = len(world.walls)
        self.closed[i] = trace.closed
        self.world_key[i], self.trace_key[i] = id(world), id(trace)
        self.length[i] = trace.length

    def __getstate__(self) -> dict[str, Any]:
        # numba's typed lists do not pickle: they are rebuilt from the worlds, traces and
        # generators (which pickle with their states, shared items staying shared)
        return {**self.__dict__, "_items": None}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        worlds, traces, generators = self.worlds, self.traces, self.generators
        self.state_addresses = np.zeros(self.n, dtype=np.uint64)  # another process's are void
        self.worlds, self.traces = [None] * self.n, [None] * self.n
        for i, (world, trace, rng) in enumerate(zip(worlds, traces, generators, strict=True)):
            if world is not None and trace is not None:
                self.set(i, world, trace)
            if rng is not None:
                self.set_generator(i, rng)

    def set_generator(self, i: int, rng: np.random.Generator) -> None:
        """Env ``i`` draws from ``rng``, a PCG64 generator (the kernel advances its state, as
        numpy would)."""
        self.generators[i] = rng
        self.state_addresses[i] = state_address(rng)
        self._store(i)

    def _store(self, i: int) -> None:
        """Env ``i``'s item into the typed list, once it has a scene and a generator."""
        parts, rng = self._parts[i], self.generators[i]
        if parts is None or rng is None:
            return
        if self._items is None:
            self._items = _filled_list((*parts, state_words(rng)), self.n)
        else:
            _set_item(self._items, i, (*parts, state_words(rng)))

    @property
    def scene(self) -> tuple:
        """``(items, first_polygon_edge, closed, length, world_key, trace_key, state_addresses)``:
        a typed list of ``(circles, segments, grid, waypoints, arc, generator state words)`` per
        env and (N,) arrays; envs of equal ``world_key`` (``trace_key``) hold the same world
        (trace) arrays; the kernels take each env's generator state by its address (taking an
        item from the typed list costs some 30 reference counts)."""
        assert self._items is not None, "set every env's scene first"
        return (self._items, self.first_edge, self.closed, self.length, self.world_key,
                self.trace_key, self.state_addresses)

    def nbytes(self) -> int:
        """Bytes of the per-env arrays, counting each distinct world and trace once."""
        seen: dict[int, int] = {}
        for world, trace in zip(self.worlds, self.traces, strict=True):
            if world is not None:
                seen[id(world)] = (world.circles.nbytes + world.segments.nbytes
                                   + sum(a.nbytes for a in world.grid[5:]))
            if trace is not None:
                seen[id(trace)] = trace.waypoints.nbytes + trace.arc.nbytes + trace.headings.nbytes
        return sum(seen.values()) + self.first_edge.nbytes + self.closed.nbytes + self.length.nbytes
