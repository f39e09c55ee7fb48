"""``report.html`` rendered in a real browser (headless Chromium): not blank, its tables in the
DOM, no broken image, no fetch beyond the file itself; and the Markdown it is built from."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from estimators.leaderboard.report import markdown_to_html, split_board, write_report
from estimators.leaderboard.style import DPI

BOARD = """slam ranks first; slam and lidar_odometry tie (paired Wilcoxon, p = 0.62).

| # | estimator | ATE [m] |
|---|---|---|
| 1 | slam | 0.017 ± 0.002 |
| =1 | lidar_odometry | 0.018 ± 0.001 |
| 3 | zero | 16.706 ± 0.100 |
Simulated figures: mean ± std over 2 seeds.

Ties (`=k`): the paired Wilcoxon test.

## Per group: each table ranked by the group's own ATE [m]

### G1 open+right_turn (mean ± std over seeds)

| # | estimator | ATE [m] | runs | overall # |
|---|---|---|---|---|
| 1 | slam | 0.007 ± 0.001 | 2 | 1 |
"""
TABLE_ONE = "| case | paper [%] | ours [%] |\n|---|---|---|\n| 1 | 31.25 | 30.1 ± 2.0 (2) |\n"
BROWSER_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run"]


def chromium() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        if path := shutil.which(name):
            return path
    pytest.skip("no headless browser: install Debian's chromium (bash scripts/setup.sh does "
                "it with apt-get where it can) to render report.html")


def browse(report: Path, profile: Path, *options: str) -> str:
    profile.mkdir()
    done = subprocess.run([chromium(), *BROWSER_FLAGS, f"--user-data-dir={profile}",
                           "--virtual-time-budget=5000", *options, report.as_uri()],
                          capture_output=True, text=True, timeout=120, check=True)
    return done.stdout


def a_figure(path: Path) -> Path:
    from matplotlib.figure import Figure

    figure = Figure(figsize=(4, 3))
    figure.add_subplot().plot([0, 1, 2], [0, 1, 4], color="#1f77b4")
    figure.savefig(path, dpi=100)
    return path


def make_report(tmp_path: Path, figures: dict[Path, str],
                lead: tuple[Path, str] | None = None) -> Path:
    return write_report(tmp_path / "report.html", title="duallidar leaderboard (test)",
                        board=BOARD, table_one=TABLE_ONE, figures=figures,
                        settings=[("--seeds", "0, 1"), ("--noise", "0.01")],
                        command="python -m estimators.leaderboard --seeds 0 1", lead_figure=lead)


def test_markdown_tables_become_sortable_html_tables() -> None:
    page = markdown_to_html(BOARD)
    assert page.count('<table class="sortable">') == 2
    assert "<th>ATE [m]</th>" in page and "<td>=1</td><td>lidar_odometry</td>" in page
    assert "<h3>Per group: each table ranked by the group&#x27;s own ATE [m]</h3>" in page
    assert "<h4>G1 open+right_turn (mean ± std over seeds)</h4>" in page
    assert "---" not in page  # the separator row is no data row
    assert "<code>x</code>" in markdown_to_html("a `x` b") and "&lt;b&gt;" in markdown_to_html(
        "<b>")


def test_the_board_is_cut_into_lead_headline_notes_and_the_rest() -> None:
    parts = split_board(BOARD)
    assert parts.lead == "slam ranks first; slam and lidar_odometry tie (paired Wilcoxon, " \
                         "p = 0.62)."
    assert parts.table.splitlines()[0] == "| # | estimator | ATE [m] |"
    assert parts.table.splitlines()[-1] == "| 3 | zero | 16.706 ± 0.100 |"
    assert parts.notes.split() == "Simulated figures: mean ± std over 2 seeds. Ties (`=k`): " \
                                  "the paired Wilcoxon test.".split()
    assert parts.rest.startswith("## Per group") and parts.rest.endswith("| 2 | 1 |")


def test_the_report_is_one_file_with_everything_inside(tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    lead = (a_figure(tmp_path / "lead.png"), "one group's traces")
    report = make_report(tmp_path, {a_figure(tmp_path / "fig.png"): "a test figure"}, lead)
    page = report.read_text()
    assert page.count("data:image/png;base64,") == 2
    # nothing fetched from elsewhere: the only links are to the page's own sections
    assert "src=\"http" not in page
    assert all(link.startswith("#") for link in re.findall(r'href="([^"]*)"', page))
    for text in ("python -m estimators.leaderboard --seeds 0 1", "31.25", "numpy", "noise",
                 "Table I", "<td>--seeds</td><td>0, 1</td>"):
        assert text in page, text
    # the answer comes first: lead paragraph, headline table and lead figure before the rest
    order = [page.index(text) for text in ('<p class="lead">slam ranks first', "<td>=1</td>",
                                           "one group&#x27;s traces", "<h4>G1", "Table I:",
                                           "a test figure", "<td>--seeds</td>")]
    assert order == sorted(order)
    # figures at print size, read as written at the leaderboard's DPI: 96 css px per inch
    assert f'width="{round(400 * 96 / DPI)}"' in page  # a_figure is 400 px wide


@pytest.mark.slow
def test_the_report_renders_in_headless_chromium(tmp_path: Path) -> None:
    from PIL import Image

    pytest.importorskip("matplotlib")
    figure = a_figure(tmp_path / "fig.png")
    report = make_report(tmp_path, {figure: "a test figure"})
    screenshot = tmp_path / "shot.png"
    browse(report, tmp_path / "profile1", f"--screenshot={screenshot}",
           "--window-size=1280,2000")
    with Image.open(screenshot) as image:
        pixels = np.asarray(image.convert("L"), dtype=np.float64)
    assert pixels.shape == (2000, 1280)
    assert pixels.std() > 10 and (pixels < 128).mean() > 0.001  # text and lines: not blank
    dom = browse(report, tmp_path / "profile2", "--dump-dom")
    assert 'data-broken-images="0"' in dom
    # headline, group, Table I, configuration, versions
    assert dom.count("<table") == 5 and "<td>lidar_odometry</td>" in dom

    # the check can fail: a figure whose bytes are no image is counted as broken
    figure.write_bytes(b"not a png")
    dom = browse(make_report(tmp_path, {figure: "broken"}), tmp_path / "profile3", "--dump-dom")
    assert 'data-broken-images="1"' in dom


@pytest.mark.slow
def test_sorting_a_column_orders_its_rows_by_value(tmp_path: Path) -> None:
    report = make_report(tmp_path, {})
    # click the ATE header of the first table once (ascending), then read the row order
    page = report.read_text().replace(
        "</body>", "<script>window.addEventListener('load', () => { const th = "
        "document.querySelectorAll('th')[2]; th.click(); th.click(); document.title = "
        "Array.from(th.closest('table').tBodies[0].rows).map(r => r.cells[1].textContent)"
        ".join(','); });</script></body>")
    report.write_text(page)
    dom = browse(report, tmp_path / "profile", "--dump-dom")
    assert "<title>zero,lidar_odometry,slam</title>" in dom  # descending after two clicks


@pytest.mark.slow
def test_a_leaderboard_run_writes_every_figure_and_a_report_that_renders(tmp_path: Path) -> None:
    from PIL import Image

    from estimators.leaderboard import cli as leaderboard

    pytest.importorskip("matplotlib")
    out = tmp_path / "board"
    assert leaderboard.main(["--worlds", "hallway", "--traces", "straight", "--seeds", "0",
                             "--estimators", "zero", "pc", "--workers", "2", "--no-progress",
                             "--no-real", "--out", str(out)]) == 0  # figures drawn by 2 workers
    figures = sorted(out.glob("*.png"))
    assert {p.name for p in figures} == {"lead_traces.png", "fig8_lidar_image.png",
                                        "fig8_traces.png", "maps.png", "segment_errors.png",
                                        "speed_accuracy.png"}
    for png in figures:
        with Image.open(png) as image:
            assert min(image.info["dpi"]) >= 150 and min(image.size) > 300, png.name
        assert png.with_suffix(".svg").read_text().lstrip().startswith("<?xml"), png.name
    page = (out / "report.html").read_text()
    assert page.count("data:image/png;base64,") == len(figures)
    assert "--estimators zero pc" in page and "|---|" not in page  # every table converted
    dom = browse(out / "report.html", tmp_path / "profile", "--dump-dom")
    assert 'data-broken-images="0"' in dom and "<td>zero</td>" in dom


#: Reads where the first screen's parts are, once the page has loaded: their boxes
#: (left, top, right, bottom) [css px] go into the title, which --dump-dom prints.
MEASURE = """<script>window.addEventListener('load', () => {
  const box = e => { const r = e.getBoundingClientRect();
                     return [r.left, r.top, r.right, r.bottom].map(Math.round).join(','); };
  document.title = ['p.lead', '.top table', '.top figure img']
    .map(s => s + '=' + box(document.querySelector(s))).join(';');
});</script></body>"""


def full_board(estimators: int = 10) -> str:
    """A board the size of the default run's: a long lead paragraph, ten estimators, eight
    columns with the real log's."""
    lead = " ".join(["10 estimators ran on 10 simulated runs: 5 scenario groups × 2 seeds, and "
                     "on the ACES log; slam ranks first at 0.035 m."] * 5)
    header = ["#", "estimator", "eq.-11 accuracy [%]", "ATE [m]", "heading RMSE [deg]",
              "drift [%]", "ms/step", "ACES rel. error [m]"]
    body = [[f"={k}" if k % 2 else str(k + 1), f"estimator_{k}", "99.2 ± 0.1", "14.371 ± 0.002",
             "46.32 ± 0.01", "79.8 ± 0.1", "18.93 ± 0.20", "n/a (needs 2 Lidars)"]
            for k in range(estimators)]
    table = "\n".join("| " + " | ".join(cells) + " |" for cells in [header, ["---"] * 8, *body])
    notes = "Simulated figures: mean ± std over 2 seeds.\n\n" + "Ties (`=k`): Wilcoxon. " * 8
    return f"{lead}\n\n{table}\n{notes}\n\n## G1\n\n| # | estimator |\n|---|---|\n| 1 | slam |\n"


@pytest.mark.slow
def test_the_first_screen_shows_the_answer_at_1280_by_800(tmp_path: Path) -> None:
    """At 1280 x 800 the lead paragraph, the headline table and the lead figure lie wholly
    within the first screen, and the screenshot shows them (not blank)."""
    from matplotlib.figure import Figure
    from PIL import Image

    from estimators.leaderboard.style import save_figure

    figure = Figure(figsize=(5.6, 5.0))  # the size of draw_lead_figure's
    figure.add_subplot().plot([0, 1, 2], [0, 1, 4], color="#1f77b4")
    lead = (save_figure(figure, tmp_path / "lead.png")[0], "one group's traces")
    report = write_report(tmp_path / "report.html", title="duallidar leaderboard (test)",
                          board=full_board(), table_one=TABLE_ONE, figures={},
                          settings=[("--seeds", "0, 1")], command="python -m x", lead_figure=lead)
    report.write_text(report.read_text().replace("</body>", MEASURE))
    dom = browse(report, tmp_path / "profile1", "--dump-dom", "--window-size=1280,800")
    title = re.search(r"<title>(.*?)</title>", dom).group(1)
    boxes = {name: [int(v) for v in box.split(",")]
             for name, box in (part.split("=") for part in title.split(";"))}
    for name, (left, top, right, bottom) in boxes.items():
        assert 0 <= left < right <= 1280 and 0 <= top < bottom <= 800, (name, boxes)
    table, image = boxes[".top table"], boxes[".top figure img"]
    assert table[2] <= image[0] and image[2] - image[0] >= 360  # side by side, readable
    assert boxes["p.lead"][3] <= table[1]

    screenshot = tmp_path / "first_screen.png"
    browse(report, tmp_path / "profile2", f"--screenshot={screenshot}", "--window-size=1280,800")
    with Image.open(screenshot) as shot:
        pixels = np.asarray(shot.convert("L"), dtype=np.float64)
    assert pixels.shape == (800, 1280) and pixels.std() > 10
    left, top, right, bottom = table
    inside = pixels[top:bottom, left:right]
    assert (inside < 100).mean() > 0.02  # the table's text and rules are drawn
    left, top, right, bottom = image
    assert (pixels[top:bottom, left:right] < 200).mean() > 0.005  # the figure's axes and line
