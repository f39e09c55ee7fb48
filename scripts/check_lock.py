"""Check that requirements.lock agrees with pyproject.toml (and requirements.in).

    python scripts/check_lock.py [--pyproject pyproject.toml] [--lock requirements.lock]

Needs Python >= 3.11 (tomllib), as the lock does. Every direct dependency of the project (core
and every extra that ``[dev]`` pulls in) must be pinned in the lock at a version its specifier
admits, and every pin the lock credits to ``duallidar (pyproject.toml)`` must still be a
dependency there. Exit status 1 lists each disagreement; ``bash scripts/lock.sh`` refreshes the
lock.
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Iterable
from importlib import metadata
from pathlib import Path

import tomllib
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from packaging.version import Version

ROOT = Path(__file__).resolve().parents[1]
_PIN = re.compile(r"^([A-Za-z0-9_.\-]+)==(\S+)")


def direct_requirements(pyproject: Path, extra: str = "dev") -> dict[str, Requirement]:
    """Name -> requirement of the core dependencies and of ``extra``, self-references expanded."""
    project = tomllib.loads(pyproject.read_text())["project"]
    name = canonicalize_name(project["name"])
    extras = project.get("optional-dependencies", {})
    found: dict[str, Requirement] = {}
    pending, seen = list(project.get("dependencies", [])), set()
    pending += extras.get(extra, [])
    while pending:
        requirement = Requirement(pending.pop())
        if canonicalize_name(requirement.name) == name:
            for sub in requirement.extras - seen:
                seen.add(sub)
                pending += extras.get(sub, [])
            continue
        found[canonicalize_name(requirement.name)] = requirement
    return found


def locked_pins(lock: Path) -> tuple[dict[str, Version], set[str]]:
    """The lock's pins (name -> version) and the names it says come from pyproject.toml."""
    pins: dict[str, Version] = {}
    from_pyproject: set[str] = set()
    current = None
    for line in lock.read_text().splitlines():
        if match := _PIN.match(line):
            current = canonicalize_name(match[1])
            pins[current] = Version(match[2])
        elif current and "(pyproject.toml)" in line:
            from_pyproject.add(current)
    return pins, from_pyproject


def _extras_of(requirements: Iterable[Requirement]) -> set[str]:
    """Names that requested extras pull in (pip-compile's ``--strip-extras`` credits them to
    pyproject.toml), read from the installed distributions' metadata."""
    names = set()
    for requirement in requirements:
        for extra in requirement.extras:
            try:
                requires = metadata.requires(requirement.name) or []
            except metadata.PackageNotFoundError:
                continue
            for line in requires:
                dependency = Requirement(line)
                if dependency.marker and dependency.marker.evaluate({"extra": extra}):
                    names.add(canonicalize_name(dependency.name))
    return names


def lock_mismatches(pyproject: Path, lock: Path) -> list[str]:
    """Human-readable disagreements between ``pyproject`` and ``lock``; empty when in step."""
    wanted = direct_requirements(pyproject)
    pins, from_pyproject = locked_pins(lock)
    problems = [
        f"{lock.name}:{number}: {line.strip()!r} pins a local path, which installs a copy of "
        "that folder in every clone; only exact versions belong in the lock"
        for number, line in enumerate(lock.read_text().splitlines(), 1)
        if " @ " in line and not line.lstrip().startswith("#")
    ]
    for name, requirement in sorted(wanted.items()):
        if name not in pins:
            problems.append(f"{requirement} is in {pyproject.name} but not pinned in {lock.name}")
        elif not requirement.specifier.contains(pins[name], prereleases=True):
            problems.append(
                f"{lock.name} pins {name}=={pins[name]}, outside {pyproject.name}'s {requirement}"
            )
    for name in sorted(from_pyproject - set(wanted) - _extras_of(wanted.values())):
        problems.append(f"{lock.name} pins {name} for {pyproject.name}, which no longer asks it")
    return problems


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pyproject", type=Path, default=ROOT / "pyproject.toml")
    parser.add_argument("--lock", type=Path, default=ROOT / "requirements.lock")
    args = parser.parse_args(argv)
    problems = lock_mismatches(args.pyproject, args.lock)
    for problem in problems:
        print(f"lock check: {problem}", file=sys.stderr)
    if problems:
        print("lock check: run `bash scripts/lock.sh`, commit requirements.lock", file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
