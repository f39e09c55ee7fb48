"""kernel_time: the CPU an estimator spends inside compiled kernels, apart from its Python."""

from __future__ import annotations

import time

import numpy as np

from estimators.matching.scan_matching import _beam_points
from tests.benchmarks.bench_modules import load

kernel_time = load("kernel_time")


def _python_only(seconds: float) -> None:
    end = time.process_time() + seconds
    while time.process_time() < end:
        pass


def test_python_work_is_not_counted_and_kernel_calls_are() -> None:
    angles = np.linspace(-np.pi, np.pi, 360)
    ranges, cos, sin = np.full(360, 4.0), np.cos(angles), np.sin(angles)
    _beam_points(ranges, cos, sin, 10.0, 0.05)  # compiled (or loaded) outside the measure

    def kernels() -> None:
        for _ in range(20_000):
            _beam_points(ranges, cos, sin, 10.0, 0.05)

    def mixed() -> None:
        _python_only(0.05)
        kernels()

    assert kernel_time.kernel_seconds(lambda: _python_only(0.05)) == 0.0
    inside = kernel_time.kernel_seconds(mixed)
    start = time.process_time()
    kernels()
    plain = time.process_time() - start
    assert 0.5 * plain < inside < 2.0 * plain  # the kernels' own time, the 50 ms of Python out
