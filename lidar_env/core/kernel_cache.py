"""Whether numba's on-disk cache holds a process's kernels, and one log line before they compile.

Every kernel is ``@njit(cache=True)``: the first process that calls it compiles it and writes
the machine code to ``__pycache__`` beside its source (inside the clone), keyed by the source
file's modification time and size, numba's version and this CPU; later processes load it in
milliseconds. ``scripts/setup.sh`` fills that cache once, so a run after it compiles nothing.
A process that meets a cold cache anyway (an install without the set-up, or edited sources)
compiles for tens of seconds before its first step: :func:`announce_first_compile` says so
once, as a ``WARNING`` of the ``lidar_env`` logger (shown by Python's default handler, so an
interactive shell sees it), and says nothing when the cache is warm.

numba keys a cached kernel by its own file alone, but the kernel holds its callees' code
compiled in: after ``git pull`` changed a callee's file (a ray caster, a packed parameter
layout), the cache would run the old code. :func:`drop_stale_caches` runs at each package's
import and drops the package's caches when the sources they were compiled from changed.
"""

from __future__ import annotations

import hashlib
import logging
from collections.abc import Iterable, Sequence
from pathlib import Path
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


def source_digest(root: Path, packages: Sequence[str]) -> str:
    """SHA-256 (first 12 hex digits) of the paths and contents of the ``*.py`` files of
    ``packages`` (folders under ``root``)."""
    digest = hashlib.sha256()
    for package in packages:
        for path in sorted((root / package).rglob("*.py")):
            digest.update(path.relative_to(root).as_posix().encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()[:12]


def drop_numba_caches(package: Path) -> int:
    """Delete numba's cache files (``*.nbi`` index, ``*.nbc`` code) under the folder
    ``package``; returns how many."""
    removed = 0
    for pattern in ("*.nbi", "*.nbc"):
        for path in package.rglob(f"__pycache__/{pattern}"):
            path.unlink(missing_ok=True)
            removed += 1
    return removed


def drop_stale_caches(root: Path, package: str, sources: Sequence[str]) -> bool:
    """Drop the numba caches of ``package`` (a folder under ``root``) unless they were written
    for the current ``sources`` (the packages its kernels compile code from, itself included);
    True if it dropped them. The sources' digest is stamped in
    ``<package>/__pycache__/numba-sources-<digest>``, so a later import with the same sources
    reads them (a few milliseconds) and drops nothing. A read-only install is left as it is."""
    try:
        cache = root / package / "__pycache__"
        stamp = cache / f"numba-sources-{source_digest(root, sources)}"
        if stamp.exists():
            return False
        drop_numba_caches(root / package)
        for old in cache.glob("numba-sources-*"):
            old.unlink(missing_ok=True)
        cache.mkdir(exist_ok=True)
        stamp.touch()
    except OSError:
        return False
    return True
