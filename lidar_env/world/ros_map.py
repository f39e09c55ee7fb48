"""ROS ``map_server`` maps (a YAML file next to a PGM/PNG image): reader and writer.

The YAML keys follow map_server: ``image`` (path, relative to the YAML file), ``resolution``
[m/px], ``origin`` [x [m], y [m], yaw [rad]] (the pose of the image's lower-left pixel; a yaw
rotates the map CCW about it), ``negate`` (0/1), ``occupied_thresh`` and ``free_thresh`` (in
[0, 1]) and ``mode`` (``trinary``, default, or ``scale``). A pixel of value ``v`` has
occupancy probability ``p = (255 - v) / 255`` (``v / 255`` if ``negate``): occupied if
``p > occupied_thresh``, free if ``p < free_thresh``, else unknown (in ``scale`` mode, cells in
between are obstacles when ``p >= 0.5``, as the scaled value would then say "occupied").
Unknown cells are obstacles by default (``unknown_is_obstacle``), so the car never drives into
unmapped space; :meth:`lidar_env.world.world.World.from_ros_map` builds the world. The writer
stores 0 = occupied, 254 = free, 205 = unknown, as map_saver does.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lidar_env.core.errors import MapError

#: map_server's modes this reader understands.
ROS_MAP_MODES: tuple[str, ...] = ("trinary", "scale")
#: Pixel values map_saver writes.
OCCUPIED_PIXEL, FREE_PIXEL, UNKNOWN_PIXEL = 0, 254, 205


@dataclass(frozen=True)
class RosMap:
    """A map read from a map_server YAML: ``cells`` (H, W) int8, row 0 at the top of the image:
    100 occupied, 0 free, -1 unknown; ``resolution`` [m/px]; ``origin`` (x [m], y [m], yaw
    [rad]) of the lower-left pixel's corner."""

    cells: NDArray[np.int8]
    resolution: float
    origin: tuple[float, float, float]
    name: str


def read_ros_map(yaml_path: str | os.PathLike) -> RosMap:
    """Read a map_server YAML and its image; a :class:`MapError` names the file and the key."""
    path = Path(yaml_path)
    meta = _read_yaml(path)
    for key in ("image", "resolution"):
        if key not in meta:
            raise MapError(f"{path}: expected a {key!r} key (map_server YAML), got keys "
                           f"{', '.join(map(str, meta)) or 'none'}")
    resolution = _number(meta["resolution"], path, "resolution")
    if resolution <= 0:
        raise MapError(f"{path}: resolution: expected a positive pixel size [m], got {resolution}")
    origin = meta.get("origin", [0.0, 0.0, 0.0])
    if not isinstance(origin, (list, tuple)) or len(origin) != 3:
        raise MapError(f"{path}: origin: expected [x, y, yaw], got {origin!r}")
    origin = tuple(_number(v, path, "origin") for v in origin)
    occupied_thresh = _number(meta.get("occupied_thresh", 0.65), path, "occupied_thresh")
    free_thresh = _number(meta.get("free_thresh", 0.196), path, "free_thresh")
    for key, value in (("occupied_thresh", occupied_thresh), ("free_thresh", free_thresh)):
        if not 0.0 <= value <= 1.0:
            raise MapError(f"{path}: {key}: expected a probability in [0, 1], got {value}")
    if free_thresh > occupied_thresh:
        raise MapError(f"{path}: expected free_thresh <= occupied_thresh, got {free_thresh} > "
                       f"{occupied_thresh}")
    negate = meta.get("negate", 0)
    if negate not in (0, 1, True, False):
        raise MapError(f"{path}: negate: expected 0 or 1, got {negate!r}")
    mode = meta.get("mode", "trinary")
    if mode not in ROS_MAP_MODES:
        raise MapError(f"{path}: mode: expected one of {', '.join(ROS_MAP_MODES)}, got {mode!r}")
    values = _read_image(path.parent / str(meta["image"]), path)
    p = values / 255.0 if negate else (255.0 - values) / 255.0
    cells = np.full(values.shape, -1, dtype=np.int8)
    cells[p > occupied_thresh] = 100
    cells[p < free_thresh] = 0
    if mode == "scale":
        between = (p <= occupied_thresh) & (p >= free_thresh)
        cells[between & (p >= 0.5)] = 100
        cells[between & (p < 0.5)] = 0
    return RosMap(cells, resolution, origin, path.stem)  # type: ignore[arg-type]


def save_ros_map(
    yaml_path: str | os.PathLike,
    probabilities: ArrayLike,
    resolution: float,
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0),
    occupied_thresh: float = 0.65,
    free_thresh: float = 0.196,
) -> tuple[Path, Path]:
    """Write an occupancy grid as ``<name>.pgm`` + ``<name>.yaml``; return both paths.

    ``probabilities`` (H, W) in [0, 1], row 0 at the top (max y), NaN = unknown; cells above
    ``occupied_thresh`` are written occupied, below ``free_thresh`` free, the rest unknown.
    """
    from PIL import Image

    grid = np.asarray(probabilities, dtype=np.float64)
    if grid.ndim != 2 or grid.size == 0:
        raise MapError(f"probabilities: expected a non-empty (H, W) grid, got shape {grid.shape}")
    known = np.isfinite(grid)
    if np.any((grid[known] < 0) | (grid[known] > 1)):
        raise MapError("probabilities: expected values in [0, 1] (NaN = unknown)")
    if not (math.isfinite(resolution) and resolution > 0):
        raise MapError(f"resolution: expected a positive pixel size [m], got {resolution}")
    pixels = np.full(grid.shape, UNKNOWN_PIXEL, dtype=np.uint8)
    pixels[known & (grid > occupied_thresh)] = OCCUPIED_PIXEL
    pixels[known & (grid < free_thresh)] = FREE_PIXEL
    yaml_path = Path(yaml_path)
    image_path = yaml_path.with_suffix(".pgm")
    Image.fromarray(pixels).save(image_path)
    x, y, yaw = (float(v) for v in origin)
    yaml_path.write_text(
        f"image: {image_path.name}\nmode: trinary\nresolution: {float(resolution)!r}\n"
        f"origin: [{x!r}, {y!r}, {yaw!r}]\nnegate: 0\noccupied_thresh: {occupied_thresh!r}\n"
        f"free_thresh: {free_thresh!r}\n")
    return yaml_path, image_path


def _read_yaml(path: Path) -> dict[str, Any]:
    try:
        import yaml
    except ImportError as error:  # pragma: no cover - pyyaml ships with the dev/agents extras
        raise ImportError("reading a ROS map needs pyyaml: pip install pyyaml") from error
    try:
        meta = yaml.safe_load(path.read_text())
    except FileNotFoundError as error:
        raise MapError(f"{path}: no such map YAML file") from error
    except yaml.YAMLError as error:
        raise MapError(f"{path}: expected map_server YAML, got a parse error: {error}") from error
    if not isinstance(meta, dict):
        raise MapError(f"{path}: expected a mapping of map_server keys, got {type(meta).__name__}")
    return meta


def _read_image(image: Path, yaml_path: Path) -> NDArray[np.float64]:
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(image) as handle:
            return np.asarray(handle.convert("L"), dtype=np.float64)
    except FileNotFoundError as error:
        raise MapError(f"{yaml_path}: image: no such file {image}") from error
    except (UnidentifiedImageError, OSError) as error:
        raise MapError(f"{yaml_path}: image: expected a readable image, got {image}: "
                       f"{error}") from error


def _number(value: Any, path: Path, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise MapError(f"{path}: {key}: expected a finite number, got {value!r}")
    return float(value)
