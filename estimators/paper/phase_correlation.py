"""Phase correlation of two images (the paper's eqs. 6-9) with an exact subpixel peak.

The paper registers two scan images by the Fourier shift theorem: if ``img2`` is ``img1``
shifted by ``(d_row, d_col)`` (eq. 6, periodic as in eq. 7) their spectra differ by a linear
phase (eq. 8), which the normalised cross-power spectrum isolates (eq. 9); its inverse
transform peaks at the shift.

Speed: each image's real FFT is whitened (divided by its magnitude) once, in
:func:`image_spectrum`, and can be reused for the next pair; the cross-power spectrum of two
whitened spectra is then a single product, because ``|F2 F1*| = |F2| |F1|``.

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

import numba
import numpy as np
import scipy.fft
from numpy.typing import ArrayLike, NDArray

from lidar_env.errors import EstimatorInputError

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


def image_spectrum(image: ArrayLike) -> ImageSpectrum:
    """Whiten the real FFT of a 2-D image once, for any number of :func:`phase_correlate` calls."""
    image = np.asarray(image)
    if image.ndim != 2 or min(image.shape) < 2:
        raise EstimatorInputError(
            f"image: expected a 2-D array of at least 2 x 2, got shape {image.shape}")
    if not np.issubdtype(image.dtype, np.number) or np.iscomplexobj(image):
        raise EstimatorInputError(f"image: expected a real numeric array, got dtype {image.dtype}")
    pixels = image.astype(np.float32, copy=False)
    # integer pixels (a drawn scan) are finite: the check is for float images
    if image.dtype.kind in "fc" and not np.all(np.isfinite(pixels)):
        raise EstimatorInputError("image: expected finite pixel values, got NaN or inf")
    spectrum = scipy.fft.rfft2(pixels, workers=1)
    _whiten(spectrum)
    return ImageSpectrum(spectrum, (int(image.shape[0]), int(image.shape[1])))


def _as_spectrum(image: ArrayLike | ImageSpectrum) -> ImageSpectrum:
    return image if isinstance(image, ImageSpectrum) else image_spectrum(image)


@numba.njit(cache=True, nogil=True)
def _axis_kernel(n: int, x: float, half: bool) -> NDArray[np.complex128]:
    """``(3, k)`` inverse-DFT kernel of one axis of length ``n`` at position ``x`` [px] and its
    first two derivatives in ``x``. ``half``: the axis holds only the non-negative frequencies
    of a real signal (rfft), so frequencies ``0 < f < n/2`` stand for their mirror too and
    weigh 2. The Nyquist frequency of an even ``n`` enters as ``cos(pi x)``, the mean of
    ``+-n/2``, which keeps the interpolated surface real and symmetric.
    """
    length = n // 2 + 1 if half else n
    kernel = np.empty((3, length), dtype=np.complex128)
    for index in range(length):
        frequency = index if (half or index < (n + 1) // 2) else index - n
        if n % 2 == 0 and abs(frequency) == n // 2:
            c, s = np.cos(np.pi * x), np.sin(np.pi * x)
            kernel[0, index] = c
            kernel[1, index] = -np.pi * s
            kernel[2, index] = -np.pi * np.pi * c
            continue
        omega = 2.0 * np.pi * frequency / n
        phase = np.exp(1j * omega * x)
        weight = 2.0 if (half and frequency > 0) else 1.0
        kernel[0, index] = weight * phase
        kernel[1, index] = weight * 1j * omega * phase
        kernel[2, index] = -weight * omega * omega * phase
    return kernel


@numba.njit(cache=True, nogil=True)
def _surface_derivatives(
    cross: NDArray[np.complex64], row: float, col: float, cols: int
) -> NDArray[np.float64]:
    """``m[i, j]``: the correlation surface's ``d^i/drow^i d^j/dcol^j`` at ``(row, col)`` [px],
    from its half spectrum ``cross`` (rows, cols // 2 + 1) by direct Fourier series.

    A loop rather than ``kernel @ cross``: BLAS's thread pool stalls badly on a busy machine
    (20x slower with 2 shared cores)."""
    rows = cross.shape[0]
    row_kernel = _axis_kernel(rows, row, False)
    col_kernel = _axis_kernel(cols, col, True)
    # partial = row_kernel @ cross in real arithmetic, (a + bi)(c + di) = ac - bd + (ad + bc)i
    # as numba's complex product computes it, which the compiler can vectorise
    partial_real = np.zeros((3, cross.shape[1]))
    partial_imag = np.zeros((3, cross.shape[1]))
    for r in range(rows):
        for i in range(3):
            weight_real, weight_imag = row_kernel[i, r].real, row_kernel[i, r].imag
            for k in range(cross.shape[1]):
                value_real = np.float64(cross[r, k].real)
                value_imag = np.float64(cross[r, k].imag)
                partial_real[i, k] += weight_real * value_real - weight_imag * value_imag
                partial_imag[i, k] += weight_real * value_imag + weight_imag * value_real
    derivatives = np.zeros((3, 3))
    for i in range(3):
        for j in range(3 - i):
            total = 0.0
            for k in range(cross.shape[1]):
                total += (partial_real[i, k] * col_kernel[j, k].real
                          - partial_imag[i, k] * col_kernel[j, k].imag)
            derivatives[i, j] = total / (rows * cols)
    return derivatives


@numba.njit(cache=True, nogil=True)
def _whiten(spectrum: NDArray[np.complex64]) -> None:
    """``F / |F|`` in place, 0 where ``F`` is 0 (eq. 9's normalisation, one factor)."""
    flat = spectrum.ravel()
    for index in range(flat.size):
        value = flat[index]
        squared = value.real * value.real + value.imag * value.imag
        scale = np.float32(1.0) / np.sqrt(squared) if squared > 0 else np.float32(0.0)
        flat[index] = value * scale


@numba.njit(cache=True, nogil=True)
def _cross_power(reference: NDArray, moving: NDArray) -> NDArray[np.complex64]:
    """``moving * conj(reference)`` of two whitened spectra: eq. 9's normalised cross power."""
    out = np.empty_like(moving)
    for r in range(moving.shape[0]):
        for k in range(moving.shape[1]):
            out[r, k] = moving[r, k] * np.conj(reference[r, k])
    return out


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
        moments = _surface_derivatives(cross, position[0], position[1], cols)
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


@numba.njit(cache=True, nogil=True)
def _refine_peak_compiled(
    cross: NDArray[np.complex64], cols: int, start: NDArray[np.float64], tolerance: float,
    max_iterations: int,
) -> tuple[NDArray[np.float64], bool, float]:  # pragma: no cover (numba)
    """:func:`_refine_peak`'s iterations in one call: (position, whether Newton found a
    concave peak, the surface value there)."""
    position = start.copy()
    found, value = False, 0.0
    for _ in range(max_iterations):
        moments = _surface_derivatives(cross, position[0], position[1], cols)
        value_here, d_col, d_col2 = moments[0, 0], moments[0, 1], moments[0, 2]
        d_row, d_row_col, d_row2 = moments[1, 0], moments[1, 1], moments[2, 0]
        determinant = d_row2 * d_col2 - d_row_col * d_row_col
        if d_row2 >= 0 or determinant <= 0:
            break
        step_row = (d_row_col * d_col - d_col2 * d_row) / determinant
        step_col = (d_row_col * d_row - d_row2 * d_col) / determinant
        if (abs(position[0] + step_row - start[0]) > 1.0
                or abs(position[1] + step_col - start[1]) > 1.0):
            break
        position[0] += step_row
        position[1] += step_col
        found, value = True, value_here
        if max(abs(step_row), abs(step_col)) < tolerance:
            break
    return (position, found, value) if found else (start.copy(), False, 0.0)


@numba.njit(cache=True, nogil=True)
def _runner_up_compiled(
    surface: NDArray[np.float32], peak_row: int, peak_col: int, radius: int
) -> float:  # pragma: no cover (numba)
    """:func:`_runner_up` without overwriting ``surface``: the highest value more than
    ``radius`` px (periodically) from the peak (-inf if none)."""
    rows, cols = surface.shape
    best = -np.inf
    for r in range(rows):
        row_gap = abs(r - peak_row)
        near_row = min(row_gap, rows - row_gap) <= radius
        for c in range(cols):
            if near_row:
                col_gap = abs(c - peak_col)
                if min(col_gap, cols - col_gap) <= radius:
                    continue
            if surface[r, c] > best:
                best = surface[r, c]
    return best


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
        compiled: Newton's iterations and the runner-up search in numba
            (:func:`_refine_peak_compiled`, :func:`_runner_up_compiled`) rather than in Python
            and numpy, the same numbers.

    Returns:
        :class:`PhaseCorrelation`; ``shift`` is ``(d_row, d_col)`` [px] such that
        ``moving(r, c) = reference(r - d_row, c - d_col)`` (eq. 6). This is minus the
        ``shift`` of ``skimage.registration.phase_cross_correlation(reference, moving)``.

    Example:
        >>> image = np.random.default_rng(0).random((64, 64))
        >>> phase_correlate(image, np.roll(image, (3, -5), axis=(0, 1))).shift.round(3)
        array([ 3., -5.])
    """
    first, second = _as_spectrum(reference), _as_spectrum(moving)
    if first.shape != second.shape:
        raise EstimatorInputError(
            f"reference and moving: expected equal shapes, got {first.shape} and {second.shape}"
        )
    shape = first.shape
    cross = _cross_power(first.whitened, second.whitened)  # eq. 9
    surface = scipy.fft.irfft2(cross, s=shape, workers=1)  # eq. 8 inverted
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
        if compiled:
            shift, found, refined = _refine_peak_compiled(
                cross, shape[1], shift, NEWTON_TOLERANCE, NEWTON_MAX_ITERATIONS)
            peak = float(refined) if found else peak
        else:
            shift, refined_peak = _refine_peak(cross, shape, shift)
            peak = refined_peak if refined_peak is not None else peak
    if compiled:
        runner_up = float(_runner_up_compiled(surface, int(peak_index[0]), int(peak_index[1]),
                                              PEAK_EXCLUSION_RADIUS))
    else:
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
