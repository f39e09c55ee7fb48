"""The flat layout's module paths still import, for one release, with a warning naming the new
path, and give the very objects of the new modules."""

import importlib
import sys

import pytest

import lidar_env  # noqa: F401  (installs the redirect)
from lidar_env.moved_modules import MOVED


@pytest.mark.parametrize("old", sorted(MOVED))
def test_an_old_path_warns_and_gives_the_new_modules_objects(old: str) -> None:
    sys.modules.pop(old, None)
    with pytest.warns(DeprecationWarning, match=MOVED[old].replace(".", r"\.")):
        module = importlib.import_module(old)
    new = importlib.import_module(MOVED[old])
    public = [name for name in vars(new) if not name.startswith("_")]
    assert public and all(getattr(module, name) is getattr(new, name) for name in public)


def test_every_old_path_names_an_existing_module() -> None:
    for new in MOVED.values():
        importlib.import_module(new)


def test_the_packages_that_replaced_modules_keep_their_main_names() -> None:
    from lidar_env.movers import Crowd, car_circles  # noqa: F401
    from lidar_env.rendering import Renderer, write_png  # noqa: F401
    from lidar_env.world import World  # noqa: F401
