"""Whether numba's on-disk cache holds a process's kernels, and one log line before they compile.

Every kernel is ``@njit(cache=True)``: the first process that calls it compiles it and writes
the machine code to ``__pycache__`` beside its source (inside the clone), keyed by the source
file's modification time and size, numba's version and this CPU; later processes load it in
milliseconds. ``scripts/setup.sh`` fills that cache once, so a run after it compiles nothing.
A process that meets a cold cache anyway (an install without the set-up, or edited sources)
compiles for tens of seconds before its first step: :func:`announce_first_compile` says so
once, as a ``WARNING`` of the ``lidar_env`` logger (shown by Python's default handler, so an
interactive shell sees it), and says nothing when the cache is warm.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable
from typing import Any

LOGGER = logging.getLogger("lidar_env")
#: What a cold compile of the simulator's kernels takes on a 2-core x86-64 machine [s].
COMPILE_SECONDS = (15, 45)
_announced: set[str] = set()


def is_cached(kernel: Any) -> bool:
    """True if numba's on-disk cache holds a compiled overload of ``kernel`` (a numba
    dispatcher) for its current source, numba version and this CPU; True as well for a
    function numba does not cache (nothing to announce)."""
    cache_file = getattr(getattr(kernel, "_cache", None), "_cache_file", None)
    if cache_file is None:
        return True
    index = cache_file._load_index()  # {} when missing, stale or from another numba
    if not index:
        return False
    magic = kernel.targetctx.codegen().magic_tuple()
    return any(key[1] == magic for key in index)


def cold_kernels(kernels: Iterable[Any]) -> list[str]:
    """The names of the ``kernels`` that a call compiles rather than loads."""
    return [kernel.py_func.__qualname__ for kernel in kernels if not is_cached(kernel)]


def announce_first_compile(what: str, kernels: Iterable[Any]) -> bool:
    """Log once per process and ``what`` that ``what`` compiles the numba kernels, and how
    long that takes, when any of ``kernels`` is missing from the on-disk cache; returns True
    if it logged. Quiet when they are cached, and on every later call."""
    if what in _announced:
        return False
    _announced.add(what)
    cold = cold_kernels(kernels)
    if not cold:
        return False
    low, high = COMPILE_SECONDS
    LOGGER.warning(
        "%s compiles the simulator's numba kernels first (%s not in the cache): %d-%d s on a "
        "2-core machine, once; later processes load them from __pycache__ in under a second "
        "(scripts/setup.sh compiles them ahead)", what, ", ".join(cold), low, high)
    return True
