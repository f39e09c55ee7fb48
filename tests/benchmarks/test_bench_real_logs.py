"""The real-log benchmark's ``--set``: dotted names reach an estimator's mapping parameters."""

from __future__ import annotations

import argparse

import pytest

from estimators import make
from tests.benchmarks.bench_modules import load

bench = load("bench_real_logs")
parameter = load("bench_layouts").parameter


def test_a_dotted_name_sets_one_key_of_a_mapping_parameter() -> None:
    settings = [parameter(text) for text in (
        "reject_dynamic=true", "moving_filter.radius=0.4", "moving_filter.history=3")]
    params = bench.estimator_params(settings)
    assert params == {"reject_dynamic": True, "moving_filter": {"radius": 0.4, "history": 3}}
    assert make("lidar_odometry", **params).moving_filter == {"radius": 0.4, "history": 3}
    slam = bench.estimator_params([parameter("frontend_params.moving_filter.radius=0.4")])
    assert make("slam", **slam).frontend_params == {"moving_filter": {"radius": 0.4}}


@pytest.mark.parametrize("texts", [("moving_filter=1", "moving_filter.radius=0.4"),
                                   ("moving_filter.radius=0.4", "moving_filter=1"),
                                   ("moving_filter..radius=0.4",), (".radius=0.4",)])
def test_a_name_set_both_ways_or_with_an_empty_part_is_refused(texts: tuple[str, ...]) -> None:
    with pytest.raises(argparse.ArgumentTypeError, match="--set"):
        bench.estimator_params([parameter(text) for text in texts])
