"""The estimator speed benchmark's bookkeeping: the forward clock it feeds Intel with, the
replay it reports, and one quick run on a short simulated drive that prints every estimator
asked for against ``icp``."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from tests.benchmarks.bench_modules import load

bench = load("bench_estimators")


def test_forward_clock_moves_only_the_stamps_that_jump_back() -> None:
    times = bench.forward_clock([0.0, 0.1, 0.05, 0.1, 0.3], step=0.001)
    np.testing.assert_allclose(times, [0.0, 0.1, 0.101, 0.102, 0.3])
    assert np.all(np.diff(times) > 0)


def test_a_short_run_prints_each_estimator_against_icp(capsys: pytest.CaptureFixture) -> None:
    bench.main(["--estimators", "zero", "lidar_odometry", "--scenarios",
                "open_cylinders:straight:0", "--no-real", "--max-episode-time", "0.5"])
    lines = capsys.readouterr().out.splitlines()
    table = {line.split()[0]: line.split()[1:] for line in lines[lines.index(
        next(line for line in lines if line.startswith("estimator"))) + 1:]}
    assert list(table) == ["icp", "zero", "lidar_odometry"]
    assert float(table["icp"][1]) == 1.0
    assert all(float(ms) > 0 and float(realtime) > 0 for ms, _, realtime in table.values())


def test_the_fastest_timed_replay_is_reported_never_the_warm_up(
        monkeypatch: pytest.MonkeyPatch) -> None:
    data = bench.simulated("open_cylinders:straight:0", max_episode_time=0.3)
    # (start, end) of each replay: the untimed one takes 1 s, the timed ones 3 s and 2 s
    clock = iter([0.0, 1.0, 10.0, 13.0, 20.0, 22.0])
    monkeypatch.setattr(bench, "time", SimpleNamespace(process_time=lambda: next(clock)))
    assert bench.cpu_seconds_per_scan("zero", data, repeats=2) == 2.0 / len(data.times)


def test_repeats_below_one_are_refused(capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit):
        bench.main(["--repeats", "0", "--no-real"])
    assert "--repeats: expected a number of replays >= 1, got 0" in capsys.readouterr().err
