"""publish.py: the vector, cold-start and peers results files, their tables and recorded command."""

from __future__ import annotations

import json

import pytest

from tests.benchmarks.bench_modules import load

publish = load("publish")


def vector_raw(ratio_256: float) -> dict:
    sizes = {"1": {"batched": 50_000.0, "sync": 20_000.0, "ratio": 2.5},
             "256": {"batched": 256_000.0, "sync": 256_000.0 / ratio_256, "ratio": ratio_256}}
    return {"machine": "m", "sizes": sizes,
            "single": {"single": 40_000.0, "batched": 50_000.0, "ratio": 1.25},
            "targets": [{"target": "batched / SyncVectorEnv at N = 256 >= 8", "n": 256,
                         "value": ratio_256, "threshold": 8.0, "met": ratio_256 >= 8},
                        {"target": "batched at N = 1 / single env >= 1", "n": 1,
                         "value": 1.25, "threshold": 1.0, "met": True}]}


def test_the_vector_tables_give_each_size_and_each_target_its_verdict() -> None:
    tables = publish.vector_tables(vector_raw(ratio_256=6.5))
    assert tables["speed"]["rows"] == [["1", "50,000", "20,000", "2.50"],
                                       ["256", "256,000", "39,385", "6.50"]]
    rows = tables["targets"]["rows"]
    assert [row[-1] for row in rows] == ["no", "yes"]
    assert rows[0][2] == "6.50"
    assert rows[1][2] == "1.25 (50,000 / 40,000 steps/s)"


def cold_raw(empty_cache: bool) -> dict:
    phases = {"import": [0.3, 0.4], "first step": [0.6, 0.8]}
    raw = {"machine": "m", "cached": {"phases": phases, "compiled": 0}, "empty_cache": None,
           "ratios": {}, "targets": [{"target": "t <= 5 s wall", "value": 0.6,
                                      "threshold": 5.0, "met": True},
                                     {"target": "compiled = 0", "value": 0, "threshold": 0,
                                      "met": True}]}
    if empty_cache:
        raw["empty_cache"] = {"phases": {"import": [3.0, 2.0], "first step": [60.0, 40.0]},
                              "compiled": 40}
        raw["ratios"] = {"import": [10.0, 5.0], "first step": [100.0, 50.0]}
    return raw


@pytest.mark.parametrize("empty_cache", [False, True])
def test_the_cold_start_tables_hold_every_phase_and_the_compile_count(empty_cache) -> None:
    tables = publish.cold_start_tables(cold_raw(empty_cache))
    phases = tables["phases"]
    assert len(phases["columns"]) == (7 if empty_cache else 3)
    assert all(len(row) == len(phases["columns"]) for row in phases["rows"])
    assert [row[0] for row in phases["rows"]] == [
        "import", "import to first step, in all", "numba kernels compiled"]
    assert phases["rows"][-1][1] == "0"
    if empty_cache:
        assert phases["rows"][1][3:] == ["60.00", "40.00", "100.0", "50.0"]
        assert phases["rows"][-1][3] == "40"
    assert tables["targets"]["rows"] == [["t <= 5 s wall", "0.60", "yes"],
                                         ["compiled = 0", "0", "yes"]]


def test_a_results_file_records_the_arguments_it_ran_with(monkeypatch, tmp_path) -> None:
    ran = []
    monkeypatch.setattr(publish, "RESULTS", tmp_path)
    monkeypatch.setattr(publish, "_run", lambda module, argv: ran.append((module, argv))
                        or vector_raw(ratio_256=9.0))
    written = json.loads(publish.publish("vector").read_text())
    assert ran[-1] == ("bench_vector_env", ["--sizes", "1", "32", "256"])
    assert written["command"] == "python benchmarks/publish.py vector"
    assert written["hardware"] == "m" and written["tables"]["targets"]["rows"][1][-1] == "yes"
    written = json.loads(publish.publish("vector", ["--seconds", "0.1"]).read_text())
    assert ran[-1] == ("bench_vector_env", ["--seconds", "0.1"])
    assert written["command"] == "python benchmarks/publish.py vector --bench-args='--seconds 0.1'"


def test_bench_args_with_two_names_is_a_one_line_error(capsys) -> None:
    with pytest.raises(SystemExit) as exit_info:
        publish.main(["vector", "cold_start", "--bench-args", "--seconds 1"])
    assert exit_info.value.code == 2 and "--bench-args" in capsys.readouterr().err


@pytest.mark.slow
def test_the_vector_benchmark_writes_what_its_tables_read(tmp_path) -> None:
    out = tmp_path / "vector.json"
    assert load("bench_vector_env").main(["--seconds", "0.01", "--sizes", "1", "2",
                                          "--json", str(out)]) == 0
    raw = json.loads(out.read_text())
    tables = publish.vector_tables(raw)
    assert [row[0] for row in tables["speed"]["rows"]] == ["1", "2"]
    assert [row[1] for row in tables["targets"]["rows"]] == ["2", "1"]


def test_the_peers_table_gives_our_kernels_cpu_over_the_peer_s_whole() -> None:
    log = {"cpu_ms_per_scan": {"lidar_odometry": 1.0, "kiss_icp": 0.5},
           "kernel_ms_per_scan": {"lidar_odometry": 0.6},
           "errors": {"lidar_odometry": {"local": {"translation_m": 0.03}},
                      "kiss_icp": {"local": {"translation_m": 0.15}}}}
    table = publish.peers_tables({"peer": "kiss_icp", "logs": {"ACES": log}})["peers"]
    assert table["columns"] == ["estimator", "ACES CPU [ms/scan]", "ACES × KISS-ICP CPU",
                                "ACES kernels × KISS-ICP CPU", "ACES local error [m]"]
    assert table["rows"] == [["lidar_odometry", "1.000", "2.00", "1.20", "0.0300"],
                             ["KISS-ICP", "0.500", "1.00", "", "0.1500"]]
