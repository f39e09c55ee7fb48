"""Greyscale map images read on one scale: ``(H, W)`` float64 in [0, 255], row 0 at the top.

PGM files (netpbm ``P2`` plain and ``P5`` raw) are parsed here, by the netpbm specification:
a header of magic, width, height and ``maxval`` (``#`` comments allowed between them), then
``H * W`` samples, one byte each when ``maxval < 256`` and two bytes big-endian otherwise.
A sample ``v`` reads as ``v * 255 / maxval``, so a 16-bit map (``maxval`` 1023 or 65535)
keeps its walls, and a header whose size or ``maxval`` does not match the samples that
follow (truncated, lying, a sample above ``maxval``) is a :class:`MapError` naming the file.
Other formats (PNG, BMP, TIFF, ...) go through Pillow: 16-bit greyscale is scaled by 65535,
colour is converted to luminance; Pillow's own decoding failures become a :class:`MapError`
too. No image over 2000 x 2000 pixels is decoded (:data:`MAX_IMAGE_PIXELS`).
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from lidar_env.core.errors import MapError

#: Largest image decoded [pixels]: 2000 x 2000, the size ``World.from_image`` documents
#: (beyond it tracing needs minutes and gigabytes).
MAX_IMAGE_PIXELS = 4_000_000
#: Largest ``maxval`` of a PGM (netpbm: 16-bit samples).
MAX_PGM_MAXVAL = 65535

#: A header field: whitespace or ``#`` comments to the end of a line, then a decimal number.
_FIELD = re.compile(rb"(?:\s|#[^\n\r]*(?:[\n\r]|$))+(\d+)", re.ASCII)


def read_grey_image(path: str | os.PathLike) -> NDArray[np.float64]:
    """``(H, W)`` grey values of the image file ``path`` on the 8-bit scale [0, 255].

    Raises ``FileNotFoundError`` when there is no such file (the caller names what it was
    looking for) and :class:`MapError` naming the file for an image that cannot be read.
    """
    path = Path(path)
    with open(path, "rb") as handle:  # FileNotFoundError goes to the caller
        start = handle.read(2)
    if start in (b"P2", b"P5"):
        return _read_pgm(path)
    return _read_with_pillow(path)


def _check_size(path: Path, width: int, height: int) -> None:
    if width < 1 or height < 1:
        raise MapError(f"{path}: expected an image of at least 1 x 1 pixels, got "
                       f"{width} x {height}")
    if width * height > MAX_IMAGE_PIXELS:
        raise MapError(f"{path}: expected at most {MAX_IMAGE_PIXELS} pixels (2000 x 2000), got "
                       f"{width} x {height}; downsample it or split the map")


def _read_pgm(path: Path) -> NDArray[np.float64]:
    data = path.read_bytes()
    fields, position = [], 2
    for name in ("width", "height", "maxval"):
        match = _FIELD.match(data, position)
        if match is None or len(match.group(1)) > 12:
            raise MapError(f"{path}: PGM header: expected the {name} as a decimal number after "
                           f"byte {position}, got {data[position:position + 20]!r}")
        fields.append(int(match.group(1)))
        position = match.end()
    width, height, maxval = fields
    _check_size(path, width, height)
    if not 0 < maxval <= MAX_PGM_MAXVAL:
        raise MapError(f"{path}: PGM header: expected a maxval in 1 .. {MAX_PGM_MAXVAL}, got "
                       f"{maxval}")
    if position >= len(data) or not data[position:position + 1].isspace():
        raise MapError(f"{path}: PGM header: expected one whitespace byte after the maxval, "
                       f"got {data[position:position + 1]!r}")
    raster = data[position + 1:]
    count = width * height
    if data[:2] == b"P5":
        size = 1 if maxval < 256 else 2
        if len(raster) < count * size:
            raise MapError(f"{path}: expected {count} samples of {size} byte(s) "
                           f"({width} x {height}, maxval {maxval}), got {len(raster)} bytes: "
                           "the file is truncated or its header is wrong")
        samples = np.frombuffer(raster, dtype=">u2" if size == 2 else "u1", count=count)
    else:
        tokens = raster.split()
        if len(tokens) < count or not all(t.isdigit() for t in tokens[:count]):
            raise MapError(f"{path}: expected {count} decimal samples ({width} x {height}), "
                           f"got {sum(t.isdigit() for t in tokens[:count])} before the end or "
                           "a non-number: the file is truncated or its header is wrong")
        samples = np.array([int(t) if len(t) < 7 else maxval + 1 for t in tokens[:count]])
    if samples.max() > maxval:
        raise MapError(f"{path}: expected samples <= maxval {maxval}, got "
                       f"{int(min(samples.max(), 10**6))}")
    values = samples.astype(np.float64).reshape(height, width)
    return values if maxval == 255 else values * (255.0 / maxval)


def _read_with_pillow(path: Path) -> NDArray[np.float64]:
    from PIL import Image

    try:
        with Image.open(path) as handle:
            _check_size(path, *handle.size)
            if handle.mode in ("I", "I;16", "I;16B", "I;16L", "I;16N"):
                values = np.asarray(handle, dtype=np.float64)
                if values.size and (values.min() < 0 or values.max() > 65535):
                    raise MapError(f"{path}: expected 8- or 16-bit greyscale, got samples "
                                   f"from {values.min():.0f} to {values.max():.0f}")
                return values * (255.0 / 65535.0)
            if handle.mode == "F":
                raise MapError(f"{path}: expected 8- or 16-bit greyscale, got a floating-point "
                               "image (mode F)")
            return np.asarray(handle.convert("L"), dtype=np.float64)
    except MapError:
        raise
    except Exception as error:  # noqa: BLE001 - Pillow raises many kinds for one corrupt file
        raise MapError(f"{path}: expected a readable image file, got {type(error).__name__}: "
                       f"{str(error)[:120]}") from error
