"""The peers benchmark: interleaved CPU time per runner, KISS-ICP's planar points, its CLI."""

from __future__ import annotations

import argparse
import importlib
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from estimators.base import SensorSetup

_BENCHMARKS = str(Path(__file__).resolve().parents[2] / "benchmarks")
sys.path.insert(0, _BENCHMARKS)
try:
    bench = importlib.import_module("bench_peers")
finally:
    sys.path.remove(_BENCHMARKS)


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
