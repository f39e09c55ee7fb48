"""The first-compile notice: said once when a kernel is missing from numba's on-disk cache,
never when it is cached."""

from __future__ import annotations

import importlib
import importlib.util
import logging
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import pytest
from numba import njit

from lidar_env.core import kernel_cache

SOURCE = '''
from numba import njit


@njit(cache=True)
def twice(x):
    return 2.0 * x
'''


def fresh_module(directory: Path, name: str) -> ModuleType:
    """A module with one cached kernel, in a directory of its own (so its cache starts empty)."""
    path = directory / f"{name}.py"
    path.write_text(SOURCE)
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def test_a_kernel_is_cached_once_a_process_compiled_it(tmp_path) -> None:
    module = fresh_module(tmp_path, "kernel_cache_probe_a")
    assert not kernel_cache.is_cached(module.twice)
    assert kernel_cache.cold_kernels([module.twice]) == ["twice"]
    assert module.twice(1.5) == 3.0
    assert kernel_cache.is_cached(module.twice)
    # another process sees the same index: a fresh dispatcher over the same file
    again = fresh_module(tmp_path, "kernel_cache_probe_a")
    assert kernel_cache.is_cached(again.twice)


def test_a_kernel_numba_does_not_cache_has_nothing_to_announce() -> None:
    assert kernel_cache.is_cached(njit(lambda x: x))


def test_a_cold_kernel_is_announced_once_as_a_warning(tmp_path, caplog) -> None:
    module = fresh_module(tmp_path, "kernel_cache_probe_b")
    with caplog.at_level(logging.WARNING, logger="lidar_env"):
        assert kernel_cache.announce_first_compile("probe B's first call", [module.twice])
        assert not kernel_cache.announce_first_compile("probe B's first call", [module.twice])
    [record] = caplog.records
    assert record.name == "lidar_env" and record.levelno == logging.WARNING
    message = record.getMessage()
    assert message.startswith("probe B's first call compiles") and "twice" in message
    low, high = kernel_cache.COMPILE_SECONDS
    assert "once" in message and f"{low}-{high} s" in message


def test_a_cached_kernel_says_nothing(tmp_path, caplog) -> None:
    module = fresh_module(tmp_path, "kernel_cache_probe_c")
    module.twice(1.0)
    with caplog.at_level(logging.DEBUG, logger="lidar_env"):
        assert not kernel_cache.announce_first_compile("probe C's first call", [module.twice])
    assert caplog.records == []


@pytest.mark.parametrize("make", ["single", "vector"])
def test_the_envs_check_their_kernels_when_made(make, monkeypatch) -> None:
    import gymnasium as gym

    import lidar_env  # noqa: F401

    checked: list[tuple[str, tuple]] = []
    monkeypatch.setattr(kernel_cache, "_announced", set())
    for module in ("lidar_env.env", "lidar_env.vector.env"):
        monkeypatch.setattr(importlib.import_module(module), "announce_first_compile",
                            lambda what, kernels: checked.append((what, tuple(kernels))))
    if make == "single":
        gym.make("DualLidar-v0").close()
    else:
        gym.make_vec("DualLidar-v0", num_envs=2, vectorization_mode="vector_entry_point").close()
    whats = [what for what, _ in checked]
    assert whats[-1] == ("DualLidar-v0's first reset" if make == "single"
                         else "the batched DualLidar-v0's first reset")
    assert all(hasattr(kernel, "py_func") for kernel in checked[-1][1])


CALLER = '''
from numba import njit

from callee_pkg.callee import value


@njit(cache=True)
def read():
    return value()
'''
CALLEE = '''
from numba import njit


@njit(cache=True)
def value():
    return {}
'''
RUN = '''
import sys
from pathlib import Path
sys.path.insert(0, sys.argv[1])
from lidar_env.core.kernel_cache import drop_stale_caches
if sys.argv[2] == "guarded":
    drop_stale_caches(Path(sys.argv[1]), "caller_pkg", ("caller_pkg", "callee_pkg"))
from caller_pkg.caller import read
print(read())
'''


def read_in_new_process(root: Path, mode: str) -> str:
    """What the cached caller returns in a fresh interpreter (``mode``: guarded or bare).
    ``-B``: no bytecode cache, whose stamp is the source's mtime in whole seconds (a source
    rewritten within the second of its last import would run its old bytecode)."""
    completed = subprocess.run([sys.executable, "-B", "-c", RUN, str(root), mode], check=True,
                               capture_output=True, text=True)
    return completed.stdout.strip()


def write_packages(root: Path, value: float) -> None:
    for package, source in (("caller_pkg", CALLER), ("callee_pkg", CALLEE.format(value))):
        (root / package).mkdir(exist_ok=True)
        (root / package / "__init__.py").write_text("")
        module = package.removesuffix("_pkg")
        (root / package / f"{module}.py").write_text(source)


def test_a_changed_callee_reaches_a_cached_caller_once_stale_caches_are_dropped(tmp_path) -> None:
    write_packages(tmp_path, 1.0)
    assert read_in_new_process(tmp_path, "guarded") == "1.0"
    write_packages(tmp_path, 2.0)  # the callee's file changes, the caller's does not
    assert read_in_new_process(tmp_path, "bare") == "1.0"  # numba's cache: the old callee
    assert read_in_new_process(tmp_path, "guarded") == "2.0"


def test_stale_caches_are_dropped_once_per_source(tmp_path) -> None:
    write_packages(tmp_path, 1.0)
    cache = tmp_path / "caller_pkg" / "__pycache__"
    cache.mkdir()
    (cache / "caller.read-5.py311.nbi").write_bytes(b"index")
    sources = ("caller_pkg", "callee_pkg")
    assert kernel_cache.drop_stale_caches(tmp_path, "caller_pkg", sources)
    assert not (cache / "caller.read-5.py311.nbi").exists()
    (cache / "caller.read-5.py311.nbi").write_bytes(b"index")  # compiled for these sources
    assert not kernel_cache.drop_stale_caches(tmp_path, "caller_pkg", sources)
    assert (cache / "caller.read-5.py311.nbi").exists()
    write_packages(tmp_path, 3.0)
    assert kernel_cache.drop_stale_caches(tmp_path, "caller_pkg", sources)
    assert not (cache / "caller.read-5.py311.nbi").exists()
    assert len(list(cache.glob("numba-sources-*"))) == 1
