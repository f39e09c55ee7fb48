"""The peers benchmark: interleaved CPU time per runner, KISS-ICP's planar points, its CLI."""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
import pytest

from estimators.base import SensorSetup
from tests.benchmarks.bench_modules import load

bench = load("bench_peers")


class Burner:
    """Spends ``seconds`` of CPU per update and records the scans it saw."""

    def __init__(self, seconds: float) -> None:
        self.seconds, self.seen = seconds, []

    def update(self, ranges, t) -> None:
        self.seen.append(t)
        end = time.process_time() + self.seconds
        while time.process_time() < end:
            pass


def source(n: int = 6) -> object:
    setup = SensorSetup(np.zeros((1, 3)), np.radians(np.arange(-90.0, 91.0)), 10.0)
    return bench.LogSource("toy", setup, np.arange(n) * 0.2, np.full((n, 181), 4.0), {},
                           np.arange(n) * 0.2)


def test_each_runner_is_charged_its_own_cpu_time_scan_by_scan() -> None:
    slow, fast = Burner(0.004), Burner(0.001)
    per_scan = bench.run_interleaved(source(), {"slow": slow, "fast": fast})
    assert slow.seen == fast.seen == list(np.arange(6) * 0.2)
    assert per_scan["slow"] > 2 * per_scan["fast"] and per_scan["fast"] >= 0.001


def test_kiss_icp_gets_the_returns_as_z0_points_in_the_robot_frame(monkeypatch) -> None:
    pytest.importorskip("kiss_icp")
    setup = SensorSetup(np.array([[0.5, 0.0, np.pi / 2]]), np.radians([-10.0, 0.0, 10.0]), 10.0)
    runner = bench.KissRunner(setup)
    fed = []
    monkeypatch.setattr(runner.odometry, "register_frame", lambda p, t: fed.append(p))
    runner.update(np.array([2.0, 10.0, np.inf]), 0.0)
    [points] = fed
    np.testing.assert_allclose(points, [[0.5 + 2 * np.cos(np.radians(80.0)),
                                         2 * np.sin(np.radians(80.0)), 0.0]], atol=1e-12)
    assert runner.trajectory.shape == (1, 3)


@pytest.mark.parametrize("argv", [["--limit", "0"], ["no/such/log.clf"]])
def test_a_bad_value_is_a_one_line_error_naming_it(argv, capsys) -> None:
    with pytest.raises(SystemExit) as exit_info:
        bench.main(argv)
    assert exit_info.value.code == 2
    error = capsys.readouterr().err.strip().splitlines()[-1]
    assert "--limit" in error or "no/such/log.clf" in error


def test_kernels_reports_each_estimator_s_cpu_inside_compiled_kernels_and_its_ratio(
        monkeypatch) -> None:
    monkeypatch.setattr(bench, "kernel_seconds", lambda work: (work(), 0.003)[1])
    monkeypatch.setattr(bench, "KissRunner", lambda setup: Burner(0.001))
    result = bench.bench_log(source(), ["icp"], with_peer=True, kernels=True)
    assert result["kernel_ms_per_scan"] == {"icp": pytest.approx(0.5)}  # 3 ms over 6 scans
    assert result["ratios"]["icp kernels/kiss_icp"] == pytest.approx(
        0.5 / result["cpu_ms_per_scan"]["kiss_icp"])
    assert "kernel_ms_per_scan" not in bench.bench_log(source(), ["icp"], with_peer=False)


@pytest.mark.realdata
def test_aces_gives_cpu_times_ratios_and_relation_errors_of_each() -> None:
    if not bench.DATA.is_dir():
        pytest.skip(f"real logs not found in {bench.DATA}")
    args = argparse.Namespace(no_default_logs=False, limit=250, logs=[])
    aces = bench.sources(args)[0]()
    result = bench.bench_log(aces, ["icp", "slam", "lidar_odometry"], with_peer=False)
    assert set(result["cpu_ms_per_scan"]) == {"icp", "slam", "lidar_odometry"}
    assert set(result["ratios"]) == {"slam/lidar_odometry"}
    assert result["errors"]["icp"]["local"]["translation_m"] < 0.2


lidars = bench.peer_lidars


def test_the_room_is_walled_and_its_obstacles_stand_apart_from_one_seed() -> None:
    scene = lidars.make_scene(3)
    again = lidars.make_scene(3)
    for a, b in ((scene.walls, again.walls), (scene.circles, again.circles),
                 (scene.boxes, again.boxes)):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(lidars.make_scene(4).circles, scene.circles)
    reach = np.concatenate([scene.circles[:, 2], 0.5 * np.hypot(*scene.boxes[:, 2:4].T)])
    centres = np.vstack([scene.circles[:, :2], scene.boxes[:, :2]])
    apart = np.hypot(*(centres[:, None] - centres[None]).transpose(2, 0, 1))
    needed = reach[:, None] + reach[None] + lidars.GAP_M
    assert np.all(apart[~np.eye(len(reach), dtype=bool)] >= needed[~np.eye(len(reach), dtype=bool)])
    assert np.all(np.abs(centres) + reach[:, None] <= lidars.ROOM_HALF_M - lidars.GAP_M)


def test_a_box_has_its_length_along_its_heading_and_our_beams_see_walls_and_boxes() -> None:
    from lidar_env.sensors.lidar import cast_rays

    walls = lidars.make_scene(0, n_circles=0, n_boxes=0).walls
    scene = lidars.Scene(walls, np.array([[0.0, 5.0, 1.0]]),
                         np.array([[5.0, 0.0, 2.0, 1.0, np.pi / 2]]))  # 1 m wide along x
    np.testing.assert_allclose(np.sort(scene.box_corners()[0, :, 0]), [4.5, 4.5, 5.5, 5.5])
    ranges = cast_rays(scene.world(), np.zeros(3), np.radians([0.0, 90.0, 180.0, 270.0]), 20.0)
    np.testing.assert_allclose(ranges[0], [4.5, 4.0, 10.0, 10.0], atol=1e-12)


def test_free_poses_keep_their_clearance_inside_the_room() -> None:
    world = lidars.make_scene(1).world()
    poses = lidars.free_poses(world, np.random.default_rng(1), 40)
    assert poses.shape == (40, 3)
    assert np.all(world.clearance(poses[:, :2]) >= lidars.POSE_CLEARANCE_M)
    assert np.all(np.abs(poses[:, :2]) < lidars.ROOM_HALF_M)


class KernelPeer:
    """A stand-in peer: our kernel on beams turned half a turn, ``error`` [m] added."""

    name, version, settings = "kernel", "0", {}

    def __init__(self, scene, error: float = 0.0) -> None:
        from lidar_env.sensors.lidar import Lidar

        self.world, self.error = scene.world(), error
        self.beam_angles = Lidar().beam_angles + np.pi

    def scan(self, poses):
        from lidar_env.sensors.lidar import cast_rays

        return cast_rays(self.world, poses, self.beam_angles, 10.0) + self.error


@pytest.mark.parametrize(("error", "batch"), [(0.0, 1), (0.05, 1), (0.0, 2)])
def test_a_peer_is_compared_along_its_own_beams_and_timed_beside_ours(monkeypatch, error,
                                                                      batch) -> None:
    from lidar_env.sensors.lidar import Lidar

    monkeypatch.setitem(lidars.TOLERANCE_M, "kernel", 1e-9)
    monkeypatch.setattr(lidars, "OUR_PASSES", 2)
    scene = lidars.make_scene(2)
    poses = lidars.free_poses(scene.world(), np.random.default_rng(2), 4)
    result = lidars.bench_scene([KernelPeer(scene, error)], scene, poses.reshape(-1, batch, 3),
                                Lidar())
    assert result["poses"] == 4 and result["batch"] == batch
    agree = result["agreement"]["kernel"]
    assert agree["median_abs_m"] == pytest.approx(error, abs=1e-12)
    assert agree["max_abs_off_discs_m"] == pytest.approx(error, abs=1e-12)
    assert agree["beams"] == 4 * 360
    assert agree["beyond"] == (0 if error == 0 else 4 * 360)
    cpu = result["cpu_us_per_scan"]
    assert set(cpu) == {"ours", "kernel"} and min(cpu.values()) > 0
    assert result["ratios"]["kernel/ours"] == pytest.approx(cpu["kernel"] / cpu["ours"])


def test_scanners_are_charged_their_own_cpu_time_in_blocks() -> None:
    slow, fast = Burner(0.002), Burner(0.0005)
    per_scan = lidars.interleaved_cpu({"slow": lambda p: slow.update(p, 0.0),
                                       "fast": lambda p: fast.update(p, 0.0)},
                                      np.zeros((6, 2, 3)), {"slow": 1, "fast": 3}, block=4)
    assert len(slow.seen) == 6 and len(fast.seen) == 18
    # charged per pose: a call on a batch of 2 poses counts as 2 scans
    assert per_scan["slow"] > 2 * per_scan["fast"] >= 2 * 250


def test_env_skips_a_missing_peer_with_its_pip_command_and_times_ours(monkeypatch, capsys,
                                                                      tmp_path) -> None:
    monkeypatch.setattr(lidars, "PEERS", {
        "ir-sim": ("_absent_irsim", "pip install ir-sim", lidars.IrSimLidar),
        "vmas": ("_absent_vmas", "pip install torch vmas", lidars.VmasLidar)})
    out = tmp_path / "env.json"
    assert bench.main(["--env", "--poses", "3", "--json", str(out)]) == 0
    printed = capsys.readouterr()
    skipped = printed.err.strip().splitlines()
    assert len(skipped) == 2
    assert "ir-sim skipped" in skipped[0] and "'pip install ir-sim'" in skipped[0]
    assert "'pip install torch vmas'" in skipped[1]
    assert "us/scan CPU" in printed.out
    report = json.loads(out.read_text())["env"]
    assert set(report["cpu_us_per_scan"]) == {"ours"} and report["peers"] == {}
    assert report["poses"] == 3 and report["beams"] == 360


def test_a_batch_larger_than_the_poses_is_a_one_line_error(capsys) -> None:
    with pytest.raises(SystemExit) as exit_info:
        bench.main(["--env", "--poses", "4", "--batch", "8"])
    assert exit_info.value.code == 2
    assert "--batch" in capsys.readouterr().err.strip().splitlines()[-1]


def test_env_takes_no_logs(capsys, tmp_path) -> None:
    log = tmp_path / "my.clf"
    log.write_text("")
    with pytest.raises(SystemExit) as exit_info:
        bench.main(["--env", str(log)])
    assert exit_info.value.code == 2
    assert "--env" in capsys.readouterr().err.strip().splitlines()[-1]
