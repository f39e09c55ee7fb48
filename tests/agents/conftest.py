"""Stable-Baselines3's default logger makes a folder per ``learn()`` under ``$SB3_LOGDIR`` (else
the system's temporary folder): the tests' go to their own temporary path."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture(autouse=True)
def _sb3_log_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SB3_LOGDIR", str(tmp_path / "sb3"))
