"""The scan's kernels are compiled inline only into kernels marked as scan loops."""

from __future__ import annotations

from types import SimpleNamespace

from lidar_env.sensors.ray_casting import inline_into_scan_loops, scan_loop
from lidar_env.vector.kernel import observe_envs


def _caller(function) -> SimpleNamespace:
    """What numba's inline cost model is handed as the caller: its ``func_id.func``."""
    return SimpleNamespace(func_id=SimpleNamespace(func=function))


def test_a_marked_kernel_takes_the_scan_inline_and_an_unmarked_one_calls_it() -> None:
    def marked() -> None:
        return None

    def plain() -> None:
        return None

    assert scan_loop(marked) is marked  # the mark leaves the function itself
    assert inline_into_scan_loops(None, _caller(marked), None) is True
    assert inline_into_scan_loops(None, _caller(plain), None) is False


def test_the_batched_scan_is_a_scan_loop() -> None:
    assert getattr(observe_envs.py_func, "inlines_scans", False) is True
