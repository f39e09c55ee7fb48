"""The cold-start benchmark: a fresh process's phases, and how many kernels it compiled."""

from __future__ import annotations

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
