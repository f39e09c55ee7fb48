"""The compiled parts of phase correlation against the array forms they replace."""

from __future__ import annotations

import numpy as np
import scipy.fft
from hypothesis import given, settings
from hypothesis import strategies as st

from estimators.paper.phase_correlation import image_spectrum, phase_correlate
from estimators.paper.phase_correlation_kernel import (
    axis_kernel,
    surface_derivatives,
    whiten,
    whitened_spectrum_of_rows,
)


def _sparse_image(rng: np.random.Generator, rows: int, cols: int, pixels: int) -> np.ndarray:
    image = np.zeros((rows, cols), dtype=np.float32)
    image[rng.integers(0, rows, pixels), rng.integers(0, cols, pixels)] = rng.integers(
        64, 256, pixels)
    return image


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), rows=st.integers(2, 64), cols=st.integers(2, 64),
       pixels=st.integers(0, 80), negative_zero=st.booleans())
def test_spectrum_of_occupied_rows_equals_rfft2_bit_for_bit(
    seed: int, rows: int, cols: int, pixels: int, negative_zero: bool
) -> None:
    """Rows left out of the row transforms change nothing, even a row of -0.0 pixels; float32
    and uint8 images."""
    rng = np.random.default_rng(seed)
    image = _sparse_image(rng, rows, cols, pixels)
    if negative_zero:
        image[int(rng.integers(0, rows))] = -0.0
    expected = scipy.fft.rfft2(image, workers=1)
    whiten(expected)
    np.testing.assert_array_equal(whitened_spectrum_of_rows(image), expected)
    np.testing.assert_array_equal(image_spectrum(image).whitened,
                                  image_spectrum(image, compiled=False).whitened)
    drawn = np.abs(image).astype(np.uint8)  # a drawn scan's uint8 image, its own rows
    expected = scipy.fft.rfft2(drawn.astype(np.float32), workers=1)
    whiten(expected)
    np.testing.assert_array_equal(whitened_spectrum_of_rows(drawn), expected)
    np.testing.assert_array_equal(image_spectrum(drawn).whitened,
                                  image_spectrum(drawn, compiled=False).whitened)


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), rows=st.integers(2, 40), cols=st.integers(2, 40),
       row=st.floats(-20, 20), col=st.floats(-20, 20))
def test_surface_derivatives_equal_the_matrix_form(
    seed: int, rows: int, cols: int, row: float, col: float
) -> None:
    """The loop's Fourier-series derivatives against ``row_kernel @ cross @ col_kernel.T``."""
    rng = np.random.default_rng(seed)
    cross = (rng.standard_normal((rows, cols // 2 + 1))
             + 1j * rng.standard_normal((rows, cols // 2 + 1))).astype(np.complex64)
    matrix = (axis_kernel(rows, row, False) @ cross.astype(np.complex128)
              @ axis_kernel(cols, col, True).T).real / (rows * cols)
    derivatives = surface_derivatives(cross, row, col, cols)
    for i in range(3):
        for j in range(3 - i):
            np.testing.assert_allclose(derivatives[i, j], matrix[i, j], rtol=1e-9, atol=1e-9)


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), size=st.sampled_from([16, 32, 48, 64]),
       subpixel=st.booleans())
def test_compiled_phase_correlation_of_scan_like_images_equals_the_python_one(
    seed: int, size: int, subpixel: bool
) -> None:
    """Sparse images (empty rows, ties of zeros on the surface's flanks) through both forms."""
    rng = np.random.default_rng(seed)
    reference = _sparse_image(rng, size, size, size)
    moving = np.roll(reference, (int(rng.integers(-4, 5)), int(rng.integers(-4, 5))), (0, 1))
    moving = moving + _sparse_image(rng, size, size, size // 4)
    compiled = phase_correlate(reference, moving, subpixel)
    python = phase_correlate(reference, moving, subpixel, compiled=False)
    np.testing.assert_array_equal(compiled.shift, python.shift)
    assert (compiled.peak, compiled.confidence) == (python.peak, python.confidence)
