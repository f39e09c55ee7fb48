"""The constant-velocity prediction's horizon (``estimators.matching.prediction``): its
median is numpy's bit for bit, and clock gaps past the horizon predict nothing."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from estimators.matching.prediction import (
    PREDICTION_GAP_FACTOR,
    median,
    prediction_horizon,
    within_prediction_horizon,
)


@settings(max_examples=300, deadline=None)
@given(st.lists(st.floats(-1e6, 1e6, allow_nan=False), min_size=1, max_size=400))
def test_median_is_numpys_bit_for_bit(values: list[float]) -> None:
    array = np.array(values)
    assert median(array) == float(np.median(array))


def test_horizon_is_the_median_positive_interval_times_the_gap_factor() -> None:
    intervals = [0.1, 0.1, 0.12, -0.05, 0.0, np.inf, 0.09]
    assert prediction_horizon(intervals) == PREDICTION_GAP_FACTOR * 0.1
    assert prediction_horizon([]) == 0.0
    assert within_prediction_horizon(0.5, intervals)
    assert not within_prediction_horizon(1.5, intervals)
    assert not within_prediction_horizon(0.0, intervals)
