"""Publishing a run: report.html from the files the run wrote (the lead figure beside the
headline, the configuration in words) and the terminal's summary (the answer and the files,
not every table)."""

from __future__ import annotations

from pathlib import Path

import pytest

from estimators.leaderboard.publish import LEAD_FIGURE, publish_report, terminal_summary
from estimators.leaderboard.real_logs import RealLog

BOARD = """# duallidar leaderboard (ranked by ate; noise 0.01 m; seeds 0, 1)

3 estimators (slam, lidar_odometry, zero) ran on 4 simulated runs: 2 scenario groups (G1 \
open+right_turn, G2 hallway+zigzag) × 2 seeds, and on the ACES log. By mean ATE, slam ranks \
first at 0.017 m; lidar_odometry follows at 0.018 m (1.06× the leader's).

| # | estimator | ATE [m] | ACES rel. error [m] |
|---|---|---|---|
| 1 | slam | 0.017 ± 0.002 | 0.041 |
| =1 | lidar_odometry | 0.018 ± 0.001 | 0.035 |
| 3 | zero | 16.706 ± 0.100 | 0.310 |
Simulated figures: mean ± std over 2 seeds.

## Per group: each table ranked by the group's own ATE [m]

### G1 open+right_turn (mean ± std over seeds)

| # | estimator | ATE [m] | runs | overall # |
|---|---|---|---|---|
| 1 | lidar_odometry | 0.004 ± 0.001 | 2 | =1 |

## Maps at the estimated poses (mean ± std over seeds)

| overall # | estimator | map IoU |
|---|---|---|
| 1 | slam | 0.977 ± 0.000 |
"""


def a_run(out: Path) -> list[Path]:
    """The files of a small run: the board, Table I and two figures."""
    from matplotlib.figure import Figure

    out.mkdir()
    (out / "leaderboard.md").write_text(BOARD, encoding="utf-8")
    (out / "table1.md").write_text("# Table I\n\n| case | paper [%] |\n|---|---|\n| 1 | 31.25 |\n")
    written = [out / "leaderboard.md", out / "leaderboard.csv", out / "table1.md"]
    for name in (LEAD_FIGURE, "maps.png"):
        figure = Figure(figsize=(3, 2))
        figure.add_subplot().plot([0, 1], [0, 1])
        figure.savefig(out / name, dpi=50)
        written += [out / name, (out / name).with_suffix(".svg")]
    return written


def test_the_report_puts_the_lead_figure_beside_the_headline_and_the_config_in_words(
        tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    out = tmp_path / "board"
    written = a_run(out)
    config = {"worlds": None, "seeds": [0, 1], "tum": False, "out": out,
              "logs": [RealLog("aces", "/d/aces.clf.bz2", "/d/aces.relations", 1000)],
              "argv": ["--seeds", "0", "1"]}
    page = publish_report(out, written, config, ["--seeds", "0", "1"]).read_text()
    top, _, below = page.partition('<h2 id="groups">')
    assert top.count("data:image/png") == 1 and below.count("data:image/png") == 1  # maps
    assert '<p class="lead">3 estimators' in top and "<td>=1</td><td>lidar_odometry</td>" in top
    assert "<h4>G1 open+right_turn" in below and "31.25" in below
    for row in ("<td>--worlds</td><td>not given (the default matrix",
                "<td>--seeds</td><td>0, 1</td>", "<td>--tum</td><td>no</td>",
                "<td>real log scored</td><td>ACES: aces.clf.bz2, first 1,000 scans"):
        assert row in below, row
    assert "None" not in page and "RealLog(" not in page
    assert "python -m estimators.leaderboard --seeds 0 1" in below


def test_the_terminal_shows_the_answer_and_where_the_files_are(tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    out = tmp_path / "board"
    written = [*a_run(out), out / "report.html", out / "tum"]
    text = terminal_summary(out, written)
    lines = text.splitlines()
    assert lines[0] == "duallidar leaderboard (ranked by ate; noise 0.01 m; seeds 0, 1)"
    prose = lines[:next(i for i, line in enumerate(lines) if line.startswith("|"))]
    assert len(prose) > 3 and max(len(line) for line in prose) <= 100  # wrapped
    assert "slam ranks first at 0.017 m" in text.replace("\n", " ")
    assert "| =1 | lidar_odometry | 0.018 ± 0.001 | 0.035 |" in lines
    # no group or map table
    assert "overall #" not in text and "0.004 ± 0.001" not in text and "map IoU" not in text
    assert f"report:  {out / 'report.html'}" in text
    assert f"tables:  in {out}/: leaderboard.md, leaderboard.csv, table1.md" in lines
    assert f"figures: in {out}/: {LEAD_FIGURE}, maps.png" in lines  # PNGs; SVGs beside them
    assert f"other:   in {out}/: tum" in lines
    assert len(lines) < 20
