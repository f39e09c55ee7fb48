"""``duallidar run``: a ROS 2 bag whose truth covers keyframes only, and the Intel log scored on
its SLAM-corrected keyframes, produce the files evo and ROS read as they are, and the ATE the
tool prints is the one ``evo_ape -a`` computes."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from estimators.leaderboard import run_cli
from estimators.paths import SHARED_DATA

pytest.importorskip("rosbags")

from estimators.datasets import load_bag  # noqa: E402
from estimators.datasets.rosbag_writer import (  # noqa: E402
    BagSink,
    check_beams,
    header,
    laser_scan,
    scan_topic,
)
from estimators.leaderboard.recording import record  # noqa: E402
from estimators.leaderboard.records import Scenario  # noqa: E402

KEYFRAME_EVERY = 7
TRUTH_LAG = 0.004  # [s] the truth topic's stamps trail the scans'
RADISH = SHARED_DATA / "radish"


def quaternion(types, heading: float):
    return types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=float(np.sin(heading / 2)),
                                                  w=float(np.cos(heading / 2)))


@pytest.fixture(scope="module")
def keyframe_bag(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, np.ndarray]:
    """A ~200-scan drive (two Lidars) as a ROS 2 bag whose ``/keyframes`` PoseStamped topic
    holds the true pose of every 7th scan only, stamped 4 ms late; returns the bag and the
    true poses of every scan."""
    drive = record(Scenario("hallway", "zigzag", 3, config={"max_episode_time": 20.0}))
    path = tmp_path_factory.mktemp("bag") / "drive"
    with BagSink(path, "sqlite3") as sink:
        types = sink.typestore.types
        mounts = [types["geometry_msgs/msg/TransformStamped"](
            header=header(types, drive.times[0], "base_link", 0, False), child_frame_id=key,
            transform=types["geometry_msgs/msg/Transform"](
                translation=types["geometry_msgs/msg/Vector3"](x=float(m[0]), y=float(m[1]),
                                                               z=0.0),
                rotation=quaternion(types, float(m[2]))))
            for key, m in zip(drive.setup.keys, drive.setup.mounts, strict=True)]
        sink.write("/tf_static", types["tf2_msgs/msg/TFMessage"](transforms=mounts),
                   drive.times[0])
        geometry = [check_beams(sensor) for sensor in drive.setup.sensors]
        for step, t in enumerate(drive.times):
            for key, sensor, beams in zip(drive.setup.keys, drive.setup.sensors, geometry,
                                          strict=True):
                sink.write(scan_topic(key), laser_scan(types, header(types, t, key, step, False),
                                                       drive.scans[key][step], beams, sensor), t)
            if step % KEYFRAME_EVERY == 0:
                x, y, heading = drive.poses[step]
                pose = types["geometry_msgs/msg/PoseStamped"](
                    header=header(types, t + TRUTH_LAG, "map", step, False),
                    pose=types["geometry_msgs/msg/Pose"](
                        position=types["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=0.0),
                        orientation=quaternion(types, float(heading))))
                sink.write("/keyframes", pose, t + TRUTH_LAG)
    return path, drive.poses


def evo_ate(truth: Path, estimate: Path) -> float:
    """``evo_ape tum truth estimate -a`` RMSE [m], through evo's API."""
    from evo.core import metrics, sync
    from evo.tools import file_interface

    reference = file_interface.read_tum_trajectory_file(str(truth))
    trajectory = file_interface.read_tum_trajectory_file(str(estimate))
    reference, trajectory = sync.associate_trajectories(reference, trajectory)
    trajectory.align(reference, correct_scale=False)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((reference, trajectory))
    return float(ape.get_statistic(metrics.StatisticsType.rmse))


def printed_ate(output: str, name: str) -> float:
    line = next(line for line in output.splitlines() if line.startswith(name + " "))
    return float(line.split()[1])


def test_the_leaderboard_bag_reader_keeps_keyframe_truth(keyframe_bag) -> None:
    path, poses = keyframe_bag
    recording = load_bag(path, truth_topic="/keyframes")
    known = np.flatnonzero(np.all(np.isfinite(recording.truth), axis=1))
    np.testing.assert_array_equal(known, np.arange(0, len(poses), KEYFRAME_EVERY))
    np.testing.assert_allclose(recording.truth[known], poses[known], atol=1e-9)


def test_a_bag_with_keyframe_truth(keyframe_bag, tmp_path: Path,
                                   capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("evo")
    path, poses = keyframe_bag
    out = tmp_path / "out"
    code = run_cli.main([str(path), "--truth-topic", "/keyframes", "--estimators",
                         "lidar_odometry", "icp", "--out", str(out)])
    printed = capsys.readouterr().out
    assert code == 0, printed
    keyframes = len(range(0, len(poses), KEYFRAME_EVERY))
    assert f"{keyframes} of {keyframes} truth poses matched to a scan" in printed
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["truth_matching"]["matched"] == keyframes
    for row in metrics["estimators"]:
        name = row["estimator"]
        folder = out / name
        for file in ("estimate.tum", "truth.tum", "relation_errors.csv", "map.pgm",
                     "map.yaml", "trajectory.png"):
            assert (folder / file).is_file(), file
        assert len((folder / "estimate.tum").read_text().splitlines()) == len(poses) + 1
        ate = evo_ate(folder / "truth.tum", folder / "estimate.tum")
        assert ate == pytest.approx(row["ate_rmse_m"], abs=1e-6)
        assert abs(printed_ate(printed, name) - ate) <= 1e-5
        assert row["ate_rmse_m"] < 0.1  # a short simulated drive: cm, not metres
        assert row["local_relations"] == keyframes - 1
        assert {"1s_translation_m", "5s_translation_m", "ms_per_scan_cpu",
                "realtime_factor"} <= set(row)
    csv_header = (out / "metrics.csv").read_text().splitlines()[0]
    assert csv_header.startswith("estimator,status,scans,truth_poses,ate_rmse_m")
    yaml = (out / "icp" / "map.yaml").read_text()
    assert "image: map.pgm" in yaml and "resolution: 0.05" in yaml


@pytest.mark.parametrize(("argv", "message"), [
    (["nowhere.bag"], "RECORDING: no such file or bag directory nowhere.bag"),
    (["{bag}", "--estimators", "lidar_odometri"], "--estimators: unknown estimator"),
    (["{bag}", "--max-scans", "0"], "argument --max-scans: expected an integer >= 1, got 0"),
    (["{bag}", "--windows", "-1"], "argument --windows"),
    (["{bag}", "--map-resolution", "nan"], "argument --map-resolution"),
    (["{bag}", "--truth-tolerance", "-0.1"], "argument --truth-tolerance"),
    (["{bag}", "--truth", "missing.tum"], "--truth: no such file missing.tum"),
    (["{bag}", "--relations", "missing.rel"], "--relations: no such file missing.rel"),
    (["{bag}", "--truth-topic", "/keyframes", "--truth", "{bag}"], "not allowed with"),
    (["{bag}", "--truth-topic", "/nothing"], "truth_topic /nothing"),
    (["{bag}", "--truth-topic", "/keyframes", "--truth-tolerance", "0"],
     "--truth-topic: expected truth poses at two scans or more"),
    (["{bag}", "--clock", "ipc"], "--clock:"),
    (["{log}", "--truth-topic", "/gt"], "--truth-topic: "),
])
def test_bad_values_are_one_line_errors_naming_the_option(
        keyframe_bag, tmp_path: Path, argv: list[str], message: str,
        capsys: pytest.CaptureFixture[str]) -> None:
    log = tmp_path / "robot.log"
    log.write_text("FLASER 3 1.0 2.0 3.0 0 0 0 0 0 0 1.0 host 1.0\n")
    argv = [a.format(bag=keyframe_bag[0], log=log) for a in argv] + ["--out",
                                                                     str(tmp_path / "o")]
    with pytest.raises(SystemExit) as stop:
        run_cli.main(argv)
    err = capsys.readouterr().err
    assert stop.value.code == 2
    assert message in err, err
    assert err.startswith("usage: duallidar run") and "Traceback" not in err


@pytest.mark.realdata
def test_intel_scored_on_its_corrected_keyframes_agrees_with_evo_ape(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log, corrected = RADISH / "intel.clf.bz2", RADISH / "intel-corrected.log.gz"
    if not (log.is_file() and corrected.is_file()):
        pytest.skip(f"the Intel log and its corrected keyframes are not in {RADISH}")
    pytest.importorskip("evo")
    out = tmp_path / "intel"
    code = run_cli.main([str(log), "--truth", str(corrected), "--estimators", "lidar_odometry",
                         "--max-scans", "600", "--out", str(out), "--no-figures"])
    printed = capsys.readouterr().out
    assert code == 0, printed
    matched = int(re.search(r"(\d+) of \d+ truth poses matched", printed).group(1))
    assert matched >= 10
    evo_ape = Path(sys.executable).with_name("evo_ape")
    folder = out / "lidar_odometry"
    if evo_ape.exists():  # the command exactly as a user types it
        done = subprocess.run([str(evo_ape), "tum", "truth.tum", "estimate.tum", "-a"],
                              cwd=folder, capture_output=True, text=True, check=True)
        ate = float(re.search(r"rmse\s+([0-9.]+)", done.stdout).group(1))
    else:
        ate = evo_ate(folder / "truth.tum", folder / "estimate.tum")
    assert abs(printed_ate(printed, "lidar_odometry") - ate) <= 1e-5
    row = json.loads((out / "metrics.json").read_text())["estimators"][0]
    assert row["truth_poses"] == matched and row["ate_rmse_m"] < 0.5


def test_a_recorded_simulated_drive_is_scored_on_its_true_poses(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from estimators.leaderboard.database import ExperimentDatabase

    scenario = Scenario("hallway", "straight", 0, config={"max_episode_time": 4.0})
    database = tmp_path / "experiments.sqlite"
    with ExperimentDatabase(database) as db:
        db.save_sensor_dataset(scenario, record(scenario))
    out = tmp_path / "out"
    assert run_cli.main([str(database), "--estimators", "icp", "--out", str(out),
                         "--no-figures"]) == 0
    printed = capsys.readouterr().out
    assert "truth: the simulation's true poses" in printed
    row = json.loads((out / "metrics.json").read_text())["estimators"][0]
    assert row["truth_poses"] == row["scans"] and row["ate_rmse_m"] < 0.05
    with pytest.raises(SystemExit):
        run_cli.main([str(database), "--scenario", "hallway/zigzag/s9", "--out", str(out)])
    assert "--scenario: unknown drive 'hallway/zigzag/s9'" in capsys.readouterr().err
