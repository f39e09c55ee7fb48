"""The documentation: the site builds strictly, and every figure the README quotes is held by a
results file in docs/results/ that names the command it came from."""

from __future__ import annotations

import csv
import importlib.util
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "docs" / "results"
README = ROOT / "README.md"
_NUMBER = re.compile(r"(?<![\w.])-?\d+(?:[.,]\d+)*(?:e-?\d+)?")
_MARKER = re.compile(r"^<!-- results: (docs/results/[\w.\-]+\.json) (.+?) -->$")


def numbers(text: str) -> set[str]:
    return set(_NUMBER.findall(text))


def markdown_table(lines: list[str]) -> tuple[list[str], list[list[str]]]:
    """Columns and rows of the markdown table at the start of ``lines``."""
    cells = [[c.strip() for c in line.strip().strip("|").split("|")]
             for line in lines if line.startswith("|")]
    return cells[0], cells[2:]


def readme_results_tables() -> list[tuple[Path, str, list[str], list[list[str]]]]:
    """Every README table that follows a ``<!-- results: FILE TABLE -->`` marker."""
    lines = README.read_text().splitlines()
    found = []
    for i, line in enumerate(lines):
        if match := _MARKER.match(line):
            end = i + 1
            while end < len(lines) and lines[end].startswith("|"):
                end += 1
            columns, rows = markdown_table(lines[i + 1:end])
            found.append((ROOT / match[1], match[2], columns, rows))
    return found


def test_the_readme_is_a_five_minute_read() -> None:
    assert len(README.read_text().splitlines()) <= 300


def test_readme_and_docs_hold_no_development_history() -> None:
    """Dates of work and numbered sessions belong in CHANGELOG.md, by version, if anywhere."""
    pages = [README, *sorted((ROOT / "docs").rglob("*.md"))]
    for page in pages:
        text = page.read_text()
        assert not re.search(r"\b20\d\d-\d\d-\d\d\b", text), f"{page}: a date of work"
        assert not re.search(r"\bsessions? \d", text, flags=re.I), f"{page}: a session number"


def test_every_readme_results_table_comes_from_a_results_file() -> None:
    tables = readme_results_tables()
    assert tables, "the README's results table lost its <!-- results: FILE TABLE --> marker"
    for path, name, columns, rows in tables:
        data = json.loads(path.read_text())
        table = data["tables"][name]
        held = {row[table["columns"].index("estimator")]: dict(zip(table["columns"], row,
                                                                   strict=True))
                for row in table["rows"]}
        every_number = numbers(json.dumps(data["tables"], ensure_ascii=False))
        for row in rows:
            cells = dict(zip(columns, row, strict=True))
            estimator = cells["estimator"].split()[0]
            assert estimator in held, f"{estimator} is in the README but not in {path.name}"
            for column, value in cells.items():
                if column in held[estimator] and column != "estimator":
                    assert value == held[estimator][column], (estimator, column, value)
                missing = numbers(value) - every_number
                assert not missing, f"README {estimator} {column}: {missing} not in {path.name}"
        order = list(held)
        shown = [order.index(row[columns.index("estimator")].split()[0]) for row in rows]
        assert shown == sorted(shown), f"the README's rows are not in {path.name}'s order"


def test_results_files_name_their_command_hardware_and_files() -> None:
    files = sorted(RESULTS.glob("*.json"))
    assert files
    for path in files:
        data = json.loads(path.read_text())
        assert data["command"].strip() and data["hardware"].strip(), path
        for name in data["files"]:
            assert (RESULTS / name).is_file(), f"{path.name} lists {name}, which is missing"
        for name, table in data["tables"].items():
            assert all(len(row) == len(table["columns"]) for row in table["rows"]), name


def test_the_leaderboard_results_agree_with_the_run_s_csv() -> None:
    """The JSON's headline cells are the leaderboard's own rounding of its CSV."""
    data = json.loads((RESULTS / "leaderboard.json").read_text())
    headline = data["tables"]["headline"]
    columns = headline["columns"]
    with (RESULTS / "leaderboard.csv").open() as file:
        by_name = {row["estimator"]: row for row in csv.DictReader(file)}
    assert set(by_name) == {row[columns.index("estimator")] for row in headline["rows"]}
    for row in headline["rows"]:
        cells = dict(zip(columns, row, strict=True))
        written = by_name[cells["estimator"]]
        assert cells["ATE [m]"].split(" ± ")[0] == f"{float(written['ate_rmse_m']):.3f}"
        assert (cells["eq.-11 accuracy [%]"].split(" ± ")[0]
                == f"{float(written['accuracy_percent']):.1f}")


def _hooks():
    spec = importlib.util.spec_from_file_location("docs_hooks", ROOT / "docs" / "hooks.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_docs_pages_hold_their_results_tables_as_the_results_files_say() -> None:
    """The tables below ``<!-- results-table: ... -->`` read on GitHub as they do on the site."""
    hooks = _hooks()
    stale = [str(page.relative_to(ROOT)) for page in sorted((ROOT / "docs").rglob("*.md"))
             if hooks.with_results_tables(page.read_text()) != page.read_text()]
    assert not stale, f"stale results tables in {', '.join(stale)}: run python docs/hooks.py"


def test_the_env_config_reference_lists_every_field_with_its_unit() -> None:
    import dataclasses

    from lidar_env import EnvConfig

    table = _hooks().dataclass_table("lidar_env.config.EnvConfig")
    rows = {line.split("|")[1].strip().strip("`"): line for line in table.splitlines()[2:]}
    assert set(rows) == {field.name for field in dataclasses.fields(EnvConfig)}
    assert "| m |" in rows["car_length"] and "| m/s |" in rows["max_speed"]


def _api_directives() -> dict[str, bool]:
    """``::: name`` directives of the API pages -> whether they render every submodule too."""
    found: dict[str, bool] = {}
    for page in sorted((ROOT / "docs" / "api").glob("*.md")):
        lines = page.read_text().splitlines()
        for i, line in enumerate(lines):
            if line.startswith("::: "):
                options = "\n".join(lines[i + 1:i + 4])
                found[line[4:].strip()] = "show_submodules: true" in options
    return found


def _source_files() -> list[Path]:
    """The packages' modules as committed (git's index), else as on disk; relative to ROOT."""
    packages = ("lidar_env", "estimators", "agents")
    listed = subprocess.run(["git", "ls-files", "--", *packages], cwd=ROOT, capture_output=True,
                            text=True)
    if listed.returncode == 0 and listed.stdout.strip():
        return sorted(Path(line) for line in listed.stdout.splitlines() if line.endswith(".py"))
    return sorted(path.relative_to(ROOT)
                  for package in packages for path in (ROOT / package).rglob("*.py"))


def test_every_public_module_is_in_the_api_reference() -> None:
    """A new module or subpackage needs its face or itself on an API page (docs/api/)."""
    directives = _api_directives()
    missing = []
    for path in _source_files():
        parts = path.with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        if any(part.startswith("_") for part in parts):
            continue
        name = ".".join(parts)
        ancestors = [".".join(parts[:k]) for k in range(1, len(parts))]
        if name not in directives and not any(directives.get(a) for a in ancestors):
            missing.append(name)
    assert not missing, (
        f"not in the API reference: {', '.join(missing)}; add '::: <package face>' with "
        "'show_submodules: true' (or '::: <module>') to a page in docs/api/ and to mkdocs.yml's "
        "nav")


def test_the_site_builds_strictly(tmp_path: Path) -> None:
    """A broken link, a missing page or API target, or a bad docstring reference fails it."""
    pytest.importorskip("mkdocs")
    pytest.importorskip("mkdocstrings")
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site"),
         "--config-file", str(ROOT / "mkdocs.yml")],
        cwd=ROOT, capture_output=True, text=True, timeout=300,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert (tmp_path / "site" / "api" / "lidar_env.core" / "index.html").is_file()


def test_no_results_file_is_older_than_the_code_that_makes_it() -> None:
    """Each results file names the code version it came from (the package version plus
    :func:`estimators.leaderboard.records.code_digest`, blind to comments and docstrings):
    a change of code that can change a figure makes the published figure stale."""
    from estimators.leaderboard.records import package_version

    now = package_version().rpartition("+src.")[2]
    stale = []
    for path in sorted(RESULTS.glob("*.json")):
        made_by = json.loads(path.read_text()).get("source_version", "")
        if made_by.rpartition("+src.")[2] != now:
            stale.append(f"{path.name} (code {made_by or 'unknown'}, now {now})")
    assert not stale, ("results older than the code: " + ", ".join(stale) + "; re-run "
                       "`bash scripts/leaderboard.sh` and `python docs/hooks.py --leaderboard "
                       "leaderboard`, and each benchmark's own command in its results file")
