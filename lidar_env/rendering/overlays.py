"""What a rendered frame shows besides the scene: the map's unknown cells, a scale bar and a
legend.

:class:`UnknownCells` holds a ROS map's unknown cells (:mod:`lidar_env.world.ros_map`), so the
renderer draws them apart from obstacles and crops frames to the map's known area. The scale bar
and the legend are drawn once per renderer with Pillow (:func:`scale_bar`, :func:`legend`) and
pasted into every frame by :func:`paste`, so they cost a copy per frame. World frame, metres.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from PIL import Image, ImageDraw, ImageFont

from lidar_env.world.ros_map import RosMap, read_ros_map

Bounds = tuple[float, float, float, float]

#: Colour of cells a ROS map marks unknown (light blue-grey, unlike the dark obstacles).
UNKNOWN = np.array([200, 206, 218], dtype=np.uint8)
#: Scale bar lengths tried, times a power of ten [m].
NICE_LENGTHS = (1.0, 2.0, 5.0)
#: Padding [pixels] around the scale bar and the legend.
PAD = 6


@dataclass(frozen=True)
class UnknownCells:
    """A ROS map's unknown cells: ``unknown`` (H, W) bool, row 0 at the top, ``resolution``
    [m/cell], ``origin`` (x, y) [m] of the lower-left cell's corner (an unrotated map)."""

    unknown: NDArray[np.bool_]
    resolution: float
    origin: tuple[float, float]

    @classmethod
    def of(cls, source: Any) -> UnknownCells | None:
        """The unknown cells of ``source`` when it is a ROS map (a YAML path or a
        :class:`~lidar_env.world.ros_map.RosMap`) whose origin has no yaw, else ``None``."""
        if isinstance(source, (str, os.PathLike)) and Path(source).suffix.lower() in (".yaml",
                                                                                      ".yml"):
            source = read_ros_map(source)
        if not isinstance(source, RosMap) or source.origin[2] != 0.0:
            return None
        return cls(source.cells == -1, source.resolution, source.origin[:2])

    def known_bounds(self) -> Bounds | None:
        """``(xmin, ymin, xmax, ymax)`` [m] of the cells that are not unknown (None: none)."""
        rows, cols = np.nonzero(~self.unknown)
        if len(rows) == 0:
            return None
        height = self.unknown.shape[0]
        x0, y0, res = self.origin[0], self.origin[1], self.resolution
        return (x0 + cols.min() * res, y0 + (height - 1 - rows.max()) * res,
                x0 + (cols.max() + 1) * res, y0 + (height - rows.min()) * res)

    def mask(self, bounds: Bounds, resolution: float, shape: tuple[int, int]) -> NDArray:
        """``shape`` bool: the pixels (of ``resolution`` [m], anchored at ``bounds``' lower-left
        corner, row 0 at the top) whose centre lies in an unknown cell or off the map."""
        height, width = shape
        x = bounds[0] + (np.arange(width) + 0.5) * resolution
        y = bounds[1] + (height - np.arange(height) - 0.5) * resolution
        rows_n, cols_n = self.unknown.shape
        cols = np.floor((x - self.origin[0]) / self.resolution).astype(np.int64)
        rows = rows_n - 1 - np.floor((y - self.origin[1]) / self.resolution).astype(np.int64)
        col_ok, row_ok = (cols >= 0) & (cols < cols_n), (rows >= 0) & (rows < rows_n)
        inside = self.unknown[np.clip(rows, 0, rows_n - 1)][:, np.clip(cols, 0, cols_n - 1)]
        return np.where(row_ok[:, None] & col_ok[None, :], inside, True)


def nice_length(span: float) -> float:
    """The largest 1, 2 or 5 x 10^k [m] not above ``span`` [m] (``span`` > 0)."""
    power = 10.0 ** math.floor(math.log10(span))
    return max(n * power for n in NICE_LENGTHS if n * power <= span)


def _font(size: int) -> Any:
    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow < 10.1 has one bitmap size
        return ImageFont.load_default()


def scale_bar(resolution: float, frame_width: int) -> NDArray[np.uint8]:
    """An RGB patch: a black bar of a round length (about a fifth of the frame) and its label,
    on white."""
    length = nice_length(0.2 * frame_width * resolution)
    pixels = max(1, round(length / resolution))
    size = max(10, frame_width // 60)
    label = f"{length:g} m"
    image = Image.new("RGB", (pixels + 2 * PAD + 5 * size, size + 2 * PAD + 6), "white")
    draw = ImageDraw.Draw(image)
    top = PAD + size // 2
    draw.rectangle([PAD, top, PAD + pixels - 1, top + 5], fill="black")
    draw.text((PAD + pixels + PAD, PAD), label, fill="black", font=_font(size))
    return np.asarray(image)


def legend(entries: Sequence[tuple[str, NDArray[np.uint8]]], frame_width: int
           ) -> NDArray[np.uint8]:
    """An RGB patch: one coloured swatch and its label per entry, on white, framed grey."""
    size = max(10, frame_width // 60)
    line = size + 6
    width = 2 * PAD + 2 * size + max(len(text) for text, _ in entries) * (size * 6 // 10 + 1)
    image = Image.new("RGB", (width, 2 * PAD + line * len(entries)), "white")
    draw = ImageDraw.Draw(image)
    for i, (text, colour) in enumerate(entries):
        top = PAD + i * line
        draw.rectangle([PAD, top + 2, PAD + size, top + 2 + size],
                       fill=tuple(int(c) for c in colour))
        draw.text((PAD + size + size // 2, top), text, fill="black", font=_font(size))
    draw.rectangle([0, 0, image.width - 1, image.height - 1], outline=(120, 120, 120))
    return np.asarray(image)


def paste(frame: NDArray[np.uint8], patch: NDArray[np.uint8], corner: str) -> None:
    """Copy ``patch`` into ``frame``'s ``corner`` ("bottom left" or "top right"), clipped."""
    height, width = min(patch.shape[0], frame.shape[0]), min(patch.shape[1], frame.shape[1])
    if corner == "bottom left":
        frame[frame.shape[0] - height:, :width] = patch[patch.shape[0] - height:, :width]
    else:
        frame[:height, frame.shape[1] - width:] = patch[:height, patch.shape[1] - width:]
