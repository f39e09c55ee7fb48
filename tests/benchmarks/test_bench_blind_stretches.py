"""The long-blind-stretch sweep: one row per run, judged by the fault matrix's own verdict,
a summary per estimator and the rows as JSON."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.benchmarks.bench_modules import load

sweep = load("bench_blind_stretches")


def test_a_run_is_judged_and_written(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                     ) -> None:
    out = tmp_path / "sweep.json"
    sweep.main(["--estimators", "lidar_odometry", "--groups", "open_cylinders/right_turn",
                "--seeds", "0", "--stretches", "60", "--offsets", "120", "--json", str(out)])
    rows = json.loads(out.read_text())
    assert len(rows) == 1
    row = rows[0]
    assert row["stretch"] == 60 and row["offset"] == 120 and row["covered"] is not None
    assert row["pass"] == (row["bound"] or (row["covered"] < 0.5 and row["lost_scans"] >= 1))
    assert "lidar_odometry  pass" in capsys.readouterr().out


def test_a_stretch_of_no_scans_is_rejected_by_name() -> None:
    with pytest.raises(SystemExit) as exit_info:
        sweep.main(["--stretches", "0"])
    assert exit_info.value.code == 2
