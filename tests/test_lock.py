"""requirements.lock pins what pyproject.toml asks for, and the check that says so can fail."""

from __future__ import annotations

import importlib.util
import re
import shutil
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("check_lock", ROOT / "scripts" / "check_lock.py")
check_lock = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(check_lock)


def test_the_committed_lock_agrees_with_pyproject() -> None:
    assert check_lock.lock_mismatches(ROOT / "pyproject.toml", ROOT / "requirements.lock") == []


def test_the_lock_pins_torch_to_the_cpu_build() -> None:
    pins, _ = check_lock.locked_pins(ROOT / "requirements.lock")
    assert str(pins["torch"]) == "2.13.0+cpu"
    assert not any(name.startswith(("nvidia-", "triton")) for name in pins)


def edited_pyproject(tmp_path: Path, old: str, new: str) -> Path:
    text = (ROOT / "pyproject.toml").read_text()
    assert old in text
    path = tmp_path / "pyproject.toml"
    path.write_text(text.replace(old, new, 1))
    return path


def test_a_dependency_missing_from_the_lock_is_named(tmp_path: Path) -> None:
    pyproject = edited_pyproject(tmp_path, '"numpy>=1.26",', '"numpy>=1.26",\n    "left-pad>=1",')
    problems = check_lock.lock_mismatches(pyproject, ROOT / "requirements.lock")
    assert problems == ["left-pad>=1 is in pyproject.toml but not pinned in requirements.lock"]
    assert check_lock.main(["--pyproject", str(pyproject)]) == 1


def test_a_pin_outside_the_specifier_is_named(tmp_path: Path) -> None:
    pyproject = edited_pyproject(tmp_path, '"numpy>=1.26",', '"numpy>=99",')
    [problem] = check_lock.lock_mismatches(pyproject, ROOT / "requirements.lock")
    assert "numpy==" in problem and "numpy>=99" in problem


def test_a_pin_for_a_dependency_pyproject_dropped_is_named(tmp_path: Path) -> None:
    pyproject = edited_pyproject(tmp_path, '    "tqdm>=4.60",\n', "")
    lock = tmp_path / "requirements.lock"
    shutil.copy(ROOT / "requirements.lock", lock)
    problems = check_lock.lock_mismatches(pyproject, lock)
    assert any("tqdm" in p and "no longer asks" in p for p in problems), problems


def test_a_path_pinned_line_is_named(tmp_path: Path) -> None:
    """pip-compile pins the project's self-reference as ``duallidar @ file:///<checkout>``:
    left in, every clone would install a copy of the folder the lock was made in."""
    lock = tmp_path / "requirements.lock"
    lock.write_text((ROOT / "requirements.lock").read_text() + "duallidar @ file:///work/x\n")
    [problem] = check_lock.lock_mismatches(ROOT / "pyproject.toml", lock)
    assert "local path" in problem and "duallidar @ file:///work/x" in problem


@pytest.mark.parametrize("script", ["setup.sh", "lock.sh"])
def test_set_up_scripts_work_from_the_lock(script: str) -> None:
    text = (ROOT / "scripts" / script).read_text()
    assert "requirements.lock" in text and "poetry" not in text


def test_set_up_installs_torch_with_pip_before_uv_installs_the_lock() -> None:
    """uv does not look at this machine's CPU build of torch: pip installs it first, at the
    lock's version, so uv finds it there and never resolves a multi-GB CUDA build."""
    text = (ROOT / "scripts" / "setup.sh").read_text()
    torch = text.index('install --no-compile --no-deps "torch==2.13.0"')
    assert torch < text.index("install -q --no-deps -r requirements.lock")
    assert torch < text.index("sync -q requirements.lock")
    assert re.search(r"^UV_VERSION=\d+\.\d+\.\d+$", text, flags=re.M)
    assert "torch==2.13.0+cpu" in (ROOT / "requirements.lock").read_text()
