"""Compile the project's numba kernels once per source into numba's on-disk cache (set-up's last
step): ``python scripts/compile_kernels.py``.

When the marker of this source exists (``estimators/leaderboard/__pycache__/warm-<digest>``)
it exits at once, having read the sources only (no numba, no numpy), so a set-up with nothing
to do stays instant; otherwise :func:`estimators.leaderboard.warmup.main` compiles every kernel
on two processes. The digest is :func:`estimators.leaderboard.records.source_digest`'s over
the packages that hold kernels.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parents[1]
#: The packages whose sources key the marker (``estimators.leaderboard.warmup``'s).
PACKAGES = ("estimators", "lidar_env")


def _kernel_cache() -> ModuleType:
    """``lidar_env.core.kernel_cache`` loaded from its file (standard library only), without
    importing ``lidar_env`` (gymnasium, numpy, numba)."""
    path = ROOT / "lidar_env" / "core" / "kernel_cache.py"
    spec = importlib.util.spec_from_file_location("_kernel_cache", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def source_digest(root: Path = ROOT) -> str:
    """SHA-256 (first 12 hex digits) of the paths and contents of the packages' ``*.py``."""
    return _kernel_cache().source_digest(root, PACKAGES)


def main() -> int:
    """0 when the kernels are cached or compiled, 1 if compiling failed."""
    marker = ROOT / "estimators" / "leaderboard" / "__pycache__" / f"warm-{source_digest()}"
    if marker.exists():
        return 0
    sys.path.insert(0, str(ROOT))
    from estimators.leaderboard.warmup import main as compile_all

    return compile_all()


if __name__ == "__main__":
    raise SystemExit(main())
