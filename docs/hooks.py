"""MkDocs hooks: tables the pages do not hold by hand.

A page asks for a table with an HTML comment on a line of its own:

- ``<!-- dataclass-table: lidar_env.config.EnvConfig -->``: one row per field of the
  dataclass (key, type, default, unit, meaning), read from its source, so the reference cannot
  drift from the code. The unit and meaning come from the field's trailing comment
  (``x: float = 1.0  # [m] what it is``).
- ``<!-- results-table: leaderboard.json headline -->``: a table of a results file in
  ``docs/results/`` (its ``tables[NAME]``: ``columns`` and ``rows``), followed by the command
  that wrote it.

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
import re
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


def on_page_markdown(markdown: str, **kwargs: Any) -> str:
    markdown = _DATACLASS.sub(lambda m: dataclass_table(m[1]), markdown)
    return _RESULTS.sub(lambda m: results_table(m[1], m[2]), markdown)


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
