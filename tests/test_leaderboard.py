"""The leaderboard CLI end to end on a tiny matrix, and its input errors."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from estimators import leaderboard

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "radish"
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

    results = read_csv(out / "results.csv")
    assert sorted(r["estimator"] for r in results) == ["pc", "zero"]
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
    assert "map IoU | map precision | map recall | cylinder recall | cylinder error [m]" in printed
    assert "worker time: record " in printed and "map scores" in printed
    ceiling = printed.split("Maps at the true poses (the mapper's ceiling): map IoU ")[1]
    assert float(ceiling.split(",")[0]) > 0.8
    assert float(zero["map_iou"]) < float(zero["map_iou_true_poses"])
    assert f"files in {out}/" in printed and "1 recorded, 2 traces new" in printed
    table_i = read_csv(out / "table1.csv")
    assert [float(r["paper_accuracy_percent"]) for r in table_i] == [
        31.25, 91.10, 60.08, 60.31, 64.45, 63.54]
    case_1 = table_i[0]  # pc_offset did not run: no number is made up for it
    assert math.isnan(float(case_1["ours_accuracy_percent"]))
    assert float(case_1["pc_main_only_accuracy_percent"]) == pytest.approx(
        float(next(r for r in results if r["estimator"] == "pc")["accuracy_percent"]))

    assert leaderboard.main([*TINY, "--no-real", "--tum", "--out", str(out)]) == 0
    assert "0 recorded, 0 traces new, 1 already stored" in capsys.readouterr().out
    assert read_csv(out / "leaderboard.csv") == board
    tum = sorted(p.name for p in (out / "tum").iterdir())
    assert tum == [f"open_cylinders_right_turn_s3_{name}.tum" for name in ("pc", "truth", "zero")]
    file_interface = pytest.importorskip("evo.tools.file_interface")
    truth = file_interface.read_tum_trajectory_file(str(out / "tum" / tum[1]))
    estimate = file_interface.read_tum_trajectory_file(str(out / "tum" / tum[2]))
    assert truth.num_poses == estimate.num_poses > 100
    np.testing.assert_allclose(estimate.positions_xyz, estimate.positions_xyz[:1].repeat(
        estimate.num_poses, axis=0))  # "zero" never moves

    assert leaderboard.main([*TINY, "--no-real", "--rank-by", "map", "--out", str(out)]) == 0
    ious = [float(r["map_iou"]) for r in read_csv(out / "leaderboard.csv")]
    assert len(ious) == 2 and ious == sorted(ious, reverse=True)


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
    with distributed.LocalCluster(n_workers=1, processes=False,
                                  dashboard_address=None) as cluster:
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

