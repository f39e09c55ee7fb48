"""Drivers by name: ``make_driver(name, pose_source=...)`` (the :class:`Driver` interface lives
in :mod:`agents.interface`)."""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from typing import Any

from agents.interface import Driver
from lidar_env.core import ConfigError

__all__ = ["DRIVERS", "Driver", "make_driver"]

#: driver name -> "module:Class"; imported on first use (the SB3 driver needs torch).
DRIVERS: dict[str, str] = {
    "scripted": "agents.scripted:PurePursuitDriver",
    "sb3": "agents.sb3_driver:SB3Driver",
    "scan_aware": "agents.scan_aware:ScanAwareDriver",
}


def make_driver(name: str, pose_source: str = "true",
                pose_params: Mapping[str, Any] | None = None) -> Driver:
    """A fresh driver by name: ``scripted`` (pure pursuit), ``scan_aware`` (pure pursuit that
    brakes and backs off for what its scans show ahead) or ``sb3`` (the shipped learned policy).

    ``pose_source`` is where the driver takes the car's pose from: ``"true"`` (the env's
    ``info["pose"]``) or the name of an estimator (``estimators.registry.names()``) that runs
    online on the scans (:class:`agents.pose_source.EstimatedPoseDriver`), built with
    ``pose_params`` over its defaults.
    """
    if name not in DRIVERS:
        raise ConfigError(
            f"unknown driver {name!r}: expected one of {', '.join(sorted(DRIVERS))}")
    if pose_source == "true" and pose_params:
        raise ConfigError(f"pose_params: only with an estimator as pose_source, got "
                          f"{dict(pose_params)!r} with pose_source='true'")
    if pose_source != "true":
        from agents.pose_source import check_pose_source

        check_pose_source(pose_source)  # before loading a model
    module_name, class_name = DRIVERS[name].split(":")
    driver = getattr(importlib.import_module(module_name), class_name)()
    if pose_source == "true":
        return driver
    from agents.pose_source import EstimatedPoseDriver

    return EstimatedPoseDriver(driver, pose_source, pose_params)
