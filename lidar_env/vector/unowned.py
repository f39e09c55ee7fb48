"""Array views that own nothing, for the batched kernels' loops over envs.

numba counts references to an array's memory with atomic operations: each array a compiled
function binds to a name, slices or hands to another function costs two (an increment and a
decrement, each a locked instruction that also drains the store buffer), and a scan of one env
binds the scene's, the beam tables' and the scratch's arrays over a hundred times. A view from
:func:`unowned` carries no owner (numba's meminfo is null), so numba skips the count. Only
arrays whose owner outlives every use of the view may be viewed so: a kernel's arguments and
what they hold (the caller holds them for the call), never an array the kernel allocates.
"""

from __future__ import annotations

from typing import Any

from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic
from numba.np.arrayobj import make_array, populate_array


@intrinsic
def unowned(typingctx: object, array: types.Type) -> tuple | None:
    """A view of ``array`` (the same type: its data, shape and strides) owning nothing."""
    if not isinstance(array, types.Array):
        return None

    def codegen(context: Any, builder: ir.IRBuilder, sig: Any, args: list) -> ir.Value:
        source = make_array(array)(context, builder, value=args[0])
        view = make_array(array)(context, builder)
        populate_array(view, data=source.data, shape=source.shape, strides=source.strides,
                       itemsize=source.itemsize, meminfo=None)
        return view._getvalue()

    return array(array), codegen


@njit(cache=True, inline="always")
def unowned_grid(grid: tuple) -> tuple:
    """A :class:`~lidar_env.world.primitive_grid.PrimitiveGrid` as a plain tuple of its fields,
    its four arrays :func:`unowned`."""
    return (grid[0], grid[1], grid[2], grid[3], grid[4], unowned(grid[5]), unowned(grid[6]),
            unowned(grid[7]), unowned(grid[8]))


@njit(cache=True, inline="always")
def unowned_scene(item: tuple) -> tuple:
    """One env's scene item (:attr:`lidar_env.vector.slots.SceneSlots.scene`'s ``items[i]``)
    as unowned views: ``(circles, segments, grid, waypoints, trace_arc)``, the grid as
    :func:`unowned_grid`'s tuple."""
    return (unowned(item[0]), unowned(item[1]), unowned_grid(item[2]), unowned(item[3]),
            unowned(item[4]))
