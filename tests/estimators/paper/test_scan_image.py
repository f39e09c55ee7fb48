"""Eq. 4 filter, eq. 5 image and the image geometry of ``estimators.paper.scan_image``."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimators.paper.phase_correlation import phase_correlate
from estimators.paper.scan_image import (
    check_image_geometry,
    pixel_shift_to_metres,
    points_to_image,
    scan_filter,
    scan_to_image,
)

ANGLES4 = np.array([0.0, 0.5, 1.0, 1.5]) * np.pi


def test_filter_matches_eq4_by_hand_with_wrap_around_neighbours() -> None:
    ranges = np.array([1.0, 2.0, 3.0, 4.0])
    rows = scan_filter(ranges, ANGLES4, max_range=10.0)
    # beam 0: neighbours are beam 3 (wrap) and beam 1
    np.testing.assert_allclose(rows[0], [1.0, 0.0, (16.0 - 4.0) / 2.0, 7.0 / 3.0], atol=1e-12)
    # beam 2 at 180 degrees: x = -3, neighbours 2 and 4
    np.testing.assert_allclose(rows[2], [-3.0, 0.0, (4.0 - 16.0) / 6.0, 3.0], atol=1e-12)
    np.testing.assert_allclose(rows[3, :2], [0.0, -4.0], atol=1e-12)


def test_filter_drops_no_returns_but_uses_them_as_max_range_neighbours() -> None:
    ranges = np.array([1.0, 10.0, 3.0, 12.0])  # beams 1 and 3 see nothing (>= max_range)
    rows = scan_filter(ranges, ANGLES4, max_range=10.0)
    assert len(rows) == 2
    np.testing.assert_allclose(rows[0, 2:], [(100.0 - 100.0) / 2.0, 7.0])
    np.testing.assert_allclose(rows[1, 2:], [(100.0 - 100.0) / 6.0, 23.0 / 3.0])


def test_single_point_lands_on_the_documented_pixel() -> None:
    angles = np.deg2rad(np.arange(360.0))
    ranges = np.full(360, 10.0)
    ranges[150] = 2.0  # point at (2 cos 150°, 2 sin 150°) = (-1.732, 1.0) m
    image = scan_to_image(ranges, angles, max_range=10.0)
    assert image.shape == (400, 400) and image.dtype == np.uint8
    rows, cols = np.nonzero(image)
    # col = floor(-1.732 / 0.05) + 200, row = 200 - 1 - floor(1.0 / 0.05) (y grows upwards)
    assert (rows.tolist(), cols.tolist()) == ([199 - 19], [-35 + 200])


def _pixel(range_m: float, degrees: float) -> tuple[int, int]:
    """(row, col) of a return at 0.05 m/px in a 400 px image, per the module docstring."""
    x, y = range_m * np.cos(np.deg2rad(degrees)), range_m * np.sin(np.deg2rad(degrees))
    return 199 - int(np.floor(y / 0.05)), int(np.floor(x / 0.05)) + 200


def test_near_and_corner_like_points_are_brighter() -> None:
    angles = np.deg2rad(np.arange(360.0))
    ranges = np.full(360, 10.0)
    ranges[0:20] = 2.0  # a near arc, its ends next to beams without return (depth jumps)
    ranges[180:200] = 8.0  # a far arc
    image = scan_to_image(ranges, angles, max_range=10.0)
    near, far, edge = image[_pixel(2.0, 10)], image[_pixel(8.0, 190)], image[_pixel(2.0, 0)]
    assert near > far > 0
    assert edge == 255 and edge > near


def test_image_is_zero_without_returns_and_points_outside_are_dropped() -> None:
    angles = np.deg2rad(np.arange(360.0))
    assert not scan_to_image(np.full(360, 10.0), angles, 10.0).any()
    image = points_to_image([[0.0, 0.0], [100.0, 0.0]], np.array([200, 200]), 8, 0.5)
    assert image.sum() == 200 and image[3, 4] == 200


def test_scene_translation_reads_back_in_metres() -> None:
    """A scene moved by (dx, dy) gives an image shift that converts back to (dx, dy)."""
    rng = np.random.default_rng(3)
    points = rng.uniform(-6, 6, (300, 2))
    values = np.full(300, 255)
    moved = points + [0.30, -0.45]
    shift = phase_correlate(points_to_image(points, values), points_to_image(moved, values)).shift
    np.testing.assert_allclose(pixel_shift_to_metres(shift, 0.05), [0.30, -0.45], atol=0.026)


def test_default_resolution_holds_max_range() -> None:
    assert check_image_geometry(400, None, 10.0) == pytest.approx(0.05)
    assert check_image_geometry(1500, None, 10.0) == pytest.approx(20.0 / 1500)
    assert check_image_geometry(400, 0.1, 10.0) == pytest.approx(0.1)


@pytest.mark.parametrize("size", [0, -4, 401, 400.0, True, "400"])
def test_bad_size_is_a_readable_error(size: object) -> None:
    with pytest.raises(ValueError, match="size: expected a positive even integer"):
        scan_to_image(np.full(360, 5.0), np.deg2rad(np.arange(360.0)), 10.0, size=size)


def test_resolution_that_cannot_hold_max_range_is_an_error() -> None:
    angles = np.deg2rad(np.arange(360.0))
    with pytest.raises(ValueError, match="cannot hold max_range 10.0 m"):
        scan_to_image(np.full(360, 5.0), angles, 10.0, size=400, resolution=0.04)
    with pytest.raises(ValueError, match="too coarse"):
        scan_to_image(np.full(360, 5.0), angles, 10.0, size=400, resolution=6.0)
    with pytest.raises(ValueError, match="resolution: expected a positive"):
        scan_to_image(np.full(360, 5.0), angles, 10.0, resolution=-1.0)


def test_bad_scans_are_readable_errors() -> None:
    angles = np.deg2rad(np.arange(360.0))
    with pytest.raises(ValueError, match="equal shape"):
        scan_to_image(np.full(359, 5.0), angles, 10.0)
    bad = np.full(360, 5.0)
    bad[7] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        scan_to_image(bad, angles, 10.0)
    bad[7] = np.inf
    with pytest.raises(ValueError, match="NaN, inf"):
        scan_filter(bad, angles, 10.0)
    with pytest.raises(ValueError, match="values: expected shape"):
        points_to_image([[0.0, 0.0]], np.array([1, 2]))
    with pytest.raises(ValueError, match=r"values: expected pixel values in \[0, 255\]"):
        points_to_image([[0.0, 0.0]], np.array([300]))


@settings(max_examples=150, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n_beams=st.integers(3, 800),
    half_size=st.integers(8, 120),
    full_turn=st.booleans(),
    turn=st.one_of(st.just(0.0), st.floats(-7.0, 7.0)),
    coarser=st.floats(1.0, 3.0),
)
def test_compiled_image_equals_the_array_form_pixel_for_pixel(
    seed: int, n_beams: int, half_size: int, full_turn: bool, turn: float, coarser: float
) -> None:
    """draw_scan against scan_filter + pixel_values + points_to_image: returns, no returns,
    zero ranges, returns outside the image, turned beams, any beam layout."""
    rng = np.random.default_rng(seed)
    max_range = float(rng.uniform(1.0, 30.0))
    ranges = rng.uniform(0.0, 1.3 * max_range, n_beams)
    ranges[rng.random(n_beams) < 0.1] = 0.0
    angles = (2 * np.pi * np.arange(n_beams) / n_beams if full_turn
              else np.sort(rng.uniform(-4.0, 4.0, n_beams)))
    size = 2 * half_size
    # coarser than the finest (None) by a margin over rounding, never too coarse
    resolution = None if coarser < 1.5 else min(2.0 * max_range / size * coarser, max_range / 2)
    compiled = scan_to_image(ranges, angles, max_range, size, resolution, turn)
    array_form = scan_to_image(ranges, angles, max_range, size, resolution, turn, compiled=False)
    np.testing.assert_array_equal(compiled, array_form)
