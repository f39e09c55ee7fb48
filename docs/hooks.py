"""MkDocs hooks: tables the pages do not hold by hand.

A page asks for a table with an HTML comment on a line of its own:

- ``<!-- dataclass-table: lidar_env.config.EnvConfig -->``: one row per field of the
  dataclass (key, type, default, unit, meaning), read from its source, so the reference cannot
  drift from the code. The unit and meaning come from the field's trailing comment
  (``x: float = 1.0  # [m] what it is``).
- ``<!-- results-table: leaderboard.json headline -->``: a table of a results file in
  ``docs/results/`` (its ``tables[NAME]``: ``columns`` and ``rows``), followed by the command
  that wrote it. The pages hold the table below the marker too, so they read on GitHub;
  ``python docs/hooks.py`` writes those, and the README's results table, afresh after a
  results file changed (a test fails while they differ); the build always renders them from
  the results file. ``python docs/hooks.py --leaderboard OUT`` first imports a leaderboard
  run's output folder into ``docs/results/``.

:class:`SphinxRoles` is a griffe extension (``mkdocs.yml`` loads it for mkdocstrings): the
docstrings cross-reference in Sphinx's roles (``:class:`~lidar_env.world.World```), which
Markdown would print as they are; it turns each into a link to the API page where one exists,
and into plain code where none does (a name outside the project, say).
"""

from __future__ import annotations

import ast
import dataclasses
import importlib
import inspect
import io
import json
import math
import os
import re
import sys
import tokenize
from pathlib import Path
from typing import Any

import griffe

DOCS = Path(__file__).resolve().parent
RESULTS = DOCS / "results"
_DATACLASS = re.compile(r"^<!-- dataclass-table: ([\w.]+) -->$", flags=re.M)
_RESULTS = re.compile(r"^<!-- results-table: ([\w.\-]+\.json) (.+?) -->$", flags=re.M)
_UNIT = re.compile(r"^\[([^\]]*)\]\s*(.*)$")
_ROLE = re.compile(r":(?:py:)?(?:mod|class|func|meth|attr|data|obj|exc|const):`(~?)([^`<>]+)`")


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _field_comments(cls: type) -> dict[str, str]:
    """Field name -> the comment that ends its line in the class body."""
    source = inspect.getsource(cls)
    comments = {
        token.start[0]: token.string.lstrip("#").strip()
        for token in tokenize.generate_tokens(io.StringIO(source).readline)
        if token.type == tokenize.COMMENT
    }
    found = {}
    for node in ast.parse(source).body[0].body:
        if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            end = node.end_lineno or node.lineno
            if end in comments:
                found[node.target.id] = comments[end]
    return found


def _default(field: dataclasses.Field[Any]) -> str:
    if field.default is not dataclasses.MISSING:
        value = field.default
        if isinstance(value, float):
            return "2π" if math.isclose(value, 2 * math.pi) else f"`{value:g}`"
        return f"`{value!r}`"
    if field.default_factory is not dataclasses.MISSING:
        doc = inspect.getdoc(field.default_factory)
        value = repr(field.default_factory())
        if len(value) <= 40:
            return f"`{value}`"
        return _cell(doc.splitlines()[0]) if doc else "(computed)"
    return "required"


def _type_name(field: dataclasses.Field[Any]) -> str:
    """The annotation as plain text (a code span would show the table's escaped ``|``)."""
    return field.type if isinstance(field.type, str) else inspect.formatannotation(field.type)


def dataclass_table(path: str) -> str:
    """A markdown table of the fields of the dataclass at dotted ``path``."""
    module_name, _, class_name = path.rpartition(".")
    cls = getattr(importlib.import_module(module_name), class_name)
    comments = _field_comments(cls)
    rows = ["| key | type | default | unit | meaning |", "|---|---|---|---|---|"]
    for field in dataclasses.fields(cls):
        if not field.repr:  # bookkeeping, not a setting
            continue
        comment = comments.get(field.name, "")
        match = _UNIT.match(comment)
        unit, meaning = (match[1], match[2]) if match else ("", comment)
        unit = "" if unit == "-" else unit
        rows.append(f"| `{field.name}` | {_cell(_type_name(field))} | "
                    f"{_cell(_default(field))} | {_cell(unit)} | {_cell(meaning)} |")
    return "\n".join(rows)


def results_table(file: str, name: str) -> str:
    """A markdown table of ``tables[name]`` in ``docs/results/file``, and where it came from."""
    data = json.loads((RESULTS / file).read_text())
    table = data["tables"][name]
    lines = ["| " + " | ".join(map(_cell, table["columns"])) + " |",
             "|" + "---|" * len(table["columns"])]
    lines += ["| " + " | ".join(map(_cell, row)) + " |" for row in table["rows"]]
    lines.append("")
    lines.append(f"*From `docs/results/{file}`, written by `{data['command']}` "
                 f"({data['hardware']}).*")
    return "\n".join(lines)


def with_results_tables(markdown: str) -> str:
    """``markdown`` with the block after each results-table marker (the table and its
    provenance line, or nothing yet) written afresh from the results file."""
    lines, out, i = markdown.splitlines(), [], 0
    while i < len(lines):
        out.append(lines[i])
        match = _RESULTS.match(lines[i])
        i += 1
        if match is None:
            continue
        while i < len(lines) and (lines[i].startswith("|") or not lines[i].strip()
                                  or lines[i].startswith("*From `docs/results/")):
            if not lines[i].strip() and i + 1 < len(lines) and not (
                    lines[i + 1].startswith(("|", "*From `docs/results/"))):
                break
            i += 1
        out.extend(results_table(match[1], match[2]).splitlines())
    return "\n".join(out) + ("\n" if markdown.endswith("\n") else "")


def on_page_markdown(markdown: str, **kwargs: Any) -> str:
    markdown = _DATACLASS.sub(lambda m: dataclass_table(m[1]), markdown)
    return with_results_tables(markdown)


def refresh_pages() -> list[Path]:
    """Write every results table of the docs pages afresh (so they read on GitHub too);
    returns the pages that changed."""
    changed = []
    for page in sorted(DOCS.rglob("*.md")):
        text = page.read_text()
        fresh = with_results_tables(text)
        if fresh != text:
            page.write_text(fresh)
            changed.append(page)
    return changed


def _target(obj: griffe.Object, name: str) -> str:
    """The dotted path a role's ``name`` means inside ``obj``'s module (relative or bare)."""
    module = obj.module
    if name.startswith("."):
        package = module if module.is_init_module else module.parent
        while name.startswith("..") and package is not None and package.parent is not None:
            package, name = package.parent, name[1:]
        return f"{package.path}{name}" if package is not None else name.lstrip(".")
    if "." not in name and name in module.members:
        return f"{module.path}.{name}"
    return name


class SphinxRoles(griffe.Extension):
    """Sphinx roles in docstrings become optional cross-references (see the module docstring)."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is None:
            return

        def link(match: re.Match[str]) -> str:
            short, name = match[1] == "~", match[2].strip()
            shown = name.rsplit(".", 1)[-1] if short else name
            target = _target(obj, name)
            return f'<autoref identifier="{target}" optional><code>{shown}</code></autoref>'

        obj.docstring.value = _fence_doctests(_ROLE.sub(link, obj.docstring.value))


def _fence_doctests(text: str) -> str:
    """Runs of ``>>>`` / ``...`` lines as fenced ``pycon`` blocks, so Markdown does not read
    their brackets as links."""
    lines, out, i = text.splitlines(), [], 0
    while i < len(lines):
        stripped = lines[i].lstrip()
        if not stripped.startswith(">>>"):
            out.append(lines[i])
            i += 1
            continue
        indent = lines[i][: len(lines[i]) - len(stripped)]
        out.append(f"{indent}```pycon")
        while i < len(lines) and lines[i].lstrip().startswith((">>>", "...")):
            out.append(lines[i])
            i += 1
        out.append(f"{indent}```")
    return "\n".join(out)


def _markdown_tables(markdown: str) -> dict[str, dict[str, list]]:
    """Every table of ``markdown`` under the heading above it: ``{"columns", "rows"}``."""
    found: dict[str, dict[str, list]] = {}
    lines, title, i = markdown.splitlines(), "", 0
    while i < len(lines):
        if lines[i].startswith("#"):
            title = lines[i].lstrip("#").strip()
        if lines[i].startswith("|") and i + 1 < len(lines) and set(lines[i + 1]) <= set("|-: "):
            columns = [c.strip() for c in lines[i].strip().strip("|").split("|")]
            rows, i = [], i + 2
            while i < len(lines) and lines[i].startswith("|"):
                rows.append([c.strip() for c in lines[i].strip().strip("|").split("|")])
                i += 1
            found[title] = {"columns": columns, "rows": rows}
            continue
        i += 1
    return found


LEADERBOARD_FIGURES = ("fig8_traces", "fig8_lidar_image", "maps", "segment_errors",
                       "speed_accuracy", "relation_errors")


def import_leaderboard(out: Path, db: Path, command: str) -> Path:
    """``docs/results/leaderboard.json`` (and its CSVs and figures) from a leaderboard run's
    output folder ``out`` and database ``db``; returns the JSON's path."""
    import shutil
    import sqlite3

    board, table1 = (out / "leaderboard.md").read_text(), (out / "table1.md").read_text()
    tables = {}
    for title, table in _markdown_tables(board).items():
        if title.startswith("duallidar leaderboard"):
            tables["headline"] = table
        elif title.startswith("Maps at the estimated poses"):
            tables["maps"] = table
        else:
            tables[title.replace(" (mean ± std over seeds)", "")] = table
    tables["table1"] = next(iter(_markdown_tables(table1).values()))
    paragraphs = [part.strip() for part in board.split("\n\n")
                  if part.strip() and not part.startswith(("|", "#"))]
    with sqlite3.connect(db) as connection:
        versions = sorted(v for (v,) in connection.execute(
            "SELECT DISTINCT package_version FROM traces"))
    cpu = next((line.split(":", 1)[1].strip() for line in
                Path("/proc/cpuinfo").read_text().splitlines() if line.startswith("model name")),
               "unknown CPU")
    files = {name: f"OUT/{name}" for name in ("leaderboard.csv", "results.csv", "table1.csv")}
    files.update({f"figures/{name}.png": f"OUT/{name}.png" for name in LEADERBOARD_FIGURES})
    (RESULTS / "figures").mkdir(parents=True, exist_ok=True)
    for name, source in files.items():
        shutil.copyfile(out / source.removeprefix("OUT/"), RESULTS / name)
    document = {
        "what": "The leaderboard's default run: every registered estimator on the paper's three "
                "groups plus the hallway straight and out-and-back drives (seeds 0 and 1, 1 cm "
                "range noise, sensor-frame scans, scripted driver) and the first 1,000 scans of "
                "the ACES log; Table I beside the paper.",
        "command": command,
        "equivalent": "bash scripts/leaderboard.sh (writes ./leaderboard/)",
        "hardware": f"{os.cpu_count()}-core {cpu}",
        "python": f"CPython {sys.version.split()[0]}",
        "source_version": ", ".join(versions),
        "tables_from": "the markdown tables of OUT/leaderboard.md and OUT/table1.md, cell for cell",
        "files": files,
        "notes": {
            "headline": next(p for p in paragraphs if p.startswith("Simulated figures")),
            "ties": next(p for p in paragraphs if p.startswith("Ties")),
            "true_pose_maps": next(p for p in paragraphs if p.startswith("Maps at the true")),
            "table1": next(part.strip() for part in table1.split("\n\n")
                           if part.startswith("world-aligned")),
        },
        "tables": tables,
    }
    path = RESULTS / "leaderboard.json"
    path.write_text(json.dumps(document, indent=1, ensure_ascii=False) + "\n")
    return path


_README_MARKER = re.compile(r"^<!-- results: docs/results/([\w.\-]+\.json) (.+?) -->$")


def refresh_readme(readme: Path) -> bool:
    """Write the README's results table (a choice of rows and columns of a results table,
    rows named by their estimator, in its order) afresh from the results file; True if it
    changed."""
    text = readme.read_text()
    lines, i = text.splitlines(), 0
    while i < len(lines):
        match = _README_MARKER.match(lines[i])
        i += 1
        if match is None:
            continue
        table = json.loads((RESULTS / match[1]).read_text())["tables"][match[2]]
        named = table["columns"].index("estimator")
        by_name = {row[named]: dict(zip(table["columns"], row, strict=True))
                   for row in table["rows"]}
        order = list(by_name)
        columns = [c.strip() for c in lines[i].strip().strip("|").split("|")]
        i += 2
        first, rows = i, []
        while i < len(lines) and lines[i].startswith("|"):
            cells = [c.strip() for c in lines[i].strip().strip("|").split("|")]
            name = cells[columns.index("estimator")].split()[0]
            held = by_name[name]
            cells = [held[column] if column in held and column != "estimator" else cell
                     for column, cell in zip(columns, cells, strict=True)]
            rows.append((order.index(name), "| " + " | ".join(cells) + " |"))
            i += 1
        lines[first:i] = [row for _, row in sorted(rows)]  # in the results table's order
    fresh = "\n".join(lines) + "\n"
    if fresh != text:
        readme.write_text(fresh)
    return fresh != text


def main(argv: list[str] | None = None) -> int:
    import argparse

    parser = argparse.ArgumentParser(
        prog="python docs/hooks.py",
        description="Write the docs pages' results tables afresh from docs/results/; with "
                    "--leaderboard, first import a leaderboard run into docs/results/.")
    parser.add_argument("--leaderboard", type=Path, metavar="OUT",
                        help="a duallidar-leaderboard output folder to import")
    parser.add_argument("--db", type=Path, help="its database (default: OUT/experiments.sqlite)")
    parser.add_argument("--command", help="the command that made OUT (default: "
                        "duallidar-leaderboard --out OUT [--db DB])")
    args = parser.parse_args(argv)
    if args.leaderboard is not None:
        db = args.db or args.leaderboard / "experiments.sqlite"
        command = args.command or " ".join(
            ["duallidar-leaderboard", "--out", str(args.leaderboard)]
            + (["--db", str(args.db)] if args.db else []))
        print(f"wrote {import_leaderboard(args.leaderboard, db, command).relative_to(DOCS.parent)}")
    for changed in refresh_pages():
        print(f"refreshed {changed.relative_to(DOCS.parent)}")
    if refresh_readme(DOCS.parent / "README.md"):
        print("refreshed README.md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
