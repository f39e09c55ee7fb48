"""``lidar_odometry``'s moving-point filter settings (``moving_filter``): they reach the filter,
through ``slam``'s ``frontend_params`` too, and bad ones fail when the estimator is made."""

from __future__ import annotations

import inspect
from typing import Any

import numpy as np
import pytest

import estimators.odometry.moving_rejection as moving_rejection
from estimators import SensorSetup, make
from estimators.odometry.moving_points import MovingPointFilter
from lidar_env.core.errors import ConfigError

SETUP = SensorSetup([[0.25, 0.0, 0.0], [-0.25, 0.0, 0.0]], 2 * np.pi * np.arange(360) / 360,
                    20.0)
#: Every setting away from the filter's default.
SETTINGS = {"radius": 0.4, "history": 3, "stale_resolution": 0.2, "anchor_time": 0.5,
            "max_anchor_scans": 12, "anchor_spacing": 0.1, "anchor_break": 0.08,
            "map_clearance": 0.2, "map_support": 0.05}


@pytest.fixture
def built(monkeypatch: pytest.MonkeyPatch) -> list[tuple[tuple[Any, ...], dict[str, Any]]]:
    """The arguments of every :class:`MovingPointFilter` the odometry builds."""
    calls: list[tuple[tuple[Any, ...], dict[str, Any]]] = []

    class Recorded(MovingPointFilter):
        def __init__(self, *args: Any, **kwargs: Any) -> None:
            calls.append((args, kwargs))
            super().__init__(*args, **kwargs)

    monkeypatch.setattr(moving_rejection, "MovingPointFilter", Recorded)
    return calls


def test_the_keys_are_the_filters_parameters_but_margin_and_min_range() -> None:
    parameters = set(inspect.signature(MovingPointFilter).parameters)
    assert set(moving_rejection.MOVING_FILTER_KEYS) == parameters - {"setup", "margin",
                                                                     "min_range"}
    assert set(SETTINGS) == set(moving_rejection.MOVING_FILTER_KEYS)


def test_every_setting_reaches_the_filter(built: list) -> None:
    estimator = make("lidar_odometry", moving_filter=SETTINGS, dynamic_margin=0.25,
                     min_range=0.1)
    estimator.reset(SETUP, np.zeros(3))
    args, kwargs = built[-1]
    assert args == (SETUP, 0.25) and kwargs == {"min_range": 0.1, **SETTINGS}
    moving = estimator._moving
    assert (moving.radius, moving.anchor_time, moving.stale_resolution,
            moving.anchor_spacing, moving.anchor_break) == (0.4, 0.5, 0.2, 0.1, 0.08)


def test_without_settings_the_filter_gets_its_defaults(built: list) -> None:
    estimator = make("lidar_odometry")
    assert estimator.moving_filter is None and not built  # nothing to check, nothing built
    estimator.reset(SETUP, np.zeros(3))
    assert built == [((SETUP, 0.2), {"min_range": estimator.min_range})]


def test_the_settings_are_kept_as_checked() -> None:
    settings = {"radius": 0.4}
    estimator = make("lidar_odometry", moving_filter=settings)
    settings["radius"] = -1.0  # the caller's mapping changes after the check
    estimator.reset(SETUP, np.zeros(3))
    assert estimator._moving.radius == 0.4


def test_slam_passes_them_to_its_front_end() -> None:
    slam = make("slam", frontend_params={"moving_filter": {"radius": 0.4, "history": 3}})
    slam.reset(SETUP, np.zeros(3))
    assert slam._frontend._moving.radius == 0.4
    with pytest.raises(ConfigError, match="moving_filter: anchor_time"):
        make("slam", frontend_params={"moving_filter": {"anchor_time": -1.0}})


def test_an_unknown_key_is_named_with_the_valid_ones() -> None:
    with pytest.raises(ConfigError, match="unknown key 'raduis': expected one of anchor_break, "
                                          "anchor_spacing, anchor_time, history, "
                                          "map_clearance, map_support, max_anchor_scans, "
                                          "radius, stale_resolution"):
        make("lidar_odometry", moving_filter={"raduis": 0.4})


@pytest.mark.parametrize(("key", "own"), [("margin", "dynamic_margin"),
                                          ("min_range", "min_range")])
def test_a_value_the_estimator_sets_itself_is_refused(key: str, own: str) -> None:
    with pytest.raises(ConfigError, match=f"'{key}' is set by lidar_odometry's {own}"):
        make("lidar_odometry", moving_filter={key: 0.3})


@pytest.mark.parametrize(("settings", "message"), [
    ({"history": 2.5}, "history: expected an integer"),
    ({"max_anchor_scans": True}, "max_anchor_scans: expected an integer"),
    ({"radius": "0.4"}, "radius: expected a number"),
    ({"history": -1}, "history: expected a scan count >= 0"),
    ({"radius": float("nan")}, r"radius: expected a distance >= 0 \[m\]"),
    ({"radius": -0.3}, r"radius: expected a distance >= 0 \[m\]"),
    ({"stale_resolution": 0.0}, "stale_resolution: expected a beam spacing > 0"),
    ({"anchor_time": -1.0}, "anchor_time: expected a duration >= 0"),
    ({"max_anchor_scans": 0}, "max_anchor_scans: expected a scan count >= 1"),
    ({"anchor_spacing": float("nan")}, "anchor_spacing: expected a spacing > 0"),
    ({"anchor_break": -0.1}, "anchor_break: expected a distance >= 0"),
    ([("radius", 0.4)], "expected a mapping of anchor_break, "),
])
def test_a_bad_value_fails_when_the_estimator_is_made(settings: Any, message: str) -> None:
    with pytest.raises(ConfigError, match=f"moving_filter: {message}"):
        make("lidar_odometry", moving_filter=settings)
