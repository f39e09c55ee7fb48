"""``duallidar``: one entry point whose subcommands each answer ``--help`` with their defaults
and refuse a bad value in one line naming the option (exit status 2)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from estimators import cli
from estimators.cli import SUBCOMMANDS


def test_the_top_level_help_lists_every_command(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as stop:
        cli.main(["--help"])
    assert stop.value.code == 0
    text = capsys.readouterr().out
    assert text.startswith("usage: duallidar")
    for name in SUBCOMMANDS:
        assert f"  {name} " in text


@pytest.mark.parametrize("command", sorted(SUBCOMMANDS))
def test_every_command_has_help_with_defaults(command: str,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("yaml") if command in ("train", "imitate") else None
    with pytest.raises(SystemExit) as stop:
        cli.main([command, "--help"])
    assert stop.value.code == 0
    text = capsys.readouterr().out
    assert text.startswith(f"usage: duallidar {command}")
    assert "default" in text


def test_an_unknown_command_or_none_is_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as stop:
        cli.main(["fly"])
    assert stop.value.code == 2
    assert "invalid choice: 'fly'" in capsys.readouterr().err
    assert cli.main([]) == 2


def test_the_dispatcher_imports_no_command_until_asked() -> None:
    code = ("import sys, estimators.cli as c; c._parser(); "
            "print(any(m.startswith(('agents', 'torch', 'estimators.leaderboard')) "
            "for m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "False"


def test_the_installed_script_runs() -> None:
    script = Path(sys.executable).with_name("duallidar")
    if not script.exists() and shutil.which("duallidar") is None:
        pytest.skip("the duallidar script is not installed (pip install -e .)")
    done = subprocess.run([str(script if script.exists() else "duallidar"), "run",
                           "--max-scans", "0", "x.clf"], capture_output=True, text=True)
    assert done.returncode == 2
    assert "--max-scans" in done.stderr and "Traceback" not in done.stderr
