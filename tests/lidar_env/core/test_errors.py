"""The project's exception types: each is a DualLidarError (a ValueError) and the three with a
built-in kind keep it, so ``except TypeError`` / ``KeyError`` / ``RuntimeError`` code works."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import estimators
import lidar_env  # noqa: F401  (registers DualLidar-v0)
from lidar_env.core.errors import (
    ArgumentTypeError,
    DualLidarError,
    ResetNeededError,
    UnknownNameError,
)


@pytest.mark.parametrize(("kind", "builtin"), [(ArgumentTypeError, TypeError),
                                               (UnknownNameError, KeyError),
                                               (ResetNeededError, RuntimeError)])
def test_each_kind_is_ours_and_the_builtin(kind: type[Exception], builtin: type) -> None:
    assert issubclass(kind, DualLidarError) and issubclass(kind, ValueError)
    assert issubclass(kind, builtin)


def test_an_unknown_name_reads_unquoted() -> None:
    with pytest.raises(UnknownNameError) as caught:
        estimators.make("nope")
    assert str(caught.value).startswith("unknown estimator 'nope': expected one of ")


def test_step_before_reset_and_a_wrong_config_type_are_named() -> None:
    env = gym.make("DualLidar-v0")
    with pytest.raises(ResetNeededError, match=r"call reset\(\) before step\(\)"):
        env.unwrapped.step(np.zeros(2, np.float32))
    with pytest.raises(ArgumentTypeError, match="config: expected an EnvConfig or a dict"):
        gym.make("DualLidar-v0", config=[1, 2])


#: The built-in exceptions that mean bad input, which must be ours (an ImportError for a missing
#: extra, SystemExit from a CLI, FileNotFoundError, an OSError whose layout no ValueError
#: subclass can share, are fine as they are).
BAD_INPUT = {"Exception", "ValueError", "TypeError", "KeyError", "IndexError", "LookupError",
             "RuntimeError", "ArithmeticError", "ZeroDivisionError", "OverflowError",
             "FloatingPointError", "AssertionError", "AttributeError"}
#: The two a Python protocol asks for by name.
ALLOWED = {("TypeError", "estimators/leaderboard/records.py"),  # json.dumps(default=) hook
           ("KeyError", "lidar_env/world/built_in.py")}  # dict.__missing__


def test_no_module_raises_a_bare_builtin_error() -> None:
    import ast
    from pathlib import Path

    root = Path(__file__).resolve().parents[3]
    found = []
    for package in ("agents", "estimators", "lidar_env"):
        for path in sorted((root / package).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text())):
                if not (isinstance(node, ast.Raise) and node.exc is not None):
                    continue
                exc = node.exc.func if isinstance(node.exc, ast.Call) else node.exc
                name = exc.id if isinstance(exc, ast.Name) else ""
                if name not in BAD_INPUT:
                    continue
                where = path.relative_to(root).as_posix()
                if (name, where) not in ALLOWED:
                    found.append(f"{where}:{node.lineno} raises {name}")
    assert not found, "raise a lidar_env.core.errors type instead:\n" + "\n".join(found)


def test_every_error_class_derives_from_ours() -> None:
    """Warnings and OSErrors (a file system's refusal; no ValueError can share their layout)
    aside."""
    import ast
    import builtins
    from pathlib import Path

    root = Path(__file__).resolve().parents[3]
    found = []
    for package in ("agents", "estimators", "lidar_env"):
        for path in sorted((root / package).rglob("*.py")):
            where = path.relative_to(root).as_posix()
            for node in ast.walk(ast.parse(path.read_text())):
                if not isinstance(node, ast.ClassDef):
                    continue
                bases = {b.id for b in node.bases if isinstance(b, ast.Name)}
                builtin = {b for b in bases if isinstance(getattr(builtins, b, None), type)
                           and issubclass(getattr(builtins, b), Exception)  # not Ctrl-C's
                           and not issubclass(getattr(builtins, b), (Warning, OSError))}
                if builtin and not bases - builtin and (where, node.name) not in {
                        ("lidar_env/core/errors.py", "DualLidarError"),  # the root
                        ("estimators/leaderboard/runner.py", "RunInterrupted")}:  # Ctrl-C
                    found.append(f"{where}:{node.lineno} class {node.name}({', '.join(bases)})")
    assert not found, "derive from a lidar_env.core.errors type instead:\n" + "\n".join(found)
