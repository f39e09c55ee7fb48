"""``phase_correlate`` (eqs. 6-9) against scikit-image and against known shifts."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.ndimage import fourier_shift, gaussian_filter
from skimage.registration import phase_cross_correlation

from estimators.paper.phase_correlation import image_spectrum, phase_correlate


def _shifted(image: np.ndarray, shift: np.ndarray) -> np.ndarray:
    """``image`` circularly shifted by ``shift`` [px] (subpixel through the Fourier domain)."""
    return np.fft.ifftn(fourier_shift(np.fft.fftn(image), shift)).real


@pytest.mark.parametrize("shape", [(64, 64), (63, 80), (400, 400)])
def test_agrees_with_skimage_on_random_images(shape: tuple[int, int]) -> None:
    rng = np.random.default_rng(sum(shape))
    for _ in range(5):
        reference = rng.random(shape)
        moving = _shifted(reference, rng.uniform(-15, 15, 2))
        ours = phase_correlate(reference, moving).shift
        oracle, _, _ = phase_cross_correlation(reference, moving, upsample_factor=100)
        # skimage returns the shift that registers moving onto reference: minus ours (eq. 6)
        np.testing.assert_allclose(ours, -oracle, atol=0.05)


def test_subpixel_shift_of_a_smooth_image_is_recovered() -> None:
    rng = np.random.default_rng(7)
    reference = gaussian_filter(rng.random((128, 128)), 2.0, mode="wrap")
    for true_shift in ([3.25, -7.6], [-0.5, 0.5], [10.9, 0.13]):
        result = phase_correlate(reference, _shifted(reference, np.array(true_shift)))
        np.testing.assert_allclose(result.shift, true_shift, atol=0.02)
        assert result.peak > 0.5


def test_integer_shifts_are_exact_and_wrap_past_half_the_image() -> None:
    rng = np.random.default_rng(1)
    image = rng.random((400, 400)).astype(np.float32)
    for roll, expected in (((3, -5), (3, -5)), ((300, 150), (-100, 150)), ((200, 0), (-200, 0))):
        moved = np.roll(image, roll, axis=(0, 1))
        for subpixel in (True, False):
            result = phase_correlate(image, moved, subpixel=subpixel)
            np.testing.assert_allclose(result.shift, expected, atol=1e-3)
            assert result.peak == pytest.approx(1.0, abs=1e-3)


def test_precomputed_spectra_give_the_same_answer() -> None:
    rng = np.random.default_rng(2)
    first, second = rng.random((2, 96, 96))
    second = _shifted(first, np.array([4.3, -2.2])) + 0.1 * second
    direct = phase_correlate(first, second)
    reused = phase_correlate(image_spectrum(first), image_spectrum(second))
    np.testing.assert_allclose(reused.shift, direct.shift)
    assert reused.confidence == pytest.approx(direct.confidence)


def test_confidence_separates_a_match_from_unrelated_images() -> None:
    rng = np.random.default_rng(4)
    image = rng.random((128, 128))
    noisy_copy = np.roll(image, (5, 9), axis=(0, 1)) + 0.5 * rng.random(image.shape)
    match = phase_correlate(image, noisy_copy)
    unrelated = phase_correlate(image, rng.random(image.shape))
    assert match.confidence > 5.0
    assert unrelated.confidence < 2.0


def test_bad_images_are_readable_errors() -> None:
    image = np.zeros((8, 8))
    with pytest.raises(ValueError, match=r"equal shapes, got \(8, 8\) and \(8, 6\)"):
        phase_correlate(image, np.zeros((8, 6)))
    with pytest.raises(ValueError, match="2-D array"):
        phase_correlate(np.zeros(8), np.zeros(8))
    bad = image.copy()
    bad[1, 1] = np.nan
    with pytest.raises(ValueError, match="finite"):
        image_spectrum(bad)
    with pytest.raises(ValueError, match="real numeric"):
        image_spectrum(image.astype(complex))


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), rows=st.integers(2, 48), cols=st.integers(2, 48),
       related=st.booleans())
def test_compiled_newton_and_runner_up_equal_the_python_ones(
    seed: int, rows: int, cols: int, related: bool
) -> None:
    """phase_correlate's compiled Newton iterations and runner-up search against the Python
    ones: the same shift, peak and confidence, bit for bit (related and unrelated images)."""
    rng = np.random.default_rng(seed)
    reference = rng.random((rows, cols))
    moving = (np.roll(reference, (int(rng.integers(-5, 6)), int(rng.integers(-5, 6))), (0, 1))
              + 0.3 * rng.random((rows, cols))) if related else rng.random((rows, cols))
    compiled = phase_correlate(reference, moving)
    python = phase_correlate(reference, moving, compiled=False)
    np.testing.assert_array_equal(compiled.shift, python.shift)
    assert (compiled.peak, compiled.confidence) == (python.peak, python.confidence)
