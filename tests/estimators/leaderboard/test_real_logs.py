"""The leaderboard's real-log path on the user's own recordings: a ROS bag scored on its
ground-truth topic, a CARMEN log on a relations file, and the options' readable errors."""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np
import pytest

from estimators.leaderboard import cli as leaderboard
from estimators.leaderboard import real_logs
from estimators.leaderboard.real_logs import RealLog, real_logs_from, user_log
from lidar_env.core.errors import ConfigError, LogFormatError

pytest.importorskip("rosbags")

from estimators.datasets import write_bag  # noqa: E402
from estimators.datasets.rosbag_writer import TRUTH_TOPIC  # noqa: E402
from estimators.leaderboard.recording import record  # noqa: E402
from estimators.leaderboard.records import Scenario  # noqa: E402

SMALL = ["--worlds", "hallway", "--traces", "straight", "--seeds", "0", "--workers", "1",
         "--no-progress"]


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short zigzag drive (two Lidars, 1 cm noise) written as a ROS 2 bag with its truth."""
    drive = record(Scenario("hallway", "zigzag", 3, config={"max_episode_time": 8.0}))
    return write_bag(tmp_path_factory.mktemp("bag") / "drive", drive.setup, drive.times,
                     drive.scans, drive.poses)


def options(**values: object) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    real_logs.add_real_log_arguments(parser)
    args = parser.parse_args([])
    for key, value in values.items():
        setattr(args, key, value)
    return args


def test_a_bag_is_scored_on_its_truth_topic_next_to_the_simulated_groups(
        bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "board"
    argv = [*SMALL, "--estimators", "zero", "lidar_odometry", "pc_pg", "--real-log", str(bag),
            "--truth-topic", TRUTH_TOPIC, "--out", str(out)]
    assert leaderboard.main(argv) == 0
    printed = capsys.readouterr().out
    assert "DRIVE rel. error [m]" in printed and "failed" not in printed
    with (out / "results.csv").open() as handle:
        real = {r["estimator"]: r for r in csv.DictReader(handle) if r["kind"] == "real"}
    assert sorted(real) == ["lidar_odometry", "pc_pg", "zero"]  # two Lidars: pc_pg runs too
    errors = {name: float(r["relations_all_translation_m"]) for name, r in real.items()}
    assert all(float(r["relations_local_count"]) > 50 for r in real.values())
    assert errors["lidar_odometry"] < 0.05 < errors["zero"]

    assert leaderboard.main(argv) == 0  # stored under the bag's digest: nothing re-runs
    assert "0 traces new" in capsys.readouterr().out


def test_a_bag_relations_are_consecutive_scans_and_windows_of_its_truth(bag: Path) -> None:
    log = user_log(bag, truth_topic=TRUTH_TOPIC)
    relations = log.relations()
    recording = log.load()
    spans = relations.t2 - relations.t1
    assert np.count_nonzero(spans < 2.0) == len(recording) - 1
    assert np.all(spans[spans >= 2.0] >= real_logs.TRUTH_WINDOW)
    assert log.n_lidars == 2 and log.scenario.config["digest"] == real_logs.file_digest(bag)


def test_a_changed_file_is_a_new_scenario(tmp_path: Path) -> None:
    path = tmp_path / "run.log"
    relations = tmp_path / "run.relations"
    relations.write_text("0 1 0 0 0 0 0 0\n")
    path.write_text("FLASER 0 0 0 0 0 0 0 1.0 host 1.0\n")
    first = user_log(path, relations).scenario
    path.write_text("FLASER 0 0 0 0 0 0 0 2.0 host 2.0\n")
    assert user_log(path, relations).scenario != first
    assert first.world == "run" and first.kind == "real"


@pytest.mark.parametrize(("values", "message"), [
    ({"relations": Path("r.txt")}, "--relations: expected it with --real-log"),
    ({"truth_topic": "/gt"}, "--truth-topic: expected it with --real-log"),
    ({"real_log": Path("nowhere.bag"), "truth_topic": "/gt"}, "no such file or bag"),
    ({"real_scans": -1}, "--real-scans: expected an integer >= 0"),
])
def test_bad_real_log_options_name_the_option(values: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        real_logs_from(options(**values), Path("/nonexistent"), 1000)


def test_a_carmen_log_takes_no_bag_options_and_needs_relations(tmp_path: Path) -> None:
    path = tmp_path / "run.log"
    path.write_text("FLASER 0 0 0 0 0 0 0 1.0 host 1.0\n")
    with pytest.raises(ConfigError, match="CARMEN log, not a bag"):
        real_logs_from(options(real_log=path, truth_topic="/gt"), tmp_path, 1000)
    with pytest.raises(ConfigError, match="expected a relations file, or a bag"):
        real_logs_from(options(real_log=path), tmp_path, 1000)


def test_a_bag_without_truth_or_relations_is_refused_before_any_run(
        bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(ConfigError, match="ground-truth topic"):
        RealLog("drive", str(bag))
    with pytest.raises(SystemExit) as exit_info:
        leaderboard.main([*SMALL, "--estimators", "zero", "--real-log", str(bag),
                          "--truth-topic", "/no_such_topic", "--out", str(tmp_path / "o")])
    assert exit_info.value.code == 2
    assert "/no_such_topic" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_topics_choose_and_order_the_bag_lidars(bag: Path) -> None:
    log, = real_logs_from(options(real_log=bag, truth_topic=TRUTH_TOPIC,
                                  topics=["/lidar_2/scan"]), Path("/nonexistent"), 1000)
    assert log.n_lidars == 1 and log.load().topics == ("/lidar_2/scan",)
    with pytest.raises(LogFormatError, match="/no_such/scan"):
        real_logs_from(options(real_log=bag, truth_topic=TRUTH_TOPIC, topics=["/no_such/scan"]),
                       Path("/nonexistent"), 1000)
