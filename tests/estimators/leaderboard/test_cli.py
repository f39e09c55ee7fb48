"""The leaderboard CLI end to end on a tiny matrix, and its input errors."""

from __future__ import annotations

import csv
import io
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from estimators.base import SensorSetup
from estimators.datasets.carmen import flaser_beam_angles
from estimators.leaderboard import cli as leaderboard
from estimators.leaderboard import matrix, table_one
from estimators.leaderboard.records import Scenario, TraceDataset, TraceRecord
from estimators.leaderboard.tasks import EstimatorSpec
from estimators.paths import SHARED_DATA
from estimators.registry import make, names
from lidar_env import lidars_with_noise

DATA = SHARED_DATA / "radish"
TINY = ["--worlds", "open_cylinders", "--traces", "right_turn", "--seeds", "3",
        "--estimators", "zero", "pc", "--workers", "1", "--no-progress"]


def read_csv(path: Path) -> list[dict[str, str]]:
    with path.open() as handle:
        return list(csv.DictReader(handle))


@pytest.mark.slow
def test_tiny_matrix_end_to_end_then_resume(tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "board"
    assert leaderboard.main([*TINY, "--no-real", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    for name in ("leaderboard.md", "leaderboard.csv", "results.csv", "table1.md", "table1.csv",
                 "experiments.sqlite"):
        assert (out / name).stat().st_size > 0, name
    for name in ("fig8_lidar_image.png", "fig8_traces.png", "maps.png"):
        image = pytest.importorskip("matplotlib.image").imread(out / name)
        assert image.ndim == 3 and min(image.shape[:2]) > 100 and image.std() > 0, name

    every_result = read_csv(out / "results.csv")
    results = [r for r in every_result if r["scan_frame"] == "sensor"]
    assert sorted(r["estimator"] for r in results) == ["pc", "zero"]
    # Table I's world-aligned recording: only the paper's estimators, outside the ranking
    world = [r for r in every_result if r["scan_frame"] == "world"]
    assert [r["estimator"] for r in world] == ["pc"]
    board = read_csv(out / "leaderboard.csv")
    ate = {r["estimator"]: float(r["ate_rmse_m"]) for r in board}
    assert ate == {r["estimator"]: float(r["ate_rmse_m"]) for r in results}  # one scenario
    assert [r["estimator"] for r in board] == sorted(ate, key=ate.get)  # ranked by ATE
    zero = next(r for r in results if r["estimator"] == "zero")
    assert float(zero["accuracy_percent"]) == 0.0  # no motion: eq. 11 = 100 %
    assert "| 1 | " + board[0]["estimator"] in printed
    # map scores: stored per trace, averaged into the ranked table, shown as columns
    for row in results:
        for metric in ("map_iou", "map_precision", "map_recall", "cylinder_recall"):
            assert 0.0 <= float(row[metric]) <= 1.0, (row["estimator"], metric)
    assert {r["estimator"]: r["map_iou"] for r in board} == {
        r["estimator"]: r["map_iou"] for r in results}
    tables = (out / "leaderboard.md").read_text() + (out / "table1.md").read_text()
    assert "map IoU | map precision | map recall | cylinder recall | cylinder error [m]" in tables
    assert "map IoU" not in printed  # the terminal shows the headline table, not every table
    assert "worker time: record " in printed and "map scores" in printed
    ceiling = tables.split("Maps at the true poses (the mapper's ceiling): map IoU ")[1]
    assert float(ceiling.split(",")[0]) > 0.8
    assert float(zero["map_iou"]) < float(zero["map_iou_true_poses"])
    assert f"files in {out}/" in printed and "2 recorded, 3 traces new" in printed
    assert "+ 1 x 1 world-aligned for Table I" in printed
    table_i = read_csv(out / "table1.csv")
    assert [float(r["paper_accuracy_percent"]) for r in table_i] == [
        31.25, 91.10, 60.08, 60.31, 64.45, 63.54]
    case_1 = table_i[0]  # pc_offset did not run: no number is made up for it
    assert math.isnan(float(case_1["ours_world_accuracy_percent"]))
    assert math.isnan(float(case_1["ours_sensor_accuracy_percent"]))
    pc = {frame: next(r for r in rows if r["estimator"] == "pc")
          for frame, rows in (("world", world), ("sensor", results))}
    for frame, row in pc.items():
        assert float(case_1[f"pc_main_only_{frame}_accuracy_percent"]) == pytest.approx(
            float(row["accuracy_percent"]))
    # in its own setting the translation-only method never has to see the turn
    assert float(pc["world"]["accuracy_percent"]) > float(pc["sensor"]["accuracy_percent"])
    assert float(pc["world"]["ate_rmse_m"]) < 0.5 * float(pc["sensor"]["ate_rmse_m"])
    assert "| ours, world-aligned [%] (mean ± std, seeds) | ours, sensor-frame" in tables

    assert leaderboard.main([*TINY, "--no-real", "--tum", "--out", str(out)]) == 0
    assert "0 recorded, 0 traces new, 2 already stored" in capsys.readouterr().out
    assert read_csv(out / "leaderboard.csv") == board
    tum = sorted(p.name for p in (out / "tum").iterdir())
    assert tum == [f"open_cylinders_right_turn_s3_{name}.tum" for name in (
        "pc", "truth", "world_pc", "world_truth", "zero")]
    file_interface = pytest.importorskip("evo.tools.file_interface")
    truth = file_interface.read_tum_trajectory_file(str(out / "tum" / tum[1]))
    estimate = file_interface.read_tum_trajectory_file(str(out / "tum" / tum[-1]))
    assert truth.num_poses == estimate.num_poses > 100
    np.testing.assert_allclose(estimate.positions_xyz, estimate.positions_xyz[:1].repeat(
        estimate.num_poses, axis=0))  # "zero" never moves

    assert leaderboard.main([*TINY, "--no-real", "--rank-by", "map", "--out", str(out)]) == 0
    ious = [float(r["map_iou"]) for r in read_csv(out / "leaderboard.csv")]
    assert len(ious) == 2 and ious == sorted(ious, reverse=True)


@pytest.mark.parametrize("terminal", [True, False])
def test_the_scenario_bar_draws_only_on_a_terminal(monkeypatch: pytest.MonkeyPatch,
                                                   terminal: bool) -> None:
    stream = io.StringIO()
    monkeypatch.setattr(stream, "isatty", lambda: terminal)
    monkeypatch.setattr(sys, "stderr", stream)
    with leaderboard._progress(3, "scenarios", True) as bar:
        bar.update(3)
    assert ("\r" in stream.getvalue()) is terminal  # a log gets no carriage-return frames
    with leaderboard._progress(3, "scenarios", False) as bar:  # --no-progress
        assert bar.disable


def test_missing_real_data_is_a_printed_note(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setattr(leaderboard, "DATA_DIR", tmp_path / "no_radish")
    assert leaderboard.main(["--worlds", "hallway", "--traces", "straight", "--seeds", "0",
                             "--estimators", "zero", "--workers", "1", "--no-progress",
                             "--out", str(tmp_path / "out")]) == 0
    printed = capsys.readouterr().out
    assert "note: real-log results skipped" in printed and "no_radish" in printed
    assert "Table I skipped" in printed  # hallway+straight is none of the paper's cases


@pytest.mark.slow
@pytest.mark.realdata
def test_real_log_results_join_the_table(tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    if not (DATA / "aces.clf.bz2").exists():
        pytest.skip(f"needs the Radish ACES log in {DATA}")
    out = tmp_path / "real"
    assert leaderboard.main([*TINY, "--real-scans", "300", "--out", str(out)]) == 0
    board = read_csv(out / "leaderboard.csv")
    errors = {r["estimator"]: float(r["relations_all_translation_m"]) for r in board}
    assert all(np.isfinite(list(errors.values())))
    real = [r for r in read_csv(out / "results.csv") if r["kind"] == "real"]
    assert sorted(r["estimator"] for r in real) == ["pc", "zero"]
    assert all(float(r["relations_all_count"]) > 10 for r in real)
    assert "ACES rel. error [m]" in capsys.readouterr().out


def test_scenarios_run_on_a_dask_scheduler(tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    distributed = pytest.importorskip("distributed")
    dask = pytest.importorskip("dask")  # its scratch folder (lock files) goes to tmp_path
    with dask.config.set({"temporary-directory": str(tmp_path)}), distributed.LocalCluster(
            n_workers=1, processes=False, dashboard_address=None) as cluster:
        status = leaderboard.main(["--worlds", "hallway", "--traces", "straight", "--seeds", "0",
                                   "1", "--estimators", "zero", "--no-real", "--no-progress",
                                   "--scheduler", cluster.scheduler_address,
                                   "--out", str(tmp_path)])
    assert status == 0
    assert "2 recorded, 2 traces new" in capsys.readouterr().out
    assert sorted(r["seed"] for r in read_csv(tmp_path / "results.csv")) == ["0", "1"]


@pytest.mark.parametrize(("option", "value", "message"), [
    ("--estimators", "pcc", "unknown estimator 'pcc': expected one of"),
    ("--worlds", "moon", "unknown world 'moon': expected one of open_cylinders"),
    ("--traces", "zig", "unknown trace 'zig': expected one of straight, right_turn, zigzag"),
    ("--workers", "0", "--workers: expected an integer >= 1, got 0"),
    ("--noise", "-1", "--noise: expected a range noise std >= 0"),
])
def test_bad_options_exit_with_a_readable_error(tmp_path: Path, option: str, value: str,
                                                message: str,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        leaderboard.main([option, value, "--out", str(tmp_path / "out")])
    assert exit_info.value.code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "out").exists()  # rejected before anything was written


def test_a_database_of_another_program_is_refused(tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    bogus = tmp_path / "notes.sqlite"
    bogus.write_text("not a database")
    assert leaderboard.main([*TINY, "--db", str(bogus), "--out", str(tmp_path / "o")]) == 2
    assert "not an SQLite database" in capsys.readouterr().err
    assert bogus.read_text() == "not a database"



def square_room_ranges(position: np.ndarray, angles: np.ndarray, half_side: float = 4.0
                       ) -> np.ndarray:
    """Ranges [m] from ``position`` (x, y) along world directions ``angles`` [rad] to the walls
    of the square room ``[-half_side, half_side]^2``: the nearer of the two walls each ray
    meets (closed form)."""
    direction = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):  # rays parallel to a wall
        to_wall = (np.sign(direction) * half_side - position) / direction
    return np.min(np.where(np.isfinite(to_wall) & (to_wall > 0), to_wall, np.inf), axis=1)


def test_declared_lidar_needs_match_what_each_estimator_does_with_one_lidar() -> None:
    """``min_lidars`` lets the pipeline skip an estimator up front; it must be the truth: an
    estimator that declares one Lidar enough runs on one, one that declares two refuses one."""
    angles = np.deg2rad(np.arange(0, 360, 2.0))
    setup = SensorSetup(np.zeros((1, 3)), angles, 10.0)
    for name in names():
        estimator = make(name)
        try:
            estimator.reset(setup)
            for step in range(3):
                position = np.array([0.1 * step, 0.0])
                estimator.update({"lidar_1": square_room_ranges(position, angles)}, 0.1 * step)
        except (ValueError, KeyError, IndexError) as error:
            assert EstimatorSpec(name).not_applicable(1) == "needs 2 Lidars", (name, error)
        else:
            assert EstimatorSpec(name).not_applicable(1) is None, name
            assert estimator.trajectory.shape == (3, 3), name
    assert {n for n in names() if EstimatorSpec(n).not_applicable(1)} >= {"pc_offset", "pc_pg"}


def write_one_laser_log(directory: Path, scans: int = 40, speed: float = 0.5) -> None:
    """``aces.clf.bz2`` (plain text: logs are recognised by content) and ``aces.relations``: a
    one-laser robot driving straight at ``speed`` [m/s] through a square room at 10 Hz."""
    angles = flaser_beam_angles(180)
    times = 100.0 + 0.1 * np.arange(scans)
    lines = []
    for t in times:
        x = -1.0 + speed * (t - times[0])
        ranges = " ".join(f"{r:.3f}" for r in square_room_ranges(np.array([x, 0.0]), angles))
        lines.append(f"FLASER 180 {ranges} {x:.3f} 0 0 {x:.3f} 0 0 {t:.3f} host {t - 100:.3f}")
    (directory / "aces.clf.bz2").write_text("\n".join(lines) + "\n")
    (directory / "aces.relations").write_text("".join(
        f"{t1:.3f} {t2:.3f} {speed * (t2 - t1):.4f} 0 0 0 0 0\n"
        for t1, t2 in zip(times[:-1], times[1:], strict=True)))


def test_two_lidar_estimators_show_na_on_a_one_lidar_log_and_are_no_failures(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    write_one_laser_log(tmp_path)
    monkeypatch.setattr(leaderboard, "DATA_DIR", tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    (out / "failures.txt").write_text("a stale list from an earlier run")
    argv = ["--worlds", "hallway", "--traces", "straight", "--seeds", "0", "--estimators",
            "zero", "pc_offset", "pc_pg", "--workers", "1", "--no-progress", "--real-scans",
            "0", "--out", str(out)]
    assert leaderboard.main(argv) == 0
    printed = capsys.readouterr().out
    assert not (out / "failures.txt").exists()
    assert "failed" not in printed
    assert "not run: aces/log/s0: pc_offset (needs 2 Lidars), aces/log/s0: pc_pg" in printed
    board = {r["estimator"]: r for r in read_csv(out / "leaderboard.csv")}
    assert board["zero"]["real_note"] == "" and float(
        board["zero"]["relations_all_translation_m"]) == pytest.approx(0.05, abs=1e-3)
    for name in ("pc_offset", "pc_pg"):
        assert board[name]["real_note"] == "needs 2 Lidars"
        assert f"| {name} |" in printed and math.isfinite(float(board[name]["ate_rmse_m"]))
    assert printed.count("n/a (needs 2 Lidars) |") == 2
    assert "1 real log" in printed and "4 traces new" in printed

    assert leaderboard.main(argv) == 0  # nothing is retried
    assert "0 traces new, 2 already stored" in capsys.readouterr().out


def test_table_one_scenarios_add_world_aligned_copies_for_the_paper_estimators() -> None:
    groups = matrix.build_groups(None, None)
    config = {"lidars": lidars_with_noise(range_noise_std=0.01)}
    scenarios = {g.name: [Scenario(g.world, g.trace, seed, config, "sb3")
                          for seed in (0, 1)] for g in groups}
    runs = matrix.table_one_scenarios(groups, scenarios, [EstimatorSpec("pc_pg")])
    cases = {(c.world, c.trace) for c in matrix.TABLE_I}
    assert set(runs["sensor"]) == set(runs["world"]) == cases  # not straight nor out_and_back
    for pair, sensor in runs["sensor"].items():
        world = runs["world"][pair]
        assert [s.seed for s in world] == [s.seed for s in sensor] == [0, 1]
        assert all(dict(w.config) == {**s.config, "scan_frame": "world"}
                   for w, s in zip(world, sensor, strict=True))
        assert {s.driver for s in world} == {"scripted"}  # no policy sees rotated scans
    assert matrix.table_one_scenarios(groups, scenarios,
                                           [EstimatorSpec("icp")])["world"] == {}


def test_table_one_reports_world_aligned_and_sensor_frame_beside_the_paper() -> None:
    pair = ("open_cylinders", "right_turn")
    runs = {frame: {pair: [Scenario(*pair, seed, {"scan_frame": frame}) for seed in (0, 1)]}
            for frame in ("world", "sensor")}
    accuracy = {("world", "pc_offset"): [90.0, 94.0], ("world", "pc_pg"): [96.0, 95.0],
                ("world", "pc"): [92.0, 93.0], ("sensor", "pc_offset"): [80.0, 81.0]}
    records = {}
    for (frame, name), values in accuracy.items():
        for scenario, value in zip(runs[frame][pair], values, strict=True):
            trace = TraceDataset(name, {}, np.zeros(1), np.zeros((1, 3)), np.zeros(1))
            records[(scenario, name)] = TraceRecord(0, scenario, trace, {
                "accuracy_percent": value, "ate_rmse_m": 100.0 - value})
    rows = table_one.table_one(runs, records)
    case_1, case_2 = rows[0], rows[1]
    assert case_1["ours_world_accuracy_percent"] == pytest.approx(92.0)
    assert case_1["ours_world_std_percent"] == pytest.approx(2.0)
    assert case_1["ours_sensor_accuracy_percent"] == pytest.approx(80.5)
    assert case_1["ours_world_ate_m"] == pytest.approx(8.0)
    assert case_1["pc_main_only_world_accuracy_percent"] == pytest.approx(92.5)
    assert math.isnan(case_1["pc_main_only_sensor_accuracy_percent"])
    assert case_2["ours_world_seeds"] == 2 and case_2["ours_sensor_seeds"] == 0
    assert all(r["ours_world_seeds"] == 0 for r in rows[2:])  # scenarios not in the run
    table = table_one.table_one_markdown(rows)
    assert ("| paper [%] | ours, world-aligned [%] (mean ± std, seeds) | ours, sensor-frame [%] "
            "(mean ± std, seeds) | ATE world-aligned / sensor-frame [m] |") in table
    assert "| pc_offset | 31.25 | 92.00 ± 2.00 (2) | 80.50 ± 0.50 (2) | 8.000 / 19.500 |" in table
    assert "| pc_pg | 91.10 | 95.50 ± 0.50 (2) | not run | 4.500 / n/a |" in table
