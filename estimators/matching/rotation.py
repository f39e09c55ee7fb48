"""Heading change between two Lidar scans, before any translation is known.

The paper's phase correlation (eqs. 6-9) recovers a shift only; with scans in the sensor frame
the heading must be found first. Two independent measurements are provided:

* :func:`spectrum_rotation` -- Fourier-Mellin: the magnitude of an image's Fourier transform
  does not change when the image is shifted, and it turns with the image. Resampled on a
  log-polar grid, a rotation becomes a circular shift along the angle axis, found by
  correlation with sub-bin refinement. The magnitude is point-symmetric, so the angle is
  known modulo pi only.
* :func:`range_profile_rotation` -- circular correlation of the two range profiles over the
  beam index: coarse (translation distorts the profile near walls) but free of the pi
  ambiguity; it needs beams spread evenly over a full turn.

:func:`heading_change` combines them: the precise spectrum angle, with its pi ambiguity resolved
by a predicted turn when one is known, else by the profile, else (partial fields of view) by
assuming the smaller turn.

Angles are radians, counter-clockwise positive. A *heading change* is the turn of the sensor
from scan ``a`` to scan ``b``; the scene then appears turned by minus that angle in scan ``b``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache

import numpy as np
import scipy.fft
from numba import njit
from numpy.typing import ArrayLike, NDArray

from estimators.paper.phase_correlation_kernel import (
    real_spectrum,
    real_spectrum_of_rows,
    uint8_rows,
)
from lidar_env.core import ConfigError, EstimatorInputError
from lidar_env.core.se2 import wrap_float

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class RotationEstimate:
    """An angle [rad] and a confidence in [0, 1] (normalised correlation at the peak)."""

    angle: float
    confidence: float


def _subbin_peak(correlation: FloatArray) -> tuple[float, float]:
    """Index of the maximum of a circular 1-D correlation, refined by a parabola through the
    peak and its two neighbours; returns (fractional index, peak value)."""
    n = len(correlation)
    k = int(np.argmax(correlation))
    left, centre, right = correlation[(k - 1) % n], correlation[k], correlation[(k + 1) % n]
    curvature = left - 2.0 * centre + right
    offset = float(0.5 * (left - right) / curvature) if curvature < 0 else 0.0
    # np.clip of one number, on the float (its per-call cost is most of this function's)
    return k + min(max(offset, -0.5), 0.5), float(centre)


@dataclass(frozen=True)
class CentredSpectrum:
    """A signal ``(n, ...)`` with its mean over axis 0 removed, as a circular correlation
    needs it: ``transform`` its real DFT over axis 0, ``energy`` its sum of squares, ``length``
    its ``n``. Made once per signal (:func:`centred_spectrum`), e.g. for a keyframe's
    log-polar grid correlated with every later scan's."""

    transform: NDArray[np.complex128]
    energy: float
    length: int


def centred_spectrum(signal: FloatArray) -> CentredSpectrum:
    """The :class:`CentredSpectrum` of ``signal`` ``(n, ...)``."""
    if signal.dtype == np.float64:
        # np.mean's and np.sum's reductions without their Python wrappers: the same ufunc
        # calls, bit for bit (a keyframe's and every scan's log-polar grid go through here)
        centred = signal - np.add.reduce(signal, axis=0) / len(signal)
        energy = float(np.add.reduce(centred * centred, axis=None))
    else:
        centred = signal - signal.mean(axis=0)
        energy = float(np.sum(centred * centred))
    # scipy's transform: numpy's values (on every log-polar grid of the 5 default drives) at
    # three quarters of its cost
    return CentredSpectrum(scipy.fft.rfft(centred, axis=0, workers=1), energy, len(signal))


def _circular_correlation(
    a: FloatArray | CentredSpectrum, b: FloatArray | CentredSpectrum
) -> FloatArray:
    """``c[k] = sum_i b[i] a[i - k]`` over axis 0, summed over any further axes, normalised
    to the Pearson correlation of the mean-removed inputs (so ``c`` lies in [-1, 1]); either
    input may be given as its :func:`centred_spectrum`."""
    a = a if isinstance(a, CentredSpectrum) else centred_spectrum(a)
    b = b if isinstance(b, CentredSpectrum) else centred_spectrum(b)
    spectrum = b.transform * np.conj(a.transform)
    if spectrum.ndim > 1:  # ndarray.sum's reduction without its wrapper
        spectrum = np.add.reduce(spectrum, axis=tuple(range(1, spectrum.ndim)))
    norm = math.sqrt(a.energy * b.energy)  # correctly rounded, as np.sqrt
    if norm == 0.0:
        return np.zeros(a.length)
    return np.fft.irfft(spectrum, n=a.length) / norm


def log_polar_spectrum(
    image: ArrayLike, n_angles: int = 360, n_radii: int = 64, min_radius: float = 4.0,
    compiled: bool = True,
) -> FloatArray:
    """Magnitude spectrum of ``image`` (H, W) resampled on a log-polar grid.

    Returns ``(n_angles, n_radii)``: row ``k`` is the direction ``-pi/2 + pi k / n_angles`` in
    the (column, row) frequency plane (half a turn suffices: the magnitude of a real image's
    spectrum is point-symmetric), columns are radii spaced evenly in log from ``min_radius``
    [frequency bins] to 0.45 of the smaller image side. Values are ``log1p`` of the magnitude
    times the radius, which evens out the 1/f fall-off so fine detail weighs in.
    ``compiled``: window the image in one numba loop that leaves empty rows alone, transform
    only its occupied rows (:func:`estimators.paper.phase_correlation_kernel.real_spectrum`)
    and sample in one numba loop (:func:`_sample_log_polar`) rather than by numpy, ``rfft2``
    and ``np.einsum`` over the gathered bins, the same values bit for bit.
    """
    image = np.asarray(image)
    if image.dtype != np.uint8 or not compiled:
        image = image.astype(np.float32, copy=False)
    if image.ndim != 2 or min(image.shape) < 16:
        raise EstimatorInputError(
            f"image: expected a 2-D array of at least 16x16 pixels, got {image.shape}")
    if n_angles < 8 or n_radii < 2:
        raise ConfigError(f"expected n_angles >= 8 and n_radii >= 2, got {n_angles}, {n_radii}")
    height, width = image.shape
    max_radius = 0.45 * min(height, width)
    if not 0 < min_radius < max_radius:
        raise ConfigError(f"min_radius: expected a value in (0, {max_radius}), got {min_radius}")
    window, corners, weights, radii = _log_polar_grid(
        height, width, n_angles, n_radii, min_radius
    )
    if compiled:
        if image.dtype == np.uint8:  # a drawn scan: its occupied rows only
            magnitude = np.abs(real_spectrum_of_rows(*uint8_rows(image, window), height))
        else:
            magnitude = np.abs(real_spectrum(_windowed(image, window)))
        # numpy's log1p, not numba's: they differ in the last bit on AVX-512 machines
        return np.log1p(_sample_log_polar(magnitude.ravel(), corners, weights, radii))
    magnitude = np.abs(scipy.fft.rfft2(image * window, workers=1))
    # Bilinear interpolation: the four neighbouring bins of each sample, weighted.
    samples = np.einsum("kij,kij->ij", magnitude.ravel()[corners], weights)
    return np.log1p(samples * radii)


@njit(cache=True, nogil=True)
def _windowed(
    image: NDArray[np.float32], window: NDArray[np.float32]
) -> NDArray[np.float32]:  # pragma: no cover (numba)
    """``image * window`` (float32, as numpy multiplies them); rows of +0.0 stay zeros
    untouched (a scan image's many empty rows)."""
    rows, cols = image.shape
    bits = image.view(np.uint32)
    out = np.zeros((rows, cols), dtype=np.float32)
    for r in range(rows):
        union = np.uint32(0)
        for c in range(cols):
            union |= bits[r, c]
        if union != 0:
            for c in range(cols):
                out[r, c] = image[r, c] * window[r, c]
    return out


@njit(cache=True, nogil=True)
def _sample_log_polar(
    magnitude: NDArray[np.float32], corners: NDArray[np.intp], weights: FloatArray,
    radii: FloatArray,
) -> FloatArray:  # pragma: no cover (numba)
    """:func:`log_polar_spectrum`'s bilinear samples times their radius,
    ``radius * sum_k w_k |F|_k``, of the flat magnitude spectrum, from its four-corner indices
    and weights (4, angles, radii)."""
    _, n_angles, n_radii = corners.shape
    samples = np.empty((n_angles, n_radii))
    for i in range(n_angles):
        for j in range(n_radii):
            total = 0.0
            for k in range(4):
                total += magnitude[corners[k, i, j]] * weights[k, i, j]
            samples[i, j] = total * radii[j]
    return samples


@cache
def _log_polar_grid(
    height: int, width: int, n_angles: int, n_radii: int, min_radius: float
) -> tuple[NDArray[np.float32], NDArray[np.intp], FloatArray, FloatArray]:
    """For :func:`log_polar_spectrum`, made once per geometry (they cost as much as the FFT):
    the Hann window (height, width); for each sample (n_angles, n_radii) the flat indices
    (4, ...) of its four neighbouring bins in the half-spectrum (height, width // 2 + 1) as
    ``rfft2`` lays it out (the grid is placed in the spectrum shifted to put frequency 0 at row
    ``height // 2``, as ``np.fft.fftshift`` would) and their bilinear weights (4, ...); the
    radii (n_radii,)."""
    # A separable Hann window stops the image border from adding a bright cross to the spectrum.
    window = np.outer(np.hanning(height), np.hanning(width)).astype(np.float32)
    angles = -0.5 * np.pi + np.pi * np.arange(n_angles) / n_angles
    radii = np.geomspace(min_radius, 0.45 * min(height, width), n_radii)
    rows = height // 2 + np.outer(np.sin(angles), radii)
    cols = np.outer(np.cos(angles), radii)
    n_cols = width // 2 + 1
    row0, col0 = np.floor(rows).astype(np.intp), np.floor(cols).astype(np.intp)
    fr, fc = rows - row0, cols - col0
    corners, weights = [], []
    for dr, dc, weight in ((0, 0, (1 - fr) * (1 - fc)), (0, 1, (1 - fr) * fc),
                           (1, 0, fr * (1 - fc)), (1, 1, fr * fc)):
        # Clipped like map_coordinates' mode="nearest" (the grid stays inside anyway).
        r = np.clip(row0 + dr, 0, height - 1)
        c = np.clip(col0 + dc, 0, n_cols - 1)
        # row r of the shifted spectrum is row (r - height // 2) mod height of rfft2's
        corners.append((r - height // 2) % height * n_cols + c)
        weights.append(weight)
    grid = (window, np.stack(corners), np.stack(weights), radii)
    for array in grid:
        array.flags.writeable = False  # shared by every call
    return grid


def spectrum_rotation(
    polar_a: FloatArray | CentredSpectrum, polar_b: FloatArray | CentredSpectrum
) -> RotationEstimate:
    """Rotation of image ``b``'s content relative to image ``a``'s, modulo pi, from their
    :func:`log_polar_spectrum` grids (Fourier-Mellin without the scale axis, since the scale
    is fixed by the metres per pixel of both images).

    The angle is counter-clockwise in the (column, row) pixel frame and lies in
    ``[-pi/2, pi/2)``; the true rotation may also be ``angle + pi``. Either grid may be given
    as its :func:`centred_spectrum` (made once for a grid correlated with many).
    """
    shapes = [(p.length, *p.transform.shape[1:]) if isinstance(p, CentredSpectrum) else p.shape
              for p in (polar_a, polar_b)]
    if shapes[0] != shapes[1] or len(shapes[0]) != 2:
        raise EstimatorInputError(
            f"expected two log-polar grids of equal 2-D shape, got {shapes[0]}, {shapes[1]}"
        )
    n_angles = shapes[0][0]
    correlation = _circular_correlation(polar_a, polar_b)
    index, peak = _subbin_peak(correlation)
    # wrap_angle's and np.clip's operations on the floats, bit for bit
    angle = wrap_float(2.0 * np.pi * index / n_angles) / 2.0
    return RotationEstimate(angle, min(max(peak, 0.0), 1.0))


def _check_full_turn(beam_angles: FloatArray) -> None:
    steps = np.diff(np.unwrap(beam_angles))
    n = len(beam_angles)
    if not np.allclose(steps, 2.0 * np.pi / n, atol=1e-6):
        raise EstimatorInputError(
            f"range profile correlation needs {n} beams evenly spread over a full turn "
            f"(step {2 * np.pi / n:.6f} rad); got steps from {steps.min():.6f} to {steps.max():.6f}"
        )


def range_profile_rotation(
    ranges_a: ArrayLike, ranges_b: ArrayLike, beam_angles: ArrayLike, max_range: float
) -> RotationEstimate:
    """Heading change [rad] of the sensor from scan ``a`` to scan ``b`` by circular correlation
    of the range profiles (beams without a return count as ``max_range``).

    A sensor that turns by ``d`` sees at beam angle ``alpha`` what it saw before at
    ``alpha + d``. Translation distorts the profile, so this is a coarse estimate (good to a
    few beams for the small motions between consecutive scans) that has no pi ambiguity.
    """
    angles = np.asarray(beam_angles, dtype=np.float64)
    a = np.minimum(np.asarray(ranges_a, dtype=np.float64), max_range)
    b = np.minimum(np.asarray(ranges_b, dtype=np.float64), max_range)
    if a.shape != angles.shape or b.shape != angles.shape:
        raise EstimatorInputError(
            f"expected two range profiles of shape {angles.shape}, got {a.shape}, {b.shape}"
        )
    _check_full_turn(angles)
    # c[k] = sum_i b[i] a[i - k] peaks where b[i] = a[i + d/step], i.e. at k = -d/step.
    index, peak = _subbin_peak(_circular_correlation(a, b))
    step = 2.0 * np.pi / len(angles)
    return RotationEstimate(wrap_float(-index * step), min(max(peak, 0.0), 1.0))


def resolve_half_turn(angle_mod_pi: float, reference: float) -> float:
    """Of ``angle_mod_pi`` and ``angle_mod_pi + pi``, the one closer to ``reference`` [rad]."""
    # on floats: wrap_angle's operations bit for bit, the first candidate on a tie (argmin's)
    first, second = wrap_float(float(angle_mod_pi)), wrap_float(float(angle_mod_pi) + np.pi)
    reference = float(reference)
    return second if abs(wrap_float(second - reference)) < abs(wrap_float(first - reference)) \
        else first


def heading_change(
    polar_a: FloatArray | CentredSpectrum,
    polar_b: FloatArray | CentredSpectrum,
    reference: float | None = None,
    profiles: tuple[ArrayLike, ArrayLike, ArrayLike, float] | None = None,
) -> RotationEstimate:
    """Heading change [rad] of the sensor from scan ``a`` to ``b`` from the log-polar spectra
    of their sensor-frame images drawn as :mod:`estimators.paper.scan_image` draws them (sensor y
    pointing up the image, towards row 0).

    Of the two pi-apart candidates, the one closest to ``reference`` [rad] (e.g. a predicted
    heading change) is taken; else, given ``profiles = (ranges_a, ranges_b, beam_angles,
    max_range)`` of full-turn scans, the one closest to :func:`range_profile_rotation`; else
    the smaller turn. The confidence is the spectrum correlation's. The grids may be given as
    their :func:`centred_spectrum`.
    """
    content = spectrum_rotation(polar_a, polar_b)
    # The scene turns by minus the heading change; with rows pointing down (-y) the pixel-frame
    # angle is mirrored, which cancels that sign.
    if reference is None:
        reference = 0.0 if profiles is None else range_profile_rotation(*profiles).angle
    return RotationEstimate(resolve_half_turn(content.angle, reference), content.confidence)
