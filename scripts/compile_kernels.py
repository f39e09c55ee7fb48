"""Compile the project's numba kernels once per source into numba's on-disk cache (set-up's last
step): ``python scripts/compile_kernels.py``.

When the marker of this source exists (``estimators/leaderboard/__pycache__/warm-<digest>``)
it exits at once, having read the sources only (no numba, no numpy), so a set-up with nothing
to do stays instant; otherwise :func:`estimators.leaderboard.warmup.main` compiles every kernel
on two processes. The digest is :func:`estimators.leaderboard.records.source_digest`'s over
the packages that hold kernels.
"""

from __future__ import annotations

import hashlib
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The packages whose sources key the marker (``estimators.leaderboard.warmup``'s).
PACKAGES = ("estimators", "lidar_env")


def source_digest(root: Path = ROOT) -> str:
    """SHA-256 (first 12 hex digits) of the paths and contents of the packages' ``*.py``."""
    digest = hashlib.sha256()
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            digest.update(path.relative_to(root).as_posix().encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()[:12]


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
