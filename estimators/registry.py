"""Estimators by name: ``make(name, **params)`` and ``names()``.

Entries are ``"module:Class"`` strings imported on first use, so listing names stays cheap
and a module's heavy dependencies load only when one of its estimators is made.
"""

from __future__ import annotations

import importlib
import inspect
from typing import Any

from estimators.base import Estimator
from lidar_env.core import ConfigError, UnknownNameError

#: name -> ("module:Class", default keyword parameters)
_ENTRIES: dict[str, tuple[str, dict[str, Any]]] = {
    "zero": ("estimators.paper.pc:ZeroMotion", {}),
    "pc": ("estimators.paper.pc:PhaseCorrelationOdometry", {"lidar": 0}),
    "pc_offset": ("estimators.paper.pc:PhaseCorrelationOdometry", {"lidar": 1}),
    "pc_pg": ("estimators.paper.pc:PoseGraphCorrelationOdometry", {}),
    "pc_rot": ("estimators.matching.rotation_pc:RotationPhaseCorrelation", {}),
    "pc_rot_icp": (
        "estimators.matching.rotation_pc:RotationPhaseCorrelation",
        {"icp_iterations": 3, "image_size": 200},
    ),
    "pc_fusion": ("estimators.odometry.fusion:FusionEstimator", {}),
    "icp": ("estimators.matching.icp_estimator:ICPEstimator", {}),
    "lidar_odometry": ("estimators.odometry.local_map:LocalMapOdometry", {}),
    "slam": ("estimators.slam.graph_slam:GraphSlam", {}),
}


def names() -> list[str]:
    """All registered estimator names, sorted."""
    return sorted(_ENTRIES)


def _check_name(name: str) -> None:
    if name not in _ENTRIES:
        raise UnknownNameError(f"unknown estimator {name!r}: expected one of {', '.join(names())}")


def defaults(name: str) -> dict[str, Any]:
    """The keyword parameters ``make(name)`` uses when none are given."""
    _check_name(name)
    return dict(_ENTRIES[name][1])


def make(name: str, **params: Any) -> Estimator:
    """A fresh estimator registered as ``name``, with ``params`` over its defaults."""
    _check_name(name)
    target, defaults = _ENTRIES[name]
    module_name, class_name = target.split(":")
    cls = getattr(importlib.import_module(module_name), class_name)
    accepted = inspect.signature(cls).parameters
    if not any(p.kind is p.VAR_KEYWORD for p in accepted.values()):
        unknown = sorted(set(params) - set(accepted))
        if unknown:
            raise ConfigError(f"{name}: unknown parameter(s) {', '.join(unknown)}: expected "
                              f"some of {', '.join(accepted)}")
    return cls(**{**defaults, **params})
