"""CPU time spent inside the project's compiled (numba) kernels, apart from the Python around
them: how much of an estimator's time per scan a faster orchestration could still remove.

    seconds = kernel_seconds(lambda: run_the_estimator())

The call runs once under :mod:`cProfile` (process time); a kernel is a module-level numba
dispatcher of the ``estimators`` or ``lidar_env`` packages, and its own time (``tottime``) is
the compiled code, numba's dispatch of the call, and the profiler's own cost of the call,
which is measured on a kernel that does next to nothing and taken off per call.
"""

from __future__ import annotations

import cProfile
import functools
import pstats
import sys
import time
from collections.abc import Callable

import numpy as np
from numba.core.dispatcher import Dispatcher

PACKAGES = ("estimators", "lidar_env")
#: Calls of the near-empty kernel that measure the profiler's cost per call.
CALIBRATION_CALLS = 20_000


def _dispatchers() -> set[tuple[str, str]]:
    """The loaded packages' module-level numba kernels as (source file, function name)."""
    found = set()
    for name, module in list(sys.modules.items()):
        if name.split(".")[0] not in PACKAGES or not getattr(module, "__file__", None):
            continue
        found.update((module.__file__, attribute) for attribute, value in vars(module).items()
                     if isinstance(value, Dispatcher))
    return found


def _profiled(work: Callable[[], object]) -> tuple[float, int]:
    """Own CPU seconds of the kernels ``work`` calls under cProfile, and their call count."""
    profile = cProfile.Profile(time.process_time)
    profile.enable()
    work()
    profile.disable()
    kernels = _dispatchers()
    stats = pstats.Stats(profile).stats  # type: ignore[attr-defined]
    own = [(seconds, calls) for (path, _, function), (_, calls, seconds, _, _) in stats.items()
           if (path, function) in kernels]
    return sum(s for s, _ in own), sum(c for _, c in own)


@functools.cache
def profiler_cost() -> float:
    """CPU seconds the profiler adds to a kernel call's own time: a three-beam scan's points
    (next to no work) called :data:`CALIBRATION_CALLS` times with and without it (measured
    once per process)."""
    from estimators.matching.scan_matching import _beam_points

    ones = np.ones(3)

    def calls() -> None:
        for _ in range(CALIBRATION_CALLS):
            _beam_points(ones, ones, ones, 10.0, 0.05)

    calls()  # loaded outside the measure
    start = time.process_time()
    calls()
    plain = time.process_time() - start
    own, _ = _profiled(calls)
    return max(own - plain, 0.0) / CALIBRATION_CALLS


def kernel_seconds(work: Callable[[], object]) -> float:
    """CPU seconds ``work`` spends inside compiled kernels (run once, profiled), less the
    profiler's cost of each kernel call (:func:`profiler_cost`)."""
    own, calls = _profiled(work)
    return max(own - calls * profiler_cost(), 0.0)
