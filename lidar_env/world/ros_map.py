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

Numbers may also be given as strings that read as finite floats: YAML 1.1 (which map_server
and PyYAML speak) reads ``5e-2`` or ``1e-05`` as a string, as it needs a dot to see a float;
the writer therefore writes ``1.0e-05``. Images are read by
:func:`~lidar_env.world.grey_image.read_grey_image` (16-bit PGM and PNG scaled by their
``maxval``). A map YAML is plain UTF-8 text of at most :data:`MAX_YAML_BYTES`; YAML aliases
(``*name``) are refused, since nested ones expand a few hundred bytes into gigabytes.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lidar_env.core.errors import MapError, quoted
from lidar_env.world.grey_image import read_grey_image

#: Largest map YAML read [bytes] (a map_server YAML is a few hundred).
MAX_YAML_BYTES = 1 << 20
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
                           f"{quoted(list(meta)) if meta else 'none'}")
    resolution = _number(meta["resolution"], path, "resolution")
    if resolution <= 0:
        raise MapError(f"{path}: resolution: expected a positive pixel size [m], got {resolution}")
    origin = meta.get("origin", [0.0, 0.0, 0.0])
    if not isinstance(origin, (list, tuple)) or len(origin) != 3:
        raise MapError(f"{path}: origin: expected [x, y, yaw], got {quoted(origin)}")
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
        raise MapError(f"{path}: negate: expected 0 or 1, got {quoted(negate)}")
    mode = meta.get("mode", "trinary")
    if mode not in ROS_MAP_MODES:
        raise MapError(f"{path}: mode: expected one of {', '.join(ROS_MAP_MODES)}, got "
                       f"{quoted(mode)}")
    values = _read_image(meta["image"], path)
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
    ``resolution`` [m/px] and ``origin`` (x [m], y [m], yaw [rad]) are written so that
    :func:`read_ros_map` reads back the same floats.
    """
    from PIL import Image

    grid = np.asarray(probabilities, dtype=np.float64)
    if grid.ndim != 2 or grid.size == 0:
        raise MapError(f"probabilities: expected a non-empty (H, W) grid, got shape {grid.shape}")
    known = np.isfinite(grid)
    if np.any((grid[known] < 0) | (grid[known] > 1)):
        raise MapError("probabilities: expected values in [0, 1] (NaN = unknown)")
    resolution = _number(resolution, None, "resolution")
    if resolution <= 0:
        raise MapError(f"resolution: expected a positive pixel size [m], got {resolution}")
    if not isinstance(origin, (list, tuple, np.ndarray)) or len(origin) != 3:
        raise MapError(f"origin: expected (x, y, yaw), got {quoted(origin)}")
    x, y, yaw = (_number(v, None, "origin") for v in origin)
    for key, value in (("occupied_thresh", occupied_thresh), ("free_thresh", free_thresh)):
        if not 0.0 <= _number(value, None, key) <= 1.0:
            raise MapError(f"{key}: expected a probability in [0, 1], got {value}")
    pixels = np.full(grid.shape, UNKNOWN_PIXEL, dtype=np.uint8)
    pixels[known & (grid > occupied_thresh)] = OCCUPIED_PIXEL
    pixels[known & (grid < free_thresh)] = FREE_PIXEL
    yaml_path = Path(yaml_path)
    image_path = yaml_path.with_suffix(".pgm")
    Image.fromarray(pixels).save(image_path)
    yaml_path.write_text(
        f"image: {image_path.name}\nmode: trinary\nresolution: {_yaml_float(resolution)}\n"
        f"origin: [{_yaml_float(x)}, {_yaml_float(y)}, {_yaml_float(yaw)}]\nnegate: 0\n"
        f"occupied_thresh: {_yaml_float(occupied_thresh)}\n"
        f"free_thresh: {_yaml_float(free_thresh)}\n")
    return yaml_path, image_path


def _yaml_float(value: float) -> str:
    """``value`` as a YAML 1.1 float: a mantissa with a dot (``1.0e-05``, not ``1e-05``)."""
    text = repr(float(value))
    mantissa, e, exponent = text.partition("e")
    return f"{mantissa}.0e{exponent}" if e and "." not in mantissa else text


def _alias_free_loader() -> type:
    import yaml

    class AliasFreeLoader(yaml.SafeLoader):
        """PyYAML's safe loader, refusing aliases (``*name``) before they are expanded."""

        def compose_node(self, parent: Any, index: Any) -> Any:
            if self.check_event(yaml.AliasEvent):
                event = self.peek_event()
                raise yaml.composer.ComposerError(
                    None, None, f"expected plain values, got the alias *{quoted(event.anchor)} "
                    "(map files take no YAML aliases)", event.start_mark)
            return super().compose_node(parent, index)

    return AliasFreeLoader


def _read_yaml(path: Path) -> dict[str, Any]:
    try:
        import yaml
    except ImportError as error:  # pragma: no cover - pyyaml ships with the dev/agents extras
        raise ImportError("reading a ROS map needs pyyaml: pip install pyyaml") from error
    try:
        with open(path, "rb") as handle:
            data = handle.read(MAX_YAML_BYTES + 1)
    except FileNotFoundError as error:
        raise MapError(f"{path}: no such map YAML file") from error
    except OSError as error:
        raise MapError(f"{path}: cannot read the map YAML ({error.strerror})") from error
    if len(data) > MAX_YAML_BYTES:
        raise MapError(f"{path}: expected a map_server YAML of at most {MAX_YAML_BYTES} bytes, "
                       "got a larger file")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as error:
        raise MapError(f"{path}: expected UTF-8 text, got byte 0x{data[error.start]:02x} at "
                       f"offset {error.start}") from error
    try:
        meta = yaml.load(text, Loader=_alias_free_loader())  # noqa: S506 - a SafeLoader
    except (yaml.YAMLError, ValueError) as error:  # ValueError: an int too long to convert
        raise MapError(f"{path}: expected map_server YAML, got a parse error: "
                       f"{str(error)[:300]}") from error
    if not isinstance(meta, dict):
        raise MapError(f"{path}: expected a mapping of map_server keys, got {type(meta).__name__}")
    return meta


def _read_image(image: Any, yaml_path: Path) -> NDArray[np.float64]:
    if not isinstance(image, str) or not image or "\0" in image:
        raise MapError(f"{yaml_path}: image: expected a file name (text without NUL bytes), "
                       f"got {quoted(image)}")
    path = yaml_path.parent / image
    try:
        return read_grey_image(path)
    except FileNotFoundError as error:
        raise MapError(f"{yaml_path}: image: no such file {path}") from error
    except OSError as error:
        raise MapError(f"{yaml_path}: image: cannot read {path} ({error.strerror})") from error


def _number(value: Any, path: Path | None, key: str) -> float:
    """``value`` as a finite float: a number, or a string that reads as one (YAML 1.1 reads
    ``5e-2`` as a string); a :class:`MapError` naming ``path`` and ``key`` otherwise."""
    where = f"{path}: {key}" if path is not None else key
    number = None
    if isinstance(value, str) and len(value) <= 64:
        try:
            number = float(value.strip())
        except ValueError:
            number = None
    elif isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(
            value, (bool, np.bool_)):
        try:
            number = float(value)
        except OverflowError:
            number = None
    if number is None or not math.isfinite(number):
        raise MapError(f"{where}: expected a finite number, got {quoted(value)}")
    return number
