"""``report.html`` rendered in a real browser (headless Chromium): not blank, its tables in the
DOM, no broken image, no fetch beyond the file itself; and the Markdown it is built from."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from estimators.leaderboard.report import markdown_to_html, write_report

BOARD = """Simulated figures: mean ± std over 2 seeds.

| # | estimator | ATE [m] |
|---|---|---|
| 1 | slam | 0.017 ± 0.002 |
| =1 | lidar_odometry | 0.018 ± 0.001 |
| 3 | zero | 16.706 ± 0.100 |

### G1 open+right_turn (mean ± std over seeds)

| # | estimator | ATE [m] | runs |
|---|---|---|---|
| 1 | slam | 0.007 ± 0.001 | 2 |
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


def make_report(tmp_path: Path, figures: dict[Path, str]) -> Path:
    return write_report(tmp_path / "report.html", title="duallidar leaderboard (test)",
                        board=BOARD, table_one=TABLE_ONE, figures=figures,
                        config={"seeds": [0, 1], "noise": 0.01},
                        command="python -m estimators.leaderboard --seeds 0 1")


def test_markdown_tables_become_sortable_html_tables() -> None:
    page = markdown_to_html(BOARD)
    assert page.count('<table class="sortable">') == 2
    assert "<th>ATE [m]</th>" in page and "<td>=1</td><td>lidar_odometry</td>" in page
    assert "<h4>G1 open+right_turn (mean ± std over seeds)</h4>" in page
    assert "---" not in page  # the separator row is no data row
    assert "<code>x</code>" in markdown_to_html("a `x` b") and "&lt;b&gt;" in markdown_to_html(
        "<b>")


def test_the_report_is_one_file_with_everything_inside(tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    report = make_report(tmp_path, {a_figure(tmp_path / "fig.png"): "a test figure"})
    page = report.read_text()
    assert page.count("data:image/png;base64,") == 1
    assert "src=\"http" not in page and "href=" not in page  # nothing fetched from elsewhere
    for text in ("python -m estimators.leaderboard --seeds 0 1", "31.25", "numpy", "noise",
                 "Table I"):
        assert text in page, text


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
    assert dom.count("<table") == 4 and "<td>lidar_odometry</td>" in dom  # board, group, I, config

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
    assert {p.name for p in figures} == {"fig8_lidar_image.png", "fig8_traces.png", "maps.png",
                                        "segment_errors.png", "speed_accuracy.png"}
    for png in figures:
        with Image.open(png) as image:
            assert min(image.info["dpi"]) >= 150 and min(image.size) > 300, png.name
        assert png.with_suffix(".svg").read_text().lstrip().startswith("<?xml"), png.name
    page = (out / "report.html").read_text()
    assert page.count("data:image/png;base64,") == len(figures)
    assert "--estimators zero pc" in page and "|---|" not in page  # every table converted
    dom = browse(out / "report.html", tmp_path / "profile", "--dump-dom")
    assert 'data-broken-images="0"' in dom and "<td>zero</td>" in dom
