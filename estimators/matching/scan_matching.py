"""Scan geometry shared by the scan matchers: scans to points, normals, likelihood fields.

Frames: a scan's points are first in the sensor frame (x forward, y left), then mapped into
the car frame through the sensor's mount; the estimators map them into the world frame with
the car pose. Distances are in metres, angles in radians.

K Lidars are merged by mapping every scan into the car frame through its known mount;
the result is one point set, as if from a single sensor at the car's origin.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import NamedTuple

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from estimators.base import SensorSetup
from estimators.matching.likelihood_grids import likelihood_scores
from estimators.matching.nearest import PointIndex
from estimators.matching.neighbourhood_fits import GROW_SPREAD, local_fits
from estimators.matching.prediction import median
from lidar_env.core import ConfigError, EstimatorInputError
from lidar_env.core.se2 import transform_points

#: Readings at or below this [m] are treated as "no return" (CARMEN logs write 0 for none).
DEFAULT_MIN_RANGE: float = 0.05


def scan_to_points(
    ranges: ArrayLike,
    angles: ArrayLike,
    max_range: float,
    mount: ArrayLike = (0.0, 0.0, 0.0),
    min_range: float = DEFAULT_MIN_RANGE,
) -> NDArray[np.float64]:
    """Points ``(M, 2)`` [m] of the beams that hit something, in the frame the sensor is
    ``mount``-ed in (the sensor frame itself for the default identity mount).

    Beams with ``range >= max_range`` or ``range <= min_range`` carry no return and are dropped.
    """
    ranges = np.asarray(ranges, dtype=np.float64)
    angles = np.asarray(angles, dtype=np.float64)
    if ranges.shape != angles.shape or ranges.ndim != 1:
        raise EstimatorInputError(
            f"ranges and angles: expected equal 1-D shapes, got {ranges.shape}, {angles.shape}"
        )
    hit = (ranges < max_range) & (ranges > min_range)
    r, a = ranges[hit], angles[hit]
    points = np.column_stack([r * np.cos(a), r * np.sin(a)])
    return transform_points(mount, points)


def scans_to_car_points(
    scans: Mapping[str, NDArray[np.float64]],
    setup: SensorSetup,
    min_range: float = DEFAULT_MIN_RANGE,
) -> NDArray[np.float64]:
    """All Lidars' hits ``(M, 2)`` [m] merged in the car frame through the known mounts, each
    scan read with its own sensor's beam angles and max range (:class:`CarPoints` once)."""
    return CarPoints(setup, min_range)(scans)


@njit(cache=True)
def _beam_points(ranges: NDArray[np.float64], cos: NDArray[np.float64],
                 sin: NDArray[np.float64], max_range: float,
                 min_range: float) -> NDArray[np.float64]:
    """``r (cos a, sin a)`` (M, 2) [m] of the beams with ``min_range < r < max_range``, in beam
    order, from each beam's ``cos a`` and ``sin a``: :func:`scan_to_points`'s sensor-frame
    points, the same products."""
    count = 0
    for i in range(len(ranges)):
        if ranges[i] < max_range and ranges[i] > min_range:
            count += 1
    points = np.empty((count, 2))
    row = 0
    for i in range(len(ranges)):
        if ranges[i] < max_range and ranges[i] > min_range:
            points[row, 0], points[row, 1] = ranges[i] * cos[i], ranges[i] * sin[i]
            row += 1
    return points


class CarPoints:
    """:func:`scans_to_car_points` for one ``setup``, each sensor's beam directions and mount
    rotation computed once rather than on every scan (a dozen numpy calls of a few
    microseconds per Lidar and scan): bit for bit the points of :func:`scan_to_points` mapped
    through each mount (the same products and the same matrix product as
    :func:`lidar_env.core.se2.transform_points`)."""

    def __init__(self, setup: SensorSetup, min_range: float = DEFAULT_MIN_RANGE) -> None:
        self.min_range = float(min_range)
        self._sensors = []
        for key, sensor in zip(setup.keys, setup.sensors, strict=True):
            mount = np.asarray(sensor.mount, dtype=np.float64)
            c, s = np.cos(mount[2]), np.sin(mount[2])
            angles = np.asarray(sensor.beam_angles, dtype=np.float64)
            self._sensors.append((key, np.cos(angles), np.sin(angles), float(sensor.max_range),
                                  np.array([[c, -s], [s, c]]), mount[:2]))
        self.beams = sum(len(cos) for _, cos, *_ in self._sensors)  # all Lidars, points' order

    @staticmethod
    def _ranges(scans: Mapping[str, NDArray[np.float64]], key: str,
                cos: NDArray[np.float64]) -> NDArray[np.float64]:
        """Lidar ``key``'s ranges [m] of ``scans``, one per beam, as float64."""
        ranges = np.ascontiguousarray(scans[key], dtype=np.float64)
        if ranges.shape != cos.shape:
            raise EstimatorInputError(
                f"{key}: expected {cos.shape[0]} ranges (one per beam), got shape "
                f"{ranges.shape}")
        return ranges

    def __call__(self, scans: Mapping[str, NDArray[np.float64]]) -> NDArray[np.float64]:
        """The hits ``(M, 2)`` [m] of ``scans`` (ranges [m] by Lidar key) in the car frame."""
        merged = []
        for key, cos, sin, max_range, rotation, translation in self._sensors:
            points = _beam_points(self._ranges(scans, key, cos), cos, sin, max_range,
                                  self.min_range)
            merged.append(points @ rotation.T + translation)
        return merged[0] if len(merged) == 1 else np.concatenate(merged)

    def returned(self, scans: Mapping[str, NDArray[np.float64]]) -> NDArray[np.bool_]:
        """Which beams (:attr:`beams`,) of ``scans`` returned, each giving a point, in order."""
        return np.concatenate([
            (ranges < max_range) & (ranges > self.min_range) for ranges, max_range in (
                (self._ranges(scans, key, cos), max_range)
                for key, cos, _, max_range, *_ in self._sensors)])


@njit(cache=True)
def cell_key_and_slot(x: float, y: float, voxel_size: float, shift: np.uint64
                      ) -> tuple[np.int64, np.int64]:
    """The ``voxel_size`` [m] cell of point ``(x, y)`` [m] as :func:`voxel_downsample` keys it
    (``floor(x / voxel_size) << 32`` plus the low 32 bits of ``floor(y / voxel_size)``) and its
    first slot (Fibonacci hashing) in an open-addressing table of ``2 ** (64 - shift)`` slots."""
    cx = np.int64(np.floor(x / voxel_size))
    cy = np.int64(np.floor(y / voxel_size))
    key = (cx << 32) + (cy & 0xFFFFFFFF)
    return key, np.int64((np.uint64(key) * np.uint64(0x9E3779B97F4A7C15)) >> shift)


@njit(cache=True)
def first_in_each_cell(points: NDArray[np.float64], voxel_size: float) -> NDArray[np.bool_]:
    """Whether each of ``points`` (N, 2) [m] is the first in its ``voxel_size`` cell: the
    cells' keys as :func:`voxel_downsample` forms them, in an open-addressing hash set (linear
    probing, Fibonacci hashing): O(N), where ``np.unique``'s stable sort is O(N log N) and a
    dozen numpy calls (a 7,000-point local map: ~0.7 ms)."""
    size = 2
    while size < 2 * len(points):
        size *= 2
    shift = np.uint64(64 - int(np.log2(size)))
    mask = size - 1
    table = np.empty(size, np.int64)
    used = np.zeros(size, np.bool_)
    first = np.zeros(len(points), np.bool_)
    for i in range(len(points)):
        key, slot = cell_key_and_slot(points[i, 0], points[i, 1], voxel_size, shift)
        while used[slot] and table[slot] != key:
            slot = (slot + 1) & mask
        if not used[slot]:
            used[slot], table[slot], first[i] = True, key, True
    return first


def voxel_downsample(points: NDArray[np.float64], voxel_size: float,
                     compiled: bool = True) -> NDArray[np.float64]:
    """Keep the first point of every ``voxel_size`` [m] square cell (order preserved).
    ``compiled`` finds the first points with :func:`first_in_each_cell`, else with
    ``np.unique`` (the same points; the tests' reference). The rows are picked by
    ``np.compress``: the same rows as a boolean index, five times faster on a keyframe map
    (4,600 points: 15 vs 75 us)."""
    if voxel_size <= 0:
        raise ConfigError(f"voxel_size: expected a positive size [m], got {voxel_size}")
    if compiled:
        first = first_in_each_cell(np.ascontiguousarray(points, np.float64), voxel_size)
        return np.asarray(points).compress(first, axis=0)
    cells = np.floor(points / voxel_size).astype(np.int64)
    # One integer key per cell (a 1-D unique is far faster than np.unique(axis=0)); cells
    # within +-2^31 voxels of the origin never collide.
    keys = (cells[:, 0] << 32) + (cells[:, 1] & 0xFFFFFFFF)
    _, first = np.unique(keys, return_index=True)
    return points[np.sort(first)]


class _Neighbourhoods(NamedTuple):
    """Some points' nearest neighbours within a radius and the line fitted through them."""

    rows: NDArray[np.intp]  # (n,) which points these are
    index: NDArray[np.intp]  # (n, k) their neighbours, len(points) for a missing one
    count: NDArray[np.float64]  # (n,) neighbours found
    mean: NDArray[np.float64]  # (n, 2) their centroid
    normals: NDArray[np.float64]  # (n, 2) unit normal of their principal axis
    across: NDArray[np.float64]  # (n,) RMS distance [m] of the neighbours from that axis
    valid: NDArray[np.bool_]  # (n,) a line: >= 3 neighbours, clearly elongated spread


def _gathered(points: NDArray[np.float64], rows: NDArray[np.intp], index: NDArray[np.intp],
              ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The neighbours ``index`` (n, k) of ``points[rows]`` as points (n, k, 2), a missing one
    repeating the point itself, and their weights (n, k): 1 found, 0 missing."""
    found = index < len(points)
    return points[np.where(found, index, rows[:, None])], found.astype(np.float64)


def _fit_rows(
    points: NDArray[np.float64], tree: PointIndex | cKDTree, rows: NDArray[np.intp], k: int,
    max_radius: float,
) -> _Neighbourhoods:
    """Lines through the ``k`` nearest neighbours (within ``max_radius``) of ``points[rows]``
    (``tree``: anything with ``cKDTree.query``'s signature over ``points``), in arrays."""
    _, index = tree.query(points[rows], k=k, distance_upper_bound=max_radius)
    index = index.reshape(len(rows), k).astype(np.int64, copy=False)
    neighbours, weights = _gathered(points, rows, index)
    count = weights.sum(axis=1)
    mean = (neighbours * weights[..., None]).sum(axis=1) / count[:, None]
    centred = (neighbours - mean[:, None, :]) * weights[..., None]
    sxx = (centred[..., 0] ** 2).sum(axis=1)
    syy = (centred[..., 1] ** 2).sum(axis=1)
    sxy = (centred[..., 0] * centred[..., 1]).sum(axis=1)
    # The normal is the eigenvector of the smaller eigenvalue of [[sxx, sxy], [sxy, syy]].
    direction = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)
    normals = np.column_stack([-np.sin(direction), np.cos(direction)])
    spread = np.sqrt((sxx - syy) ** 2 + 4.0 * sxy**2)
    small = 0.5 * (sxx + syy - spread)
    large = 0.5 * (sxx + syy + spread)
    across = np.sqrt(np.maximum(small, 0.0) / count)
    # The point itself must lie within the band (3 sigma of the spread across the line): a
    # return off a chair leg next to a wall is not a wall point.
    own = np.abs(np.einsum("ij,ij->i", points[rows] - mean, normals))
    valid = (count >= 3) & (small < 0.1 * large) & (own <= 3.0 * across + 1e-9)
    return _Neighbourhoods(rows, index, count, mean, normals, across, valid)


def _subset(fit: _Neighbourhoods, keep: NDArray[np.bool_]) -> _Neighbourhoods:
    """The rows of ``fit`` where ``keep`` (n,) holds."""
    return _Neighbourhoods(*(value[keep] for value in fit))


def _fit_lines(
    points: NDArray[np.float64], tree: PointIndex | cKDTree, k: int, max_radius: float,
    max_k: int | None = None,
) -> list[_Neighbourhoods]:
    """Lines through each point's ``k`` nearest neighbours; where they do not form one, the
    neighbourhood doubles (up to ``max_k`` points and ``max_radius``) until they do.

    Returns the fits grouped by neighbourhood size, each point in exactly one group: most
    points keep ``k`` neighbours, and later steps (the parabolas of :func:`fit_local_curves`)
    then work on ``k``-wide arrays for them rather than on all points padded to the widest.

    Why grow: the line test compares the spread across the fitted line with the spread along
    it, and a few neighbours of a noisy wall (range noise comparable to the point spacing)
    span a band about as wide as it is long, so they fail it; more neighbours span more of
    the wall while the band stays as wide. A corner or a blob stays one at any size, but a
    small feature (a door jamb a few cm deep) would be smoothed into the wall around it, and
    its point-to-line pairs are what pins the motion along a corridor; so a grown line is
    kept only if its spread across is at most twice the typical one of the first fits (their
    median, i.e. the walls' range noise): where the sensor is precise, the feature stands out
    of that noise and stays a feature; where it is as noisy as the feature is deep, it cannot
    be told from a wall anyway. Growing is tried up to ``GROW_SPREAD`` times that limit: a
    noisy wall's band has first fits just past it by chance.
    """
    fit = _fit_rows(points, tree, np.arange(len(points)), min(k, len(points)), max_radius)
    noise = 2.0 * median(fit.across)  # np.median's, bit for bit
    groups = [fit]
    width = fit.index.shape[1]
    limit = min(max_k or k, len(points))
    while width < limit:
        # Only the widest group can grow: a point with fewer neighbours than its width has
        # its whole neighbourhood within max_radius in the fit already.
        widest = groups[-1]
        grow = ~widest.valid & (widest.count == width) & (widest.across <= GROW_SPREAD * noise)
        if not np.any(grow):
            break
        width = min(2 * width, limit)
        grown = _fit_rows(points, tree, widest.rows[grow], width, max_radius)
        groups[-1] = _subset(widest, ~grow)
        groups.append(grown._replace(valid=grown.valid & (grown.across <= noise)))
    return groups


def estimate_normals(
    points: NDArray[np.float64], tree: PointIndex | cKDTree, k: int = 5, max_radius: float = 0.5,
    max_k: int | None = None, compiled: bool = True,
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Unit normals ``(M, 2)`` of the local line through each point's ``k`` nearest neighbours
    (principal axis of their covariance), and which points have a reliable one: at least 3
    neighbours within ``max_radius`` [m] and a clearly elongated spread (a line, not a blob:
    the smaller eigenvalue below a tenth of the larger). With ``max_k`` > ``k``, a point whose
    neighbours fail that test is fitted again through twice as many, up to ``max_k``: what a
    noisy wall needs (see :func:`_fit_lines`); None keeps ``k``. ``compiled`` fits in the
    numba kernels of :mod:`estimators.matching.neighbourhood_fits` (``tree`` must then be a
    :class:`PointIndex`), else in arrays (the same math; the tests' reference)."""
    if compiled:
        normals, valid, _ = local_fits(points, tree, k, max_radius, max_k, curves=False)
        return normals, valid
    normals = np.empty((len(points), 2))
    valid = np.empty(len(points), dtype=bool)
    for fit in _fit_lines(points, tree, k, max_radius, max_k):
        normals[fit.rows], valid[fit.rows] = fit.normals, fit.valid
    return normals, valid


def _curve_points(
    points: NDArray[np.float64], fit: _Neighbourhoods,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Normals and anchors ``(n, 2)``: ``points[fit.rows]`` moved onto the parabola through
    their neighbours in the frame of their line (see :func:`fit_local_curves`), in arrays."""
    neighbours, weights = _gathered(points, fit.rows, fit.index)
    points = points[fit.rows]
    tangents = np.column_stack([fit.normals[:, 1], -fit.normals[:, 0]])
    offsets = neighbours - fit.mean[:, None, :]
    along = np.einsum("ijk,ik->ij", offsets, tangents)
    across = np.einsum("ijk,ik->ij", offsets, fit.normals)
    basis = np.stack([np.ones_like(along), along, along**2], axis=-1) * weights[..., None]
    gram = np.einsum("ijk,ijl->ikl", basis, basis)
    moment = np.einsum("ijk,ij->ik", basis, across)
    a, b, c = np.linalg.solve(gram, moment[..., None])[..., 0].T
    s = np.einsum("ij,ij->i", points - fit.mean, tangents)
    on_curve = fit.mean + s[:, None] * tangents + (a + b * s + c * s**2)[:, None] * fit.normals
    curve_normals = fit.normals - (b + 2.0 * c * s)[:, None] * tangents
    curve_normals /= np.linalg.norm(curve_normals, axis=1)[:, None]
    return curve_normals, on_curve


def fit_local_curves(
    points: NDArray[np.float64], tree: PointIndex | cKDTree, k: int = 9, max_radius: float = 0.5,
    max_k: int | None = None, compiled: bool = True,
) -> tuple[NDArray[np.float64], NDArray[np.bool_], NDArray[np.float64]]:
    """Denoised surface points: normals ``(M, 2)``, which are reliable (as
    :func:`estimate_normals`), and anchors ``(M, 2)``.

    Where the ``k`` neighbours (within ``max_radius`` [m]) form a line and number at least 5,
    a parabola ``t = a + b s + c s^2`` is fitted to them in that line's frame (``s`` along,
    ``t`` across); the anchor is the point moved onto it and the normal is the parabola's at
    that point. The anchor then carries the range noise of ``k`` readings averaged rather
    than one reading's, and, unlike a projection onto the straight line, is not pulled
    towards the centre of a curved surface (by ``curvature * spread^2 / 6``: ~2 cm on a
    0.3 m cylinder seen over 0.4 m). Elsewhere the raw point and the line's normal are kept.
    ``max_k`` grows the neighbourhoods that fail the line test, as in :func:`estimate_normals`.
    ``compiled`` as in :func:`estimate_normals`.
    """
    if compiled:
        return local_fits(points, tree, k, max_radius, max_k, curves=True)
    normals = np.empty((len(points), 2))
    valid = np.empty(len(points), dtype=bool)
    anchors = points.astype(np.float64)
    for fit in _fit_lines(points, tree, k, max_radius, max_k):
        normals[fit.rows], valid[fit.rows] = fit.normals, fit.valid
        curved = _subset(fit, fit.valid & (fit.count >= 5))
        normals[curved.rows], anchors[curved.rows] = _curve_points(points, curved)
    return normals, valid, anchors


class LikelihoodField:
    """A grid [m] holding, per cell, ``exp(-d^2 / 2 sigma^2)`` of the distance ``d`` to the
    nearest reference point: the smooth score of Olson's correlative scan matching.

    E. Olson, "Real-time correlative scan matching", ICRA 2009.
    """

    def __init__(
        self, points: NDArray[np.float64], resolution: float = 0.05, sigma: float = 0.1,
        margin: float = 1.0,
    ) -> None:
        if len(points) == 0:
            raise EstimatorInputError("points: expected at least one reference point, got none")
        if resolution <= 0 or sigma <= 0:
            raise ConfigError(
                f"resolution and sigma: expected positive [m], got {resolution}, {sigma}"
            )
        self.resolution = resolution
        self.origin = points.min(axis=0) - margin
        shape = np.ceil((points.max(axis=0) + margin - self.origin) / resolution).astype(int) + 1
        occupied = np.zeros(tuple(shape), dtype=bool)
        cells = np.floor((points - self.origin) / resolution).astype(int)
        occupied[cells[:, 0], cells[:, 1]] = True
        self.grid = self._scores(occupied, resolution, sigma)

    @staticmethod
    def _scores(occupied: NDArray[np.bool_], resolution: float,
                sigma: float) -> NDArray[np.float64]:
        """The grid's scores from its ``occupied`` cells (those holding a reference point),
        by the compiled exact distance transform
        (:func:`~estimators.matching.likelihood_grids.likelihood_scores`)."""
        return likelihood_scores(occupied, resolution, sigma)

    def score(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """Score of each point ``(..., 2)`` [m]; 0 outside the grid."""
        cells = np.floor((points - self.origin) / self.resolution).astype(np.int64)
        inside = (
            (cells[..., 0] >= 0) & (cells[..., 0] < self.grid.shape[0])
            & (cells[..., 1] >= 0) & (cells[..., 1] < self.grid.shape[1])
        )
        scores = np.zeros(points.shape[:-1])
        scores[inside] = self.grid[cells[inside][:, 0], cells[inside][:, 1]]
        return scores
