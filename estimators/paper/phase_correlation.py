"""Phase correlation of two images (the paper's eqs. 6-9) with an exact subpixel peak.

The paper registers two scan images by the Fourier shift theorem: if ``img2`` is ``img1``
shifted by ``(d_row, d_col)`` (eq. 6, periodic as in eq. 7) their spectra differ by a linear
phase (eq. 8), which the normalised cross-power spectrum isolates (eq. 9); its inverse
transform peaks at the shift.

Speed: each image's real FFT is whitened (divided by its magnitude) once, in
:func:`image_spectrum`, and can be reused for the next pair; the cross-power spectrum of two
whitened spectra is then a single product, because ``|F2 F1*| = |F2| |F1|``. A scan image
leaves most rows empty, whose row transforms are skipped; what follows the inverse transform
runs in one compiled call (:mod:`estimators.paper.phase_correlation_kernel`). The two FFTs of
a pair (one forward, one inverse, 400 x 400) are then about 60 % of its time, Newton's
refinement (about three Fourier-series passes over the cross spectrum) about 13 %.

Subpixel peak: the inverse transform of the cross-power spectrum, evaluated off the integer
grid by its Fourier series, is the band-limited interpolation of the correlation surface.
Guizar-Sicairos, Thurman & Fienup (2008, "Efficient subpixel image registration algorithms",
Opt. Lett. 33:156) sample it on a grid ``1/upsample_factor`` px fine around the peak with a
matrix DFT (``skimage.registration.phase_cross_correlation``). We instead maximise the same
surface with Newton's method, its gradient and Hessian also being Fourier series: the limit of
an infinitely fine upsampling, at the cost of three matrix-vector DFT rows per iteration.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.fft
from numpy.typing import ArrayLike, NDArray

from estimators.paper.phase_correlation_kernel import (
    cross_power,
    locate_peak,
    surface_derivatives,
    whiten,
    whitened_spectrum_of_rows,
)
from lidar_env.core import EstimatorInputError

#: Newton stops when its step is below this [px]: convergence is quadratic, so the position
#: is then good to ~1e-4 px, far under any accuracy we can claim.
NEWTON_TOLERANCE = 1e-2
NEWTON_MAX_ITERATIONS = 6
#: Half side [px] of the window around the peak excluded when looking for the runner-up peak:
#: a subpixel peak spreads over its neighbours, which are not a competing match.
PEAK_EXCLUSION_RADIUS = 2


@dataclass(frozen=True)
class ImageSpectrum:
    """The whitened real 2-D FFT ``F / |F|`` of one image (0 where ``F`` is 0).

    Attributes:
        whitened: ``(rows, cols // 2 + 1)`` complex64.
        shape: ``(rows, cols)`` of the image.
    """

    whitened: NDArray[np.complex64]
    shape: tuple[int, int]


@dataclass(frozen=True)
class PhaseCorrelation:
    """Result of :func:`phase_correlate`.

    Attributes:
        shift: ``(d_row, d_col)`` [px]: ``moving`` is ``reference`` shifted by this much
            (eq. 6), each component in ``[-n/2, n/2)`` (the periodic boundary of eq. 7).
        peak: correlation surface value at the peak, in ``[0, 1]``: the fraction of the
            spectrum that agrees on this shift (1 for an exact circular shift).
        confidence: ``peak`` over the highest value outside ``PEAK_EXCLUSION_RADIUS`` px of it:
            the peak height ratio; near 1 means an ambiguous match.
    """

    shift: NDArray[np.float64]
    peak: float
    confidence: float


def image_spectrum(image: ArrayLike, compiled: bool = True) -> ImageSpectrum:
    """Whiten the real FFT of a 2-D image once, for any number of :func:`phase_correlate` calls.

    ``compiled``: transform only the rows that hold a pixel
    (:func:`~estimators.paper.phase_correlation_kernel.whitened_spectrum_of_rows`) rather than
    all of them by ``scipy.fft.rfft2``, the same spectrum bit for bit."""
    image = np.asarray(image)
    if image.dtype == np.uint8 and image.ndim == 2 and min(image.shape) >= 2:  # a drawn scan
        return ImageSpectrum(
            whitened_spectrum_of_rows(image) if compiled else
            _whitened_rfft2(image.astype(np.float32)), (int(image.shape[0]), int(image.shape[1])))
    if image.ndim != 2 or min(image.shape) < 2:
        raise EstimatorInputError(
            f"image: expected a 2-D array of at least 2 x 2, got shape {image.shape}")
    if not np.issubdtype(image.dtype, np.number) or np.iscomplexobj(image):
        raise EstimatorInputError(f"image: expected a real numeric array, got dtype {image.dtype}")
    pixels = image.astype(np.float32, copy=False)
    # integer pixels (a drawn scan) are finite: the check is for float images
    if image.dtype.kind in "fc" and not np.all(np.isfinite(pixels)):
        raise EstimatorInputError("image: expected finite pixel values, got NaN or inf")
    spectrum = whitened_spectrum_of_rows(pixels) if compiled else _whitened_rfft2(pixels)
    return ImageSpectrum(spectrum, (int(image.shape[0]), int(image.shape[1])))


def _whitened_rfft2(pixels: NDArray[np.float32]) -> NDArray[np.complex64]:
    spectrum = scipy.fft.rfft2(pixels, workers=1)
    whiten(spectrum)
    return spectrum


def _as_spectrum(image: ArrayLike | ImageSpectrum, compiled: bool) -> ImageSpectrum:
    return image if isinstance(image, ImageSpectrum) else image_spectrum(image, compiled)


def _parabola_vertex(below: float, centre: float, above: float) -> float:
    """Offset [px] of the vertex of the parabola through three equally spaced samples."""
    curvature = below - 2.0 * centre + above
    return 0.0 if curvature >= 0 else min(0.5, max(-0.5, 0.5 * (below - above) / curvature))


def _refine_peak(
    cross: NDArray[np.complex64], shape: tuple[int, int], start: NDArray[np.float64]
) -> tuple[NDArray[np.float64], float | None]:
    """Newton's method on the Fourier-interpolated correlation surface from ``start`` [px].

    Returns the refined position and the surface value there (None if Newton found no
    concave peak within 1 px of ``start``, which is then returned unchanged).
    """
    rows, cols = shape
    position = start.copy()
    value = None
    for _ in range(NEWTON_MAX_ITERATIONS):
        # moments[i, j] = sum over the spectrum of d^i/drow^i d^j/dcol^j of the series
        moments = surface_derivatives(cross, position[0], position[1], cols)
        (value_here, d_col, d_col2), (d_row, d_row_col, _), (d_row2, _, _) = moments
        determinant = d_row2 * d_col2 - d_row_col**2
        if d_row2 >= 0 or determinant <= 0:  # not a concave peak: Newton would not climb
            break
        # the 2 x 2 Newton step -H^-1 g in closed form
        step = np.array(
            [d_row_col * d_col - d_col2 * d_row, d_row_col * d_row - d_row2 * d_col]
        ) / determinant
        if np.any(np.abs(position + step - start) > 1.0):
            break
        position = position + step
        value = float(value_here)
        if np.max(np.abs(step)) < NEWTON_TOLERANCE:
            break
    if value is None:
        return start, None
    return position, value


def phase_correlate(
    reference: ArrayLike | ImageSpectrum,
    moving: ArrayLike | ImageSpectrum,
    subpixel: bool = True,
    compiled: bool = True,
) -> PhaseCorrelation:
    """Shift of ``moving`` relative to ``reference`` by phase correlation (eqs. 6-9).

    Args:
        reference, moving: equal-shape 2-D real images, or their :func:`image_spectrum`
            (pass spectra to transform each image only once over a sequence).
        subpixel: refine the integer peak to the exact maximum of the Fourier-interpolated
            surface (Newton's method, see the module docstring), started from a parabola
            through the peak's neighbours, whose vertex is kept if Newton finds no concave
            peak within 1 px of it.
        compiled: everything after the inverse transform in one numba call
            (:func:`~estimators.paper.phase_correlation_kernel.locate_peak`) rather than in
            Python and numpy, and images transformed by
            :func:`image_spectrum`'s compiled form; the same numbers bit for bit.

    Returns:
        :class:`PhaseCorrelation`; ``shift`` is ``(d_row, d_col)`` [px] such that
        ``moving(r, c) = reference(r - d_row, c - d_col)`` (eq. 6). This is minus the
        ``shift`` of ``skimage.registration.phase_cross_correlation(reference, moving)``.

    Example:
        >>> image = np.random.default_rng(0).random((64, 64))
        >>> phase_correlate(image, np.roll(image, (3, -5), axis=(0, 1))).shift.round(3)
        array([ 3., -5.])
    """
    first, second = _as_spectrum(reference, compiled), _as_spectrum(moving, compiled)
    if first.shape != second.shape:
        raise EstimatorInputError(
            f"reference and moving: expected equal shapes, got {first.shape} and {second.shape}"
        )
    shape = first.shape
    cross = cross_power(first.whitened, second.whitened)  # eq. 9
    surface = scipy.fft.irfft2(cross, s=shape, workers=1)  # eq. 8 inverted
    if compiled:
        peak_row, peak_col = divmod(int(np.argmax(surface)), shape[1])
        d_row, d_col, peak = locate_peak(
            cross, surface, peak_row, peak_col, subpixel, NEWTON_TOLERANCE,
            NEWTON_MAX_ITERATIONS, PEAK_EXCLUSION_RADIUS)
        runner_up = float(surface.max())
        confidence = peak / runner_up if runner_up > 0 else np.inf
        return PhaseCorrelation(np.array([d_row, d_col]), peak, float(confidence))
    flat_peak = int(np.argmax(surface))
    peak_index = np.array(np.unravel_index(flat_peak, shape))
    peak = float(surface.flat[flat_peak])
    sizes = np.array(shape)
    shift = np.where(peak_index >= sizes / 2, peak_index - sizes, peak_index).astype(np.float64)
    if subpixel:
        # Newton starts from a parabola through the peak and its neighbours along each axis:
        # from the integer peak, half a pixel off, the surface may not be concave yet.
        row, col = peak_index
        shift += [
            _parabola_vertex(surface[row - 1, col], peak, surface[(row + 1) % shape[0], col]),
            _parabola_vertex(surface[row, col - 1], peak, surface[row, (col + 1) % shape[1]]),
        ]
        shift, refined_peak = _refine_peak(cross, shape, shift)
        peak = refined_peak if refined_peak is not None else peak
    runner_up = _runner_up(surface, peak_index)
    confidence = peak / runner_up if runner_up > 0 else np.inf
    return PhaseCorrelation(shift, peak, float(confidence))


def _runner_up(surface: NDArray[np.floating], peak_index: NDArray[np.int64]) -> float:
    """Highest surface value more than ``PEAK_EXCLUSION_RADIUS`` px (periodically) from the peak.

    Overwrites the peak's neighbourhood in ``surface``.
    """
    offsets = np.arange(-PEAK_EXCLUSION_RADIUS, PEAK_EXCLUSION_RADIUS + 1)
    rows = (peak_index[0] + offsets) % surface.shape[0]
    cols = (peak_index[1] + offsets) % surface.shape[1]
    surface[np.ix_(rows, cols)] = -np.inf
    return float(surface.max())
