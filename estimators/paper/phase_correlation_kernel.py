"""The compiled parts of :mod:`estimators.paper.phase_correlation` (numba, ``cache=True``).

* :func:`real_spectrum`: ``rfft2`` of an image whose empty rows are skipped
  (a scan image leaves more than half of them empty), the same numbers bit for bit: the 2-D
  transform is a row transform then a column transform, and a row of zeros transforms to zeros;
  :func:`whitened_spectrum_of_rows` whitens it in place (:func:`whiten`).
* :func:`locate_peak`: what follows the inverse transform and numpy's ``argmax``, in one call:
  the parabola start and Newton's refinement (:func:`refine_peak`) on the Fourier series of
  the surface, then the peak's neighbourhood masked for the runner-up. It keeps the Python
  form's arithmetic, including the parabola's single precision (numpy computes it on the
  surface's float32 values), so it gives the same numbers bit for bit
  (``tests/estimators/paper/test_phase_correlation.py``).
"""

from __future__ import annotations

import numba
import numpy as np
import scipy.fft
from numpy.typing import NDArray

#: :func:`uint8_rows`' "no window".
NO_WINDOW = np.empty((0, 0), dtype=np.float32)


@numba.njit(cache=True, nogil=True)
def _occupied_rows(bits: NDArray[np.uint32]) -> NDArray[np.int64]:  # pragma: no cover (numba)
    """Indices of the rows of an image, given as its float32 bits, that hold a set bit (a
    pixel other than +0.0)."""
    rows = np.empty(bits.shape[0], dtype=np.int64)
    count = 0
    for r in range(bits.shape[0]):
        union = np.uint32(0)
        for c in range(bits.shape[1]):
            union |= bits[r, c]
        if union != 0:
            rows[count] = r
            count += 1
    return rows[:count]


@numba.njit(cache=True, nogil=True)
def _scatter_rows(
    transformed: NDArray[np.complex64], rows: NDArray[np.int64], n_rows: int
) -> NDArray[np.complex64]:  # pragma: no cover (numba)
    """A zero ``(n_rows, cols)`` array with ``transformed``'s rows placed at ``rows``."""
    out = np.empty((n_rows, transformed.shape[1]), dtype=np.complex64)
    below = 0  # rows before this one that are still to be zeroed
    for index in range(len(rows)):
        out[below:rows[index]] = 0
        out[rows[index]] = transformed[index]
        below = rows[index] + 1
    out[below:] = 0
    return out


@numba.njit(cache=True, nogil=True)
def uint8_rows(
    image: NDArray[np.uint8], window: NDArray[np.float32]
) -> tuple[NDArray[np.int64], NDArray[np.float32]]:  # pragma: no cover (numba)
    """The rows of a uint8 ``image`` that hold a pixel, and those rows as float32 (times
    ``window``, as numpy multiplies them, unless ``window`` is empty): what
    :func:`real_spectrum_of_rows` transforms, without converting the whole image first."""
    n_rows, cols = image.shape
    rows = np.empty(n_rows, dtype=np.int64)
    count = 0
    for r in range(n_rows):
        union = np.uint8(0)
        for c in range(cols):
            union |= image[r, c]
        if union != 0:
            rows[count] = r
            count += 1
    compact = np.empty((count, cols), dtype=np.float32)
    for index in range(count):
        r = rows[index]
        if window.size:
            for c in range(cols):
                compact[index, c] = np.float32(image[r, c]) * window[r, c]
        else:
            for c in range(cols):
                compact[index, c] = np.float32(image[r, c])
    return rows[:count], compact


def real_spectrum_of_rows(
    rows: NDArray[np.int64], compact: NDArray[np.float32], n_rows: int
) -> NDArray[np.complex64]:
    """``scipy.fft.rfft2`` of the ``(n_rows, cols)`` float32 image that is zero but for the
    rows ``rows``, which hold ``compact`` (len(rows), cols), bit for bit."""
    if len(rows) == n_rows:
        return scipy.fft.rfft2(compact, workers=1)
    half = scipy.fft.rfft(compact, axis=1, workers=1)
    return scipy.fft.fft(_scatter_rows(half, rows, n_rows), axis=0, overwrite_x=True, workers=1)


def real_spectrum(pixels: NDArray[np.float32]) -> NDArray[np.complex64]:
    """``scipy.fft.rfft2(pixels, workers=1)`` of a float32 image, bit for bit, with its
    all-zero rows (all bits zero, so -0.0 counts as a pixel) left out of the row transforms."""
    rows = _occupied_rows(pixels.view(np.uint32))
    return real_spectrum_of_rows(rows, pixels[rows], pixels.shape[0])


def whitened_spectrum_of_rows(pixels: NDArray[np.float32 | np.uint8]) -> NDArray[np.complex64]:
    """``whiten(scipy.fft.rfft2(pixels.astype(np.float32), workers=1))`` of a float32 or uint8
    image (a drawn scan), bit for bit (:func:`real_spectrum`)."""
    if pixels.dtype == np.uint8:
        rows, compact = uint8_rows(pixels, NO_WINDOW)
        spectrum = real_spectrum_of_rows(rows, compact, pixels.shape[0])
    else:
        spectrum = real_spectrum(pixels)
    whiten(spectrum)
    return spectrum


@numba.njit(cache=True, nogil=True)
def whiten(spectrum: NDArray[np.complex64]) -> None:  # pragma: no cover (numba)
    """``F / |F|`` in place, 0 where ``F`` is 0 (eq. 9's normalisation, one factor)."""
    flat = spectrum.ravel()
    for index in range(flat.size):
        value = flat[index]
        squared = value.real * value.real + value.imag * value.imag
        scale = np.float32(1.0) / np.sqrt(squared) if squared > 0 else np.float32(0.0)
        flat[index] = value * scale


@numba.njit(cache=True, nogil=True)
def cross_power(reference: NDArray, moving: NDArray) -> NDArray[np.complex64]:  # pragma: no cover
    """``moving * conj(reference)`` of two whitened spectra: eq. 9's normalised cross power."""
    out = np.empty_like(moving)
    for r in range(moving.shape[0]):
        for k in range(moving.shape[1]):
            out[r, k] = moving[r, k] * np.conj(reference[r, k])
    return out


@numba.njit(cache=True, nogil=True)
def axis_kernel(n: int, x: float, half: bool) -> NDArray[np.complex128]:  # pragma: no cover
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
def surface_derivatives(
    cross: NDArray[np.complex64], row: float, col: float, cols: int
) -> NDArray[np.float64]:  # pragma: no cover (numba)
    """``m[i, j]``: the correlation surface's ``d^i/drow^i d^j/dcol^j`` at ``(row, col)`` [px],
    from its half spectrum ``cross`` (rows, cols // 2 + 1) by direct Fourier series.

    A loop rather than ``kernel @ cross``: BLAS's thread pool stalls badly on a busy machine
    (20x slower with 2 shared cores). The three row kernels share one pass over ``cross``;
    each partial sum still adds its terms in row order."""
    rows = cross.shape[0]
    row_kernel = axis_kernel(rows, row, False)
    col_kernel = axis_kernel(cols, col, True)
    # partial = row_kernel @ cross in real arithmetic, (a + bi)(c + di) = ac - bd + (ad + bc)i
    # as numba's complex product computes it, which the compiler can vectorise
    width = cross.shape[1]
    partial_real = np.zeros((3, width))
    partial_imag = np.zeros((3, width))
    for r in range(rows):
        w0r, w0i = row_kernel[0, r].real, row_kernel[0, r].imag
        w1r, w1i = row_kernel[1, r].real, row_kernel[1, r].imag
        w2r, w2i = row_kernel[2, r].real, row_kernel[2, r].imag
        for k in range(width):
            value_real = np.float64(cross[r, k].real)
            value_imag = np.float64(cross[r, k].imag)
            partial_real[0, k] += w0r * value_real - w0i * value_imag
            partial_imag[0, k] += w0r * value_imag + w0i * value_real
            partial_real[1, k] += w1r * value_real - w1i * value_imag
            partial_imag[1, k] += w1r * value_imag + w1i * value_real
            partial_real[2, k] += w2r * value_real - w2i * value_imag
            partial_imag[2, k] += w2r * value_imag + w2i * value_real
    derivatives = np.zeros((3, 3))
    for i in range(3):
        for j in range(3 - i):
            total = 0.0
            for k in range(width):
                total += (partial_real[i, k] * col_kernel[j, k].real
                          - partial_imag[i, k] * col_kernel[j, k].imag)
            derivatives[i, j] = total / (rows * cols)
    return derivatives


@numba.njit(cache=True, nogil=True)
def refine_peak(
    cross: NDArray[np.complex64], cols: int, start: NDArray[np.float64], tolerance: float,
    max_iterations: int,
) -> tuple[NDArray[np.float64], bool, float]:  # pragma: no cover (numba)
    """``phase_correlation._refine_peak``'s Newton iterations in one call: (position, whether
    Newton found a concave peak, the surface value there)."""
    position = start.copy()
    found, value = False, 0.0
    for _ in range(max_iterations):
        moments = surface_derivatives(cross, position[0], position[1], cols)
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
def _parabola_vertex32(
    below: np.float32, centre: np.float32, above: np.float32
) -> np.float32:  # pragma: no cover (numba)
    """``phase_correlation._parabola_vertex`` on float32 samples, in float32 as numpy does it
    (the Python constants are cast to float32 first)."""
    curvature = below - np.float32(2.0) * centre + above
    if curvature >= 0:
        return np.float32(0.0)
    offset = np.float32(0.5) * (below - above) / curvature
    return min(np.float32(0.5), max(np.float32(-0.5), offset))


@numba.njit(cache=True, nogil=True)
def locate_peak(
    cross: NDArray[np.complex64], surface: NDArray[np.float32], peak_row: int, peak_col: int,
    subpixel: bool, tolerance: float, max_iterations: int, radius: int,
) -> tuple[float, float, float]:  # pragma: no cover (numba)
    """``(d_row, d_col, peak)`` of a correlation ``surface`` (rows, cols) with its maximum at
    ``(peak_row, peak_col)`` and its half spectrum ``cross``: ``phase_correlate``'s answer
    (see there) before the confidence. Then overwrites the ``radius`` px around the peak
    (periodically) with -inf, so ``surface.max()`` is the runner-up (numpy's reduction is
    vectorised; a loop here is not)."""
    rows, cols = surface.shape
    peak = surface[peak_row, peak_col]
    shift = np.empty(2)
    shift[0] = peak_row - rows if peak_row >= rows / 2 else peak_row
    shift[1] = peak_col - cols if peak_col >= cols / 2 else peak_col
    value = np.float64(peak)
    if subpixel:
        above, below = (peak_row - 1) % rows, (peak_row + 1) % rows
        left, right = (peak_col - 1) % cols, (peak_col + 1) % cols
        shift[0] += np.float64(_parabola_vertex32(
            surface[above, peak_col], peak, surface[below, peak_col]))
        shift[1] += np.float64(_parabola_vertex32(
            surface[peak_row, left], peak, surface[peak_row, right]))
        shift, found, refined = refine_peak(cross, cols, shift, tolerance, max_iterations)
        if found:
            value = refined
    for dr in range(-radius, radius + 1):
        for dc in range(-radius, radius + 1):
            surface[(peak_row + dr) % rows, (peak_col + dc) % cols] = -np.inf
    return shift[0], shift[1], value
