"""Lidar mounts as ROS tf: a YAML of ``base_link -> lidar_k`` transforms and one
``static_transform_publisher`` command per Lidar.

A mount is the planar pose (x [m] forward, y [m] left, yaw [rad] CCW) of a Lidar's frame in
the base frame; z, pitch and roll are 0. The commands use ROS 2's named arguments
(``ros2 run tf2_ros static_transform_publisher --x .. --frame-id .. --child-frame-id ..``).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import yaml
from numpy.typing import ArrayLike

from lidar_env.core import ConfigError

#: The frame the mounts are given in.
BASE_FRAME = "base_link"


def _checked(mounts: ArrayLike, frames: Sequence[str]) -> np.ndarray:
    rows = np.asarray(mounts, dtype=np.float64)
    if rows.ndim != 2 or rows.shape[1] != 3 or len(rows) != len(frames) \
            or not np.all(np.isfinite(rows)):
        raise ConfigError(f"mounts: expected ({len(frames)}, 3) finite poses (x [m], y [m], "
                          f"yaw [rad]), one per frame, got shape {rows.shape}")
    return rows


def static_transform_commands(mounts: ArrayLike, frames: Sequence[str],
                              base: str = BASE_FRAME) -> list[str]:
    """One ``ros2 run tf2_ros static_transform_publisher`` command per mount (K, 3)."""
    rows = _checked(mounts, frames)
    return [f"ros2 run tf2_ros static_transform_publisher --x {x:.6f} --y {y:.6f} --z 0 "
            f"--yaw {yaw:.6f} --pitch 0 --roll 0 --frame-id {base} --child-frame-id {frame}"
            for (x, y, yaw), frame in zip(rows, frames, strict=True)]


def tf_yaml(mounts: ArrayLike, frames: Sequence[str], sources: Sequence[str],
            base: str = BASE_FRAME) -> str:
    """The mounts (K, 3) as a YAML list of transforms ``{parent, child, x, y, z, yaw,
    source}`` (``source``: where each mount comes from, e.g. "configured", "calibrated")."""
    rows = _checked(mounts, frames)
    transforms = [{"parent": base, "child": frame, "x": float(x), "y": float(y), "z": 0.0,
                   "yaw": float(yaw), "source": source}
                  for (x, y, yaw), frame, source in zip(rows, frames, sources, strict=True)]
    header = (f"# {base} -> Lidar frames: x, y, z [m], yaw [rad] (CCW about z); "
              "pitch and roll 0\n")
    return header + yaml.safe_dump({"transforms": transforms}, sort_keys=False)


def read_tf_yaml(path: str | Path) -> tuple[np.ndarray, list[str]]:
    """``(mounts (K, 3), child frames)`` of a file written from :func:`tf_yaml`."""
    data = yaml.safe_load(Path(path).read_text())
    items = data.get("transforms") if isinstance(data, dict) else None
    if not isinstance(items, list) or not items:
        raise ConfigError(f"{path}: expected a 'transforms' list of parent/child/x/y/yaw")
    return (np.array([[item["x"], item["y"], item["yaw"]] for item in items], dtype=np.float64),
            [str(item["child"]) for item in items])
