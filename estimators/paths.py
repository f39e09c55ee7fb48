"""Where the project is on disk, computed in one place so that moving a module never changes it.

``PROJECT_ROOT`` is the repository (the folder holding ``estimators/``, ``lidar_env/`` and
``agents/``); ``SHARED_DATA`` is ``../shared/data`` beside it (real logs in ``radish/``,
pose-graph benchmarks in ``g2o/``), never copied into the project.
"""

from __future__ import annotations

from pathlib import Path

PROJECT_ROOT: Path = Path(__file__).resolve().parent.parent
SHARED_DATA: Path = PROJECT_ROOT.parent / "shared" / "data"
