"""``duallidar run`` reports each estimator's input health: a drive with a frozen second Lidar,
a blank stretch and a clock jump injected shows their counts in ``metrics.json``,
``metrics.csv`` and the terminal table, and their scan indices in ``health.json``; a clean
drive reads ``ok``."""

from __future__ import annotations

import csv
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from estimators.datasets.faults import with_faults
from estimators.datasets.recording import Recording
from estimators.health import BLIND_STRETCH, Health
from estimators.leaderboard import run_cli
from estimators.leaderboard.database import ExperimentDatabase
from estimators.leaderboard.recording import record
from estimators.leaderboard.records import Scenario
from estimators.leaderboard.run_outputs import health_summary
from lidar_env.faults import Blind, ClockJump, FrozenLidar

BLANK = (30, 12)  # first scan, scans: both Lidars read max range (no return)
FROZEN = (8, 8)  # first scan, scans: the second Lidar republishes its scan
JUMP_AT = 55  # scan at which the clock jumps 3 s ahead
SCENARIO = Scenario("hallway", "straight", 0, config={"max_episode_time": 7.0})


def store(path: Path, faulty: bool) -> Path:
    """A short straight drive in an experiment database, with the module's faults or clean."""
    drive = record(SCENARIO)
    if faulty:
        recording = Recording(str(path), drive.setup, drive.times, dict(drive.scans),
                              drive.setup.keys, drive.setup.keys, drive.poses)
        recording = with_faults(recording, [
            FrozenLidar(keys=("lidar_2",), after=FROZEN[0], duration=FROZEN[1]),
            Blind(every=10_000, stretch=BLANK[1], offset=BLANK[0]),
            ClockJump(jump=3.0, every=10_000, offset=JUMP_AT)], seed=0)
        assert len(recording) == len(drive)
        scans = {key: scan.astype(np.float32) for key, scan in recording.scans.items()}
        drive = dataclasses.replace(drive, times=recording.times, scans=scans)
    with ExperimentDatabase(path) as db:
        db.save_sensor_dataset(SCENARIO, drive)
    return path


def test_a_faulty_drive_shows_its_faults_in_every_output(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    database = store(tmp_path / "experiments.sqlite", faulty=True)
    out = tmp_path / "out"
    code = run_cli.main([str(database), "--estimators", "icp", "--out", str(out),
                         "--no-figures"])
    printed = capsys.readouterr().out
    assert code == 0, printed
    row = json.loads((out / "metrics.json").read_text())["estimators"][0]
    assert row["skipped_scans"] >= BLANK[1] and row["blind_stretches"] == 1
    assert row["frozen_scans"] >= FROZEN[1] - 1  # the first held scan is not yet a repeat
    assert row["clock_jumps"] == 1
    health = json.loads((out / "icp" / "health.json").read_text())
    assert {key: health[key] for key in row if key in health and key != "estimator"} == {
        key: row[key] for key in ("skipped_scans", "frozen_scans", "clock_jumps",
                                  "blind_stretches")}
    assert health["ok"] is False and health["jumps"] == [JUMP_AT]
    assert set(range(BLANK[0], sum(BLANK))) <= set(health["skipped"])
    [[first, last]] = health["stretches"]
    assert first <= BLANK[0] + 1 and last == sum(BLANK) - 1 and last - first + 1 >= BLIND_STRETCH
    with (out / "metrics.csv").open() as handle:
        [csv_row] = list(csv.DictReader(handle))
    assert int(csv_row["clock_jumps"]) == 1
    assert int(csv_row["skipped_scans"]) == row["skipped_scans"]
    head = next(line for line in printed.splitlines() if line.startswith("estimator "))
    assert head.rstrip().endswith("health")
    line = next(line for line in printed.splitlines() if line.startswith("icp "))
    assert line.rstrip().endswith(health_summary(row)), printed
    assert f"{row['skipped_scans']} skipped" in line and "1 clock jump" in line


def test_a_clean_drive_reads_ok(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    database = store(tmp_path / "experiments.sqlite", faulty=False)
    out = tmp_path / "out"
    assert run_cli.main([str(database), "--estimators", "icp", "--out", str(out),
                         "--no-figures"]) == 0
    line = next(line for line in capsys.readouterr().out.splitlines()
                if line.startswith("icp "))
    assert line.rstrip().endswith(" ok")
    health = json.loads((out / "icp" / "health.json").read_text())
    assert health["ok"] is True and health["skipped"] == health["jumps"] == []


def test_the_health_words() -> None:
    assert health_summary(Health().counts()) == "ok"
    counts = Health(skipped_scans=12, frozen_scans=1, clock_jumps=2, blind_stretches=1).counts()
    assert health_summary(counts) == "12 skipped, 1 frozen, 2 clock jumps, 1 blind stretch"
    assert health_summary({"estimator": "slam", "status": "failed: x"}) == "-"
