"""``leaderboard/report.html``: the whole leaderboard in one self-contained page to open in a
browser (:func:`write_report`): the headline table, the per-group tables, Table I beside the
paper's numbers, every figure embedded as a data URI (no file or network fetch), the
configuration and versions used and the command that reproduces the run. Tables sort on a
click of their header (a few lines of plain JavaScript, no framework). The Markdown tables of
:mod:`estimators.leaderboard.headline` and :mod:`estimators.leaderboard.table_one` are
converted by :func:`markdown_to_html` (tables, ``#``-headings and paragraphs only).
"""

from __future__ import annotations

import base64
import html
import platform
from collections.abc import Mapping, Sequence
from importlib import metadata
from pathlib import Path

_STYLE = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1250px; color: #222; }
table { border-collapse: collapse; margin: 0.5em 0 1.5em; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: right; }
td:nth-child(2), th:nth-child(2) { text-align: left; }
th { background: #eee; cursor: pointer; user-select: none; }
th.sorted-asc::after { content: " \\25B2"; } th.sorted-desc::after { content: " \\25BC"; }
figure { margin: 1.5em 0; } figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { font-size: 0.9em; color: #555; } code, pre { background: #f6f6f6; }
pre { padding: 0.6em; overflow-x: auto; }
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


def _figure(path: Path, caption: str) -> str:
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    return (f'<figure><img src="data:image/png;base64,{data}" alt="{html.escape(caption)}">'
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


def write_report(path: Path, *, title: str, board: str, table_one: str | None,
                 figures: Mapping[Path, str], config: Mapping[str, object],
                 command: str) -> Path:
    """Write the report to ``path`` and return it. ``board``: the Markdown of
    :func:`estimators.leaderboard.headline.board_markdown`; ``table_one``: Table I's Markdown
    (None when the run held none of its cases); ``figures``: PNG -> caption, embedded in order;
    ``config``: the run's settings; ``command``: the shell command that reproduces the run."""
    settings = {**{key: str(value) for key, value in config.items()}, **versions()}
    listing = "".join(f"<tr><td>{html.escape(k)}</td><td>{html.escape(v)}</td></tr>\n"
                      for k, v in settings.items())
    sections = [f"<h1>{html.escape(title)}</h1>",
                f"<p>Reproduce: <code>{html.escape(command)}</code></p>",
                "<h2>Leaderboard</h2>", markdown_to_html(board),
                "<h2>Table I: the paper's accuracy beside ours</h2>",
                markdown_to_html(table_one) if table_one else
                "<p>Not in this run: it holds none of the paper's world/trace pairs.</p>",
                "<h2>Figures</h2>",
                *(_figure(p, caption) for p, caption in figures.items() if p.exists()),
                "<h2>Configuration and versions</h2>",
                f'<table class="sortable"><thead><tr><th>setting</th><th>value</th></tr>'
                f"</thead><tbody>\n{listing}</tbody></table>"]
    page = (f'<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
            f"<title>{html.escape(title)}</title>\n<style>{_STYLE}</style>\n</head>\n<body>\n"
            + "\n".join(sections) + f"\n<script>{_SCRIPT}</script>\n</body>\n</html>\n")
    path.write_text(page, encoding="utf-8")
    return path
