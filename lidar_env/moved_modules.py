"""The module paths of the flat ``lidar_env`` layout (0.1.0), still importable for one release.

``import lidar_env.traces`` (or ``from lidar_env.se2 import compose``) returns the module at its
new path, ``lidar_env.routes.traces``, and warns once with a ``DeprecationWarning`` that names
it. ``lidar_env.world``, ``lidar_env.movers`` and ``lidar_env.rendering`` are now subpackages
whose faces export what those modules' users imported, so they need no redirect.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import warnings
from types import ModuleType

#: old module path -> new module path
MOVED: dict[str, str] = {
    "lidar_env.se2": "lidar_env.core.se2",
    "lidar_env.errors": "lidar_env.core.errors",
    "lidar_env.polygons": "lidar_env.world.polygons",
    "lidar_env.primitive_grid": "lidar_env.world.primitive_grid",
    "lidar_env.occupancy_image": "lidar_env.world.occupancy_image",
    "lidar_env.ros_map": "lidar_env.world.ros_map",
    "lidar_env.worlds": "lidar_env.world.built_in",
    "lidar_env.feature_worlds": "lidar_env.world.feature_worlds",
    "lidar_env.user_worlds": "lidar_env.world.user_worlds",
    "lidar_env.traces": "lidar_env.routes.traces",
    "lidar_env.trace_geometry": "lidar_env.routes.trace_geometry",
    "lidar_env.user_traces": "lidar_env.routes.user_traces",
    "lidar_env.lidar": "lidar_env.sensors.lidar",
    "lidar_env.lidar_config": "lidar_env.sensors.lidar_config",
    "lidar_env.lidar_layout": "lidar_env.sensors.lidar_layout",
    "lidar_env.layout_kernels": "lidar_env.sensors.layout_kernels",
    "lidar_env.ray_casting": "lidar_env.sensors.ray_casting",
    "lidar_env.beam_wedge": "lidar_env.sensors.beam_wedge",
    "lidar_env.edge_facing": "lidar_env.sensors.edge_facing",
    "lidar_env.car": "lidar_env.vehicle.car",
    "lidar_env.actions": "lidar_env.vehicle.actions",
    "lidar_env.mover_kernels": "lidar_env.movers.kernels",
    "estimators.clock": "lidar_env.core.clock",
}


class _Redirect(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds an old path in :data:`MOVED` and loads the module at the new one."""

    def find_spec(self, fullname: str, path: object = None,
                  target: object = None) -> importlib.machinery.ModuleSpec | None:
        if fullname not in MOVED:
            return None
        return importlib.machinery.ModuleSpec(fullname, self)

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> None:
        """The default: a new, empty module object under the old name."""

    def exec_module(self, module: ModuleType) -> None:
        new_name = MOVED[module.__name__]
        warnings.warn(f"{module.__name__} is now {new_name}; the old path goes in the next "
                      "release", DeprecationWarning, stacklevel=2)
        new = importlib.import_module(new_name)
        module.__dict__.update((key, value) for key, value in vars(new).items()
                               if not key.startswith("__"))
        module.__doc__ = new.__doc__


def install() -> None:
    """Let the old paths import (the redirect is added to ``sys.meta_path`` once)."""
    if not any(isinstance(finder, _Redirect) for finder in sys.meta_path):
        sys.meta_path.append(_Redirect())
