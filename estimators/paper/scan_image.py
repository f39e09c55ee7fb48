"""From a planar scan to the image the paper's phase correlation works on (eqs. 4 and 5).

Image geometry (shared by every function here): the sensor sits at the image centre, at the
corner shared by pixels ``(size/2 - 1, size/2 - 1)`` and ``(size/2, size/2)``. The sensor's
forward axis x [m] grows along the columns (left to right) and its left axis y [m] grows
*up* the image, i.e. towards row 0, so the image reads like a map (as ``World.to_image``):

    col = floor(x / resolution) + size / 2
    row = size / 2 - 1 - floor(y / resolution)

A shift of the image content by ``(d_row, d_col)`` pixels is therefore a shift of the scene
by ``(dx, dy) = (d_col, -d_row) * resolution`` metres (:func:`pixel_shift_to_metres`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimators.paper.scan_image_kernel import draw_scan
from lidar_env.core import ConfigError, EstimatorInputError

#: Default image side [px]: the paper's default 400 x 400.
DEFAULT_SIZE = 400
#: Default resolution [m/px] of :func:`points_to_image`: a 10 m range across 200 px.
DEFAULT_RESOLUTION = 0.05

#: A point's corner measure (see :func:`scan_to_image`) at which its corner weight saturates.
#: Along a flat wall seen at incidence angle theta the measure is about 2 tan(theta): 7.5 is
#: reached at 75 degrees, so only grazing walls and depth jumps (object edges) count as corners.
CORNER_SATURATION = 2.0 * np.tan(np.deg2rad(75.0))

#: Pixel value of the weakest return. Every return must register in the image (a far point
#: is still evidence), but stays below near or corner-like points.
MIN_PIXEL_VALUE = 64


def check_image_size(size: int) -> None:
    """Raise unless ``size`` [px] is a positive even integer."""
    if isinstance(size, bool) or not isinstance(size, (int, np.integer)) or size <= 0 or size % 2:
        raise ConfigError(f"size: expected a positive even integer [px], got {size!r}")


def _check_resolution(resolution: float) -> float:
    resolution = float(resolution)
    if not np.isfinite(resolution) or resolution <= 0:
        raise ConfigError(f"resolution: expected a positive finite number [m/px], got {resolution}")
    return resolution


def check_image_geometry(size: int, resolution: float | None, max_range: float) -> float:
    """Validate an image ``size`` [px] and ``resolution`` [m/px]; return the resolution.

    ``resolution=None`` picks the finest one whose image still holds every return:
    ``2 max_range / size`` (0.05 m/px for 400 px and 10 m).
    """
    check_image_size(size)
    if not np.isfinite(max_range) or max_range <= 0:
        raise ConfigError(f"max_range: expected a positive finite number [m], got {max_range!r}")
    if resolution is None:
        return 2.0 * float(max_range) / int(size)
    resolution = _check_resolution(resolution)
    half_extent = resolution * int(size) / 2.0
    if half_extent < max_range:
        raise ConfigError(
            f"resolution {resolution} m/px cannot hold max_range {max_range} m in a {size} px "
            f"image (it reaches only {half_extent:g} m from the centre): expected a resolution "
            f">= {2.0 * max_range / size:g} m/px"
        )
    if max_range / resolution < 2.0:
        raise ConfigError(
            f"resolution {resolution} m/px is too coarse for max_range {max_range} m: expected "
            f"at most {max_range / 2.0:g} m/px so a scan spans more than 2 px"
        )
    return resolution


def _checked_scan(
    ranges: ArrayLike, beam_angles: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``ranges`` and ``beam_angles`` as float64 ``(n,)``, after checking they make a scan."""
    ranges = np.asarray(ranges, dtype=np.float64)
    angles = np.asarray(beam_angles, dtype=np.float64)
    if ranges.ndim != 1 or ranges.shape != angles.shape or len(ranges) < 3:
        raise EstimatorInputError(
            f"expected ranges and beam_angles of equal shape (n,), n >= 3; got {ranges.shape} "
            f"and {angles.shape}"
        )
    if not 0.0 <= ranges.min() <= ranges.max() < np.inf:  # NaN fails both
        raise EstimatorInputError(
            "ranges: expected finite ranges >= 0 [m], got NaN, inf or negative")
    return ranges, angles


def scan_filter(
    ranges: ArrayLike, beam_angles: ArrayLike, max_range: float
) -> NDArray[np.float64]:
    """The paper's filter Fl(S) (eq. 4) for the beams that returned (``0 < l < max_range``;
    a zero range, a sensor touching an obstacle, has no direction to place a point along).

    Args:
        ranges: ``(n,)`` ranges [m] of one full revolution; ``>= max_range`` is "no return".
        beam_angles: ``(n,)`` beam directions [rad] in the frame the points should be in.
        max_range: [m].

    Returns:
        ``(m, 4)`` rows ``(x [m], y [m], c [m], mean [m])`` for the ``m`` beams with a return:
        ``x = l_i cos a_i``, ``y = l_i sin a_i``, the neighbour term
        ``c = (l_{i-1}^2 - l_{i+1}^2) / (2 l_i)`` and ``mean(l_{i-1}, l_i, l_{i+1})``.
        Neighbours wrap around (the scan is a full circle); a neighbour without a return
        counts as ``max_range``, so the edge of an object stands out as a large ``|c|``.
    """
    ranges, angles = _checked_scan(ranges, beam_angles)
    clipped = np.minimum(ranges, max_range)
    # np.roll's values, without its generality (a third of this function's time)
    before = np.concatenate((clipped[-1:], clipped[:-1]))
    after = np.concatenate((clipped[1:], clipped[:1]))
    hit = (ranges < max_range) & (ranges > 0)
    l_i = clipped[hit]
    # eq. 4
    return np.column_stack(
        [
            l_i * np.cos(angles[hit]),
            l_i * np.sin(angles[hit]),
            (before[hit] ** 2 - after[hit] ** 2) / (2.0 * l_i),
            (before[hit] + l_i + after[hit]) / 3.0,
        ]
    )


def points_to_image(
    points: ArrayLike,
    values: ArrayLike,
    size: int = DEFAULT_SIZE,
    resolution: float = DEFAULT_RESOLUTION,
) -> NDArray[np.uint8]:
    """Draw points ``(N, 2)`` [m] (sensor frame) as uint8 ``values`` (N,) into a zero image.

    Points outside the image are dropped; where several points fall into one pixel the
    largest value wins. See the module docstring for the geometry.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    values = np.asarray(values)
    if values.shape != (len(points),):
        raise EstimatorInputError(f"values: expected shape ({len(points)},), got {values.shape}")
    if values.size and (np.min(values) < 0 or np.max(values) > 255):
        raise EstimatorInputError("values: expected pixel values in [0, 255] (uint8)")
    check_image_size(size)
    resolution = _check_resolution(resolution)
    half = size // 2
    cols = np.floor(points[:, 0] / resolution).astype(np.int64) + half
    rows = half - 1 - np.floor(points[:, 1] / resolution).astype(np.int64)
    inside = (cols >= 0) & (cols < size) & (rows >= 0) & (rows < size)
    image = np.zeros((size, size), dtype=np.uint8)
    np.maximum.at(image, (rows[inside], cols[inside]), values[inside].astype(np.uint8))
    return image


def pixel_values(filtered: NDArray[np.float64], max_range: float, beam_step: float) -> NDArray:
    """The paper's rule (eq. 5): a uint8 value per filtered point, stronger near the sensor
    or where the point is corner-like.

    Our rule (the paper gives none): ``value = 64 + 191 max(w_near, w_corner)`` with
    ``w_near = 1 - mean / max_range`` (near points are denser and more precisely placed:
    beams 1 degree apart are 17 cm = 3.5 px apart at 10 m) and
    ``w_corner = min(1, |c| / (mean * beam_step) / CORNER_SATURATION)``: ``|c| / mean``
    divided by the beam step is scale-free (about ``2 tan(incidence)`` on a flat wall), so
    depth jumps and edges, which stay put under translation while points slide along walls,
    saturate it. The smoothed ``mean`` rather than ``l_i`` keeps range noise out of the weights.
    """
    mean = filtered[:, 3]
    w_near = 1.0 - mean / max_range
    corner = np.abs(filtered[:, 2]) / (mean * beam_step)
    w_corner = np.minimum(1.0, corner / CORNER_SATURATION)
    weight = np.clip(np.maximum(w_near, w_corner), 0.0, 1.0)
    # eq. 5
    return (MIN_PIXEL_VALUE + (255 - MIN_PIXEL_VALUE) * weight).astype(np.uint8)


def scan_to_image(
    ranges: ArrayLike,
    beam_angles: ArrayLike,
    max_range: float,
    size: int = DEFAULT_SIZE,
    resolution: float | None = None,
    turn: float = 0.0,
    compiled: bool = True,
) -> NDArray[np.uint8]:
    """One scan as a ``(size, size)`` uint8 image (eqs. 4 and 5); zero where nothing returned.

    Args:
        ranges: ``(n,)`` ranges [m]; ``>= max_range`` is "no return".
        beam_angles: ``(n,)`` beam directions [rad], CCW from the image's x axis (the sensor's
            forward axis, or world +x for world-aligned scans).
        max_range: [m].
        size: image side [px], a positive even integer (default 400, the paper's).
        resolution: [m/px]; default ``2 max_range / size``; must hold ``max_range``.
        turn: [rad] added to every beam angle (draws the scan rotated by it, e.g. into another
            sensor's axes).
        compiled: draw in one numba pass (:func:`estimators.paper.scan_image_kernel.draw_scan`)
            rather than by :func:`scan_filter`, :func:`pixel_values` and
            :func:`points_to_image`, the same image pixel for pixel.
    To draw arbitrary points, use :func:`points_to_image`.
    """
    resolution = check_image_geometry(size, resolution, max_range)
    ranges, angles = _checked_scan(ranges, beam_angles)
    if compiled:
        return draw_scan(ranges, angles, float(turn), float(max_range), int(size), resolution,
                         MIN_PIXEL_VALUE, CORNER_SATURATION)
    filtered = scan_filter(ranges, angles + turn, max_range)
    beam_step = 2.0 * np.pi / len(angles)
    values = pixel_values(filtered, max_range, beam_step)
    return points_to_image(filtered[:, :2], values, size, resolution)


def pixel_shift_to_metres(shift: ArrayLike, resolution: float) -> NDArray[np.float64]:
    """Image content shift ``(d_row, d_col)`` [px] -> scene shift ``(dx, dy)`` [m]."""
    d_row, d_col = np.asarray(shift, dtype=np.float64)
    return np.array([d_col * resolution, -d_row * resolution])
