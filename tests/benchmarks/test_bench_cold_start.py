"""The cold-start benchmark: a fresh process's phases, and how many kernels it compiled."""

from __future__ import annotations

import json

import pytest

from tests.benchmarks.bench_modules import load

bench = load("bench_cold_start")


def test_a_negative_vector_size_is_a_one_line_error(capsys) -> None:
    with pytest.raises(SystemExit) as exit_info:
        bench.main(["--vector", "-1"])
    assert exit_info.value.code == 2 and "--vector" in capsys.readouterr().err


@pytest.mark.slow
def test_a_second_process_loads_what_the_first_compiled(tmp_path) -> None:
    """Against a cache directory of its own: the first process compiles, the next none."""
    first = bench.probe(0, str(tmp_path))
    second = bench.probe(0, str(tmp_path))
    assert first["compiled"] > 0 and second["compiled"] == 0
    assert set(second["phases"]) == {"import", "make", "reset", "step", "first step"}
    assert all(wall > 0 and cpu > 0 for wall, cpu in second["phases"].values()
               if wall > 0.05)


def test_each_target_is_met_or_missed_by_its_own_figure() -> None:
    phases = {"first step": [4.0, 3.0], bench.vector_phase(32): [9.0, 8.0]}
    found = bench.targets({"phases": phases, "compiled": 2}, 32)
    assert [(target["value"], target["met"]) for target in found] == [
        (4.0, True), (9.0, False), (2, False)]
    assert len(bench.targets({"phases": phases, "compiled": 0}, 0)) == 2


def test_json_holds_the_phases_compiles_and_targets(tmp_path, monkeypatch) -> None:
    result = {"phases": {"first step": [1.0, 1.0]}, "compiled": 0}
    monkeypatch.setattr(bench, "probe", lambda num_envs, cache_dir: result)
    out = tmp_path / "cold.json"
    assert bench.main(["--vector", "0", "--json", str(out)]) == 0
    written = json.loads(out.read_text())
    assert written["cached"] == result and written["empty_cache"] is None
    assert [target["met"] for target in written["targets"]] == [True, True]
