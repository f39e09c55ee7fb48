"""Greyscale map images (``lidar_env.world.grey_image``): 16-bit PGM (P2 and P5) and PNG scaled
by their maxval so their walls survive, and PGM headers that lie or files that end early named
as MapErrors."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from PIL import Image

from lidar_env.core.errors import MapError
from lidar_env.world.grey_image import read_grey_image
from lidar_env.world.ros_map import read_ros_map


def pgm(samples: np.ndarray, maxval: int, plain: bool = False) -> bytes:
    height, width = samples.shape
    header = f"P{2 if plain else 5}\n# a comment\n{width} {height}\n{maxval}\n".encode()
    if plain:
        return header + " ".join(map(str, samples.ravel())).encode() + b"\n"
    return header + samples.astype(">u2" if maxval > 255 else "u1").tobytes()


def sixteen_bit_map(maxval: int) -> tuple[np.ndarray, np.ndarray]:
    """Samples of a maxval map (free at maxval, a dark-grey wall, unknown grey) and the cells
    map_server gives them: p = (maxval - v) / maxval, occupied > 0.65, free < 0.196."""
    samples = np.full((6, 8), maxval, dtype=np.int64)
    samples[2, 1:7] = maxval // 10  # p = 0.9: a wall
    samples[4, :] = maxval // 2  # p = 0.5: unknown
    cells = np.zeros(samples.shape, dtype=np.int8)
    cells[2, 1:7] = 100
    cells[4, :] = -1
    return samples, cells


@pytest.mark.parametrize("maxval", [1023, 4095, 65535])
@pytest.mark.parametrize("plain", [False, True])
def test_16_bit_pgm_maps_keep_their_walls(tmp_path, maxval: int, plain: bool) -> None:
    samples, cells = sixteen_bit_map(maxval)
    (tmp_path / "m.pgm").write_bytes(pgm(samples, maxval, plain))
    (tmp_path / "m.yaml").write_text("image: m.pgm\nresolution: 0.05\n")
    np.testing.assert_array_equal(read_ros_map(tmp_path / "m.yaml").cells, cells)


def test_16_bit_png_maps_keep_their_walls(tmp_path) -> None:
    samples, cells = sixteen_bit_map(65535)
    Image.fromarray(samples.astype(np.uint16)).save(tmp_path / "m.png")
    (tmp_path / "m.yaml").write_text("image: m.png\nresolution: 0.05\n")
    np.testing.assert_array_equal(read_ros_map(tmp_path / "m.yaml").cells, cells)


@given(samples=st.lists(st.integers(0, 255), min_size=12, max_size=12),
       plain=st.booleans())
def test_8_bit_pgm_reads_as_pillow_reads_it(tmp_path_factory, samples, plain) -> None:
    path = tmp_path_factory.mktemp("pgm") / "m.pgm"
    array = np.array(samples).reshape(3, 4)
    path.write_bytes(pgm(array, 255, plain))
    with Image.open(path) as image:
        expected = np.asarray(image.convert("L"), dtype=np.float64)
    np.testing.assert_array_equal(read_grey_image(path), expected)


BAD_PGM = {
    "truncated raw": (b"P5\n4 4\n255\n" + bytes(10), "expected 16 samples of 1 byte"),
    "truncated 16-bit": (b"P5\n4 4\n1023\n" + bytes(20), "expected 16 samples of 2 byte"),
    "truncated plain": (b"P2\n2 2\n255\n1 2 3\n", "expected 4 decimal samples"),
    "a word in plain": (b"P2\n2 2\n255\n1 2 x 4\n", "expected 4 decimal samples"),
    "no maxval": (b"P5\n4 4\n", "expected the maxval"),
    "maxval 0": (b"P5\n1 1\n0\n\x00", "maxval in 1 .. 65535"),
    "maxval 70000": (b"P5\n1 1\n70000\n\x00\x00", "maxval in 1 .. 65535"),
    "sample above maxval": (b"P5\n2 1\n100\n\x05\xc8", "samples <= maxval 100, got 200"),
    "a lying size": (b"P5\n100000 100000\n255\n" + bytes(16), "at most 4000000 pixels"),
    "zero width": (b"P5\n0 3\n255\n", "at least 1 x 1 pixels"),
    "a huge number": (b"P5\n" + b"9" * 5000 + b" 3\n255\n", "expected the width"),
    "no space after maxval": (b"P5\n1 1\n255", "one whitespace byte after the maxval"),
}


@pytest.mark.parametrize("case", list(BAD_PGM))
def test_a_pgm_whose_header_lies_or_which_ends_early_is_named(tmp_path, case: str) -> None:
    data, message = BAD_PGM[case]
    (tmp_path / "m.pgm").write_bytes(data)
    (tmp_path / "m.yaml").write_text("image: m.pgm\nresolution: 0.05\n")
    with pytest.raises(MapError, match=message) as caught:
        read_ros_map(tmp_path / "m.yaml")
    assert "m.pgm" in str(caught.value)


def test_a_truncated_png_is_named(tmp_path) -> None:
    Image.fromarray(np.arange(10000, dtype=np.uint8).reshape(100, 100)).save(tmp_path / "m.png")
    data = (tmp_path / "m.png").read_bytes()
    (tmp_path / "m.png").write_bytes(data[: len(data) // 2])
    with pytest.raises(MapError, match="m.png: expected a readable image file"):
        read_grey_image(tmp_path / "m.png")


def test_a_missing_file_is_left_to_the_caller(tmp_path) -> None:
    with pytest.raises(FileNotFoundError):
        read_grey_image(tmp_path / "none.pgm")
