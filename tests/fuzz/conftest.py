"""Hypothesis profiles of the fuzz suite: ``fuzz`` (default, the whole suite in about a
minute) and ``long`` (20x the examples): ``pytest tests/fuzz --hypothesis-profile=long``.

Every property says: a named project error (a :class:`~lidar_env.core.errors.DualLidarError`) or a
correct result; any other exception, or a NaN pose, fails it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest
from hypothesis import HealthCheck, settings

from lidar_env.core.errors import DualLidarError

BASE = {"deadline": None, "derandomize": True, "suppress_health_check": [HealthCheck.too_slow]}
settings.register_profile("fuzz", max_examples=40, **BASE)
settings.register_profile("long", max_examples=800, **BASE)


def pytest_configure(config: pytest.Config) -> None:
    # the hypothesis plugin has loaded --hypothesis-profile if given; otherwise use ours
    if not config.getoption("hypothesis_profile", None):
        settings.load_profile("fuzz")


def named_or_result(call: Callable[[], Any]) -> Any:
    """``call()``, or None when it raises a named project error (any other error propagates
    and fails the property)."""
    try:
        return call()
    except DualLidarError:
        return None


def scaled(examples: int) -> int:
    """``examples`` in the ``fuzz`` profile, 20x that in ``long`` (for slow properties)."""
    return examples * 20 if settings().max_examples >= 800 else examples
