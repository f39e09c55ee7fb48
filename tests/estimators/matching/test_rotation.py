"""Heading change between two scans: Fourier-Mellin on the eq.-5 images, range-profile
correlation, and their combination. Oracle: scans cast from known sensor poses."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimators.matching.rotation import (
    heading_change,
    log_polar_spectrum,
    range_profile_rotation,
    resolve_half_turn,
    spectrum_rotation,
)
from estimators.paper.scan_image import scan_to_image
from lidar_env.core.se2 import wrap_angle
from lidar_env.sensors.lidar import Lidar
from lidar_env.world.world import World

ANGLES = 2.0 * np.pi * np.arange(360) / 360
MAX_RANGE = 10.0


def cluttered_room(rng: np.random.Generator) -> World:
    """A 16 m square room with a dozen cylinders kept off its centre."""
    walls = [[-8, -8, 8, -8], [8, -8, 8, 8], [8, 8, -8, 8], [-8, 8, -8, -8]]
    centres = rng.uniform(-7, 7, (40, 2))
    centres = centres[np.hypot(*centres.T) > 3.0][:12]
    circles = np.column_stack([centres, rng.uniform(0.15, 0.5, len(centres))])
    return World(circles, walls)


def scan_pair(rng: np.random.Generator, turn: float, shift: float):
    """Two noisy scans from sensor poses ``turn`` [rad] and ``shift`` [m] apart."""
    world = cluttered_room(rng)
    first = np.array([*rng.uniform(-1, 1, 2), rng.uniform(-np.pi, np.pi)])
    direction = rng.uniform(-np.pi, np.pi)
    second = first + [shift * np.cos(direction), shift * np.sin(direction), turn]
    ranges = Lidar(noise_std=0.01).scan(world, np.stack([first, second]), rng)
    return ranges[0].astype(np.float64), ranges[1].astype(np.float64)


def spectra(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return (
        log_polar_spectrum(scan_to_image(a, ANGLES, MAX_RANGE)),
        log_polar_spectrum(scan_to_image(b, ANGLES, MAX_RANGE)),
    )


def test_heading_change_of_real_scans_is_found_to_a_fraction_of_a_beam() -> None:
    rng = np.random.default_rng(11)
    errors = []
    for _ in range(12):
        turn = rng.uniform(-0.5, 0.5)
        a, b = scan_pair(rng, turn, shift=rng.uniform(0.0, 0.3))
        polar_a, polar_b = spectra(a, b)
        estimate = heading_change(polar_a, polar_b, profiles=(a, b, ANGLES, MAX_RANGE))
        errors.append(wrap_angle(estimate.angle - turn))
        assert 0.0 < estimate.confidence <= 1.0
    errors = np.degrees(np.abs(errors))
    # 1 beam = 1 degree; the spectrum ignores the shift, so the error stays sub-beam.
    assert np.median(errors) < 0.25
    assert errors.max() < 1.0


def test_spectrum_is_blind_to_translation() -> None:
    rng = np.random.default_rng(3)
    a, b = scan_pair(rng, turn=0.0, shift=0.4)
    assert abs(spectrum_rotation(*spectra(a, b)).angle) < np.radians(0.5)


def test_spectrum_rotation_agrees_with_an_image_rotated_by_scipy() -> None:
    from scipy import ndimage

    rng = np.random.default_rng(5)
    a, _ = scan_pair(rng, 0.0, 0.0)
    image = scan_to_image(a, ANGLES, MAX_RANGE).astype(np.float64)
    angle = 17.0  # [deg], scipy turns the picture counter-clockwise as displayed (rows down)
    turned = ndimage.rotate(image, angle, reshape=False, order=1)
    estimate = spectrum_rotation(log_polar_spectrum(image), log_polar_spectrum(turned))
    # counter-clockwise on screen is clockwise in the (column, row) frame
    assert np.degrees(estimate.angle) == pytest.approx(-angle, abs=0.3)


def test_large_turns_need_the_profile_to_choose_between_pi_apart_candidates() -> None:
    rng = np.random.default_rng(8)
    turn = 2.6  # beyond +-pi/2: the spectrum alone cannot tell it from turn - pi
    a, b = scan_pair(rng, turn, shift=0.1)
    polar_a, polar_b = spectra(a, b)
    with_profile = heading_change(polar_a, polar_b, profiles=(a, b, ANGLES, MAX_RANGE))
    assert abs(wrap_angle(with_profile.angle - turn)) < np.radians(1.0)
    smaller_turn = heading_change(polar_a, polar_b)
    assert abs(wrap_angle(smaller_turn.angle - turn + np.pi)) < np.radians(1.0)
    hinted = heading_change(polar_a, polar_b, reference=2.5)
    assert hinted.angle == pytest.approx(with_profile.angle)


def test_range_profile_rotation_of_a_shifted_profile_is_exact() -> None:
    # A sensor turned by k beams sees at beam i what it saw at beam i + k.
    profile = 3.0 + np.sin(ANGLES) + 0.5 * np.cos(3 * ANGLES) + 0.2 * np.sin(7 * ANGLES)
    turned = np.roll(profile, -7)
    estimate = range_profile_rotation(profile, turned, ANGLES, MAX_RANGE)
    assert np.degrees(estimate.angle) == pytest.approx(7.0, abs=1e-9)
    assert estimate.confidence == pytest.approx(1.0)
    # between beams: sample the same smooth profile 0.4 beam further on
    shifted = (
        3.0 + np.sin(ANGLES + 0.4 * np.pi / 180) + 0.5 * np.cos(3 * (ANGLES + 0.4 * np.pi / 180))
    )
    smooth = 3.0 + np.sin(ANGLES) + 0.5 * np.cos(3 * ANGLES)
    estimate = range_profile_rotation(smooth, shifted, ANGLES, MAX_RANGE)
    assert np.degrees(estimate.angle) == pytest.approx(0.4, abs=0.05)


def test_resolve_half_turn_picks_the_candidate_nearest_the_reference() -> None:
    assert resolve_half_turn(0.1, 0.0) == pytest.approx(0.1)
    assert resolve_half_turn(0.1, 3.0) == pytest.approx(wrap_angle(0.1 + np.pi))
    assert resolve_half_turn(-0.2, -2.9) == pytest.approx(wrap_angle(-0.2 + np.pi))


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: log_polar_spectrum(np.zeros((8, 8))), "at least 16x16"),
        (lambda: log_polar_spectrum(np.zeros((64, 64)), n_angles=4), "n_angles >= 8"),
        (lambda: log_polar_spectrum(np.zeros((64, 64)), min_radius=40.0), "min_radius"),
        (lambda: spectrum_rotation(np.zeros((36, 8)), np.zeros((36, 9))), "equal 2-D shape"),
        (
            lambda: range_profile_rotation(np.ones(180), np.ones(180), ANGLES[:180], MAX_RANGE),
            "full turn",
        ),
        (lambda: range_profile_rotation(np.ones(360), np.ones(10), ANGLES, MAX_RANGE), "shape"),
    ],
)
def test_bad_input_raises_readable_errors(call, message) -> None:
    with pytest.raises(ValueError, match=message):
        call()


def test_log_polar_spectrum_samples_the_magnitude_like_scipy_map_coordinates() -> None:
    # Oracle: the windowed magnitude spectrum sampled bilinearly by scipy.ndimage at the
    # documented grid (directions -pi/2 + pi k / n, radii geometric from min_radius).
    from scipy import ndimage
    from scipy.fft import rfft2

    rng = np.random.default_rng(3)
    for shape, n_angles, n_radii in (((200, 200), 180, 32), ((64, 100), 90, 16)):
        image = (rng.random(shape) > 0.97).astype(np.uint8)
        height, width = shape
        window = np.outer(np.hanning(height), np.hanning(width))
        magnitude = np.abs(np.fft.fftshift(rfft2(image * window), axes=0))
        angles = -0.5 * np.pi + np.pi * np.arange(n_angles) / n_angles
        radii = np.geomspace(4.0, 0.45 * min(shape), n_radii)
        rows = height // 2 + np.outer(np.sin(angles), radii)
        cols = np.outer(np.cos(angles), radii)
        expected = np.log1p(ndimage.map_coordinates(magnitude, [rows, cols], order=1) * radii)
        np.testing.assert_allclose(
            log_polar_spectrum(image, n_angles, n_radii), expected, rtol=1e-5, atol=1e-5
        )


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), height=st.integers(16, 120), width=st.integers(16, 120),
       n_angles=st.integers(8, 200), n_radii=st.integers(2, 50), drawn=st.booleans(),
       empty_rows=st.floats(0.0, 1.0))
def test_compiled_log_polar_sampling_equals_the_einsum_form(
    seed: int, height: int, width: int, n_angles: int, n_radii: int, drawn: bool,
    empty_rows: float,
) -> None:
    """log_polar_spectrum's numba windowing, row-skipping transform and sampling against its
    numpy, rfft2 and np.einsum form, bit for bit, on sparse uint8 images (a drawn scan) and
    dense float ones, with a share ``empty_rows`` of their rows empty, any shape and grid."""
    rng = np.random.default_rng(seed)
    sparse = (rng.random((height, width)) < 0.05) * rng.integers(0, 256, (height, width))
    image = sparse.astype(np.uint8) if drawn else rng.random((height, width))
    image[rng.random(height) < empty_rows] = 0
    np.testing.assert_array_equal(
        log_polar_spectrum(image, n_angles, n_radii),
        log_polar_spectrum(image, n_angles, n_radii, compiled=False),
    )
