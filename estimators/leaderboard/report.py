"""``leaderboard/report.html``: the whole leaderboard in one self-contained page to open in a
browser (:func:`write_report`). Its first screen (1280 x 800) answers: the lead paragraph of
:func:`estimators.leaderboard.summary.lead_paragraph`, the headline table beside the traces of
one group; below come the per-group and map tables, Table I beside the paper's numbers, every
figure at print size (96 px per inch, from the PNG's width and
:data:`~estimators.leaderboard.style.DPI`), the configuration as option/value rows, the
versions and the command that reproduces the run. Figures are embedded as data URIs (no file
or network fetch); tables sort on a click of their header (a few lines of plain JavaScript).
The Markdown the leaderboard writes is converted by :func:`markdown_to_html` (tables,
``#``-headings and paragraphs only) after :func:`split_board` has cut the board into its parts.
"""

from __future__ import annotations

import base64
import html
import platform
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

from estimators.leaderboard.style import DPI

_STYLE = """
body { font-family: system-ui, sans-serif; margin: 0 auto; padding: 10px 16px 2em;
       max-width: 1248px; color: #222; font-size: 15px; line-height: 1.35; }
h1 { font-size: 1.4em; margin: 0.1em 0 0.3em; } h2 { margin-top: 1.6em; }
p.lead { margin: 0 0 0.6em; }
.top { display: flex; gap: 12px 20px; align-items: flex-start; }
.top .headline { flex: 1 1 auto; } .top .headline table { margin: 0 0 0.3em; }
.top td { white-space: nowrap; }
.top figure { flex: 0 1 520px; min-width: 360px; margin: 0; }
@media (max-width: 1100px) { .top { flex-wrap: wrap; } }
p.note { font-size: 0.8em; color: #555; margin: 0.2em 0; max-width: 760px; }
nav { font-size: 0.9em; margin: 0.6em 0; }
table { border-collapse: collapse; margin: 0.4em 0 1.2em; font-size: 0.85em; }
th, td { border: 1px solid #ccc; padding: 0.2em 0.5em; text-align: right; }
td:nth-child(2), th:nth-child(2) { text-align: left; }
th { background: #eee; cursor: pointer; user-select: none; }
th.sorted-asc::after { content: " \\25B2"; } th.sorted-desc::after { content: " \\25BC"; }
table.settings td, table.settings th { text-align: left; }
figure { margin: 1.2em 0; } figure img { max-width: 100%; height: auto; }
figcaption { font-size: 0.85em; color: #555; } code, pre { background: #f6f6f6; }
pre { padding: 0.6em; overflow-x: auto; white-space: pre-wrap; }
"""

# Sort a table by the clicked column: numbers by value (the leading number of "1.2 ± 0.1",
# "=3"), "n/a" last, text alphabetically; a second click reverses. After load, the count of
# images that failed to decode goes to <body data-broken-images> (what the browser test reads).
_SCRIPT = """
function cellKey(cell) {
  const match = cell.textContent.trim().match(/^=?(-?\\d+(?:\\.\\d+)?(?:e-?\\d+)?)/);
  return match ? parseFloat(match[1]) : cell.textContent.trim().toLowerCase();
}
function sortTable(header) {
  const table = header.closest("table"), body = table.tBodies[0];
  const column = Array.from(header.parentNode.children).indexOf(header);
  const ascending = !header.classList.contains("sorted-asc");
  table.querySelectorAll("th").forEach(th => th.classList.remove("sorted-asc", "sorted-desc"));
  header.classList.add(ascending ? "sorted-asc" : "sorted-desc");
  const rows = Array.from(body.rows).sort((a, b) => {
    const x = cellKey(a.cells[column]), y = cellKey(b.cells[column]);
    if (typeof x !== typeof y) return typeof x === "number" ? -1 : 1;
    return (x < y ? -1 : x > y ? 1 : 0) * (ascending ? 1 : -1);
  });
  rows.forEach(row => body.appendChild(row));
}
document.querySelectorAll("th").forEach(th => th.addEventListener("click", () => sortTable(th)));
window.addEventListener("load", () => {
  const broken = Array.from(document.images).filter(i => !i.complete || i.naturalWidth === 0);
  document.body.dataset.brokenImages = String(broken.length);
});
"""


def _inline(text: str) -> str:
    """Escape ``text`` for HTML, keeping Markdown `code` spans as <code>."""
    parts = html.escape(text).split("`")
    return "".join(f"<code>{part}</code>" if index % 2 else part
                   for index, part in enumerate(parts))


def _table(lines: Sequence[str]) -> str:
    rows = [[cell.strip() for cell in line.strip().strip("|").split("|")] for line in lines]
    header, body = rows[0], [r for r in rows[1:] if not all(set(c) <= {"-", ":"} for c in r)]
    head = "".join(f"<th>{_inline(cell)}</th>" for cell in header)
    cells = "".join("<tr>" + "".join(f"<td>{_inline(c)}</td>" for c in row) + "</tr>\n"
                    for row in body)
    return f'<table class="sortable">\n<thead><tr>{head}</tr></thead>\n<tbody>\n{cells}</tbody>' \
           "\n</table>"


def markdown_to_html(text: str, heading_offset: int = 1) -> str:
    """The Markdown the leaderboard writes as HTML: ``|`` tables, ``#`` headings (moved down
    ``heading_offset`` levels) and paragraphs; everything else is escaped text."""
    blocks: list[str] = []
    table: list[str] = []
    for line in [*text.splitlines(), ""]:
        if line.lstrip().startswith("|"):
            table.append(line)
            continue
        if table:
            blocks.append(_table(table))
            table = []
        stripped = line.strip()
        if stripped.startswith("#"):
            level = min(6, len(stripped) - len(stripped.lstrip("#")) + heading_offset)
            blocks.append(f"<h{level}>{_inline(stripped.lstrip('#').strip())}</h{level}>")
        elif stripped:
            blocks.append(f"<p>{_inline(stripped)}</p>")
    return "\n".join(blocks)


def png_width(data: bytes) -> int | None:
    """The width [px] in a PNG's header (None when ``data`` is no PNG)."""
    if data[:8] != b"\x89PNG\r\n\x1a\n" or data[12:16] != b"IHDR":
        return None
    return int.from_bytes(data[16:20], "big")


def _figure(path: Path, caption: str) -> str:
    """A PNG embedded as a data URI, shown at print size (its width at :data:`DPI`, 96 css px
    per inch; narrower when the page is)."""
    data = path.read_bytes()
    width = png_width(data)
    size = f' width="{round(width * 96 / DPI)}"' if width else ""
    encoded = base64.b64encode(data).decode("ascii")
    return (f'<figure><img src="data:image/png;base64,{encoded}"{size} '
            f'alt="{html.escape(caption)}">'
            f"<figcaption>{html.escape(caption)}</figcaption></figure>")


def versions() -> dict[str, str]:
    """Versions of Python and of the libraries behind the numbers and figures."""
    found = {"python": platform.python_version(), "platform": platform.platform()}
    for name in ("duallidar", "numpy", "scipy", "numba", "pymunk", "gymnasium", "matplotlib"):
        try:
            found[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            found[name] = "not installed"
    return found


@dataclass(frozen=True)
class BoardParts:
    """The board's Markdown (:func:`estimators.leaderboard.headline.board_markdown`) cut into
    what the report places apart: the lead paragraph, the headline table, the notes under it
    and the rest (the ``##`` sections: per-group and map tables)."""

    lead: str
    table: str
    notes: str
    rest: str


def split_board(board: str) -> BoardParts:
    """Cut ``board`` at its first table (the headline) and at its first ``#`` heading after it;
    the text before the table is the lead."""
    lines = board.splitlines()
    first = next((i for i, line in enumerate(lines) if line.lstrip().startswith("|")),
                 len(lines))
    end = next((i for i in range(first, len(lines)) if not lines[i].lstrip().startswith("|")),
               len(lines))
    rest = next((i for i in range(end, len(lines)) if lines[i].lstrip().startswith("#")),
                len(lines))
    return BoardParts(" ".join(line.strip() for line in lines[:first] if line.strip()),
                      "\n".join(lines[first:end]), "\n".join(lines[end:rest]),
                      "\n".join(lines[rest:]))


def _two_columns(rows: Sequence[tuple[str, str]], header: tuple[str, str]) -> str:
    body = "".join(f"<tr><td>{html.escape(key)}</td><td>{html.escape(value)}</td></tr>\n"
                   for key, value in rows)
    return (f'<table class="sortable settings"><thead><tr><th>{header[0]}</th><th>{header[1]}'
            f"</th></tr></thead><tbody>\n{body}</tbody></table>")


def write_report(path: Path, *, title: str, board: str, table_one: str | None,
                 figures: Mapping[Path, str], settings: Sequence[tuple[str, str]],
                 command: str, lead_figure: tuple[Path, str] | None = None) -> Path:
    """Write the report to ``path`` and return it. ``board``: the Markdown of
    :func:`estimators.leaderboard.headline.board_markdown` (with any notes after it);
    ``table_one``: Table I's Markdown (None when the run held none of its cases); ``figures``:
    PNG -> caption, embedded in order; ``settings``: the run's (option, value) rows
    (:func:`estimators.leaderboard.settings.describe_settings`); ``command``: the shell command
    that reproduces the run; ``lead_figure``: (PNG, caption) shown beside the headline table."""
    parts = split_board(board)
    notes = "".join(f'<p class="note">{_inline(line.strip())}</p>'
                    for line in parts.notes.splitlines() if line.strip())
    beside = (_figure(*lead_figure) if lead_figure and lead_figure[0].exists() else "")
    top = [f"<h1>{html.escape(title)}</h1>",
           f'<p class="lead">{_inline(parts.lead)}</p>' if parts.lead else "",
           f'<div class="top"><section class="headline">{markdown_to_html(parts.table)}'
           f"{notes}</section>{beside}</div>",
           '<nav>Below: <a href="#groups">per-group and map tables</a> · '
           '<a href="#table-one">Table I</a> · <a href="#figures">figures</a> · '
           '<a href="#configuration">configuration and versions</a></nav>']
    sections = [*top,
                '<h2 id="groups">Per-group and map tables</h2>', markdown_to_html(parts.rest),
                '<h2 id="table-one">Table I: the paper\'s accuracy beside ours</h2>',
                markdown_to_html(table_one) if table_one else
                "<p>Not in this run: it holds none of the paper's world/trace pairs.</p>",
                '<h2 id="figures">Figures</h2>',
                *(_figure(p, caption) for p, caption in figures.items() if p.exists()),
                '<h2 id="configuration">Configuration and versions</h2>',
                _two_columns(settings, ("option", "value")),
                _two_columns(list(versions().items()), ("software", "version")),
                f"<p>Reproduce the run:</p><pre><code>{html.escape(command)}</code></pre>"]
    page = (f'<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
            f"<title>{html.escape(title)}</title>\n<style>{_STYLE}</style>\n</head>\n<body>\n"
            + "\n".join(s for s in sections if s)
            + f"\n<script>{_SCRIPT}</script>\n</body>\n</html>\n")
    path.write_text(page, encoding="utf-8")
    return path
