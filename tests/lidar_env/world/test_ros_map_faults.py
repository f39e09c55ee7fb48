"""Hostile ROS maps: YAML aliases, numbers YAML 1.1 reads as strings, numbers too large for a
float, text that is not UTF-8, NUL bytes in the image name, and the writer's round trip over
any origin and resolution."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from PIL import Image

from lidar_env.core.errors import QUOTE_LIMIT, MapError, quoted
from lidar_env.world.ros_map import read_ros_map, save_ros_map
from lidar_env.world.world import World

#: "billion laughs": each level repeats the one before 9 times; ``origin`` expands to 3 * 9**7
#: numbers (a 60 MB repr) from under 300 bytes.
LAUGHS = "a: &a [1,1,1,1,1,1,1,1,1]\n" + "".join(
    f"{b}: &{b} [{', '.join([f'*{a}'] * 9)}]\n" for a, b in zip("abcdef", "bcdefg", strict=True)
) + "origin: [*g, *g, *g]\n"


def write_yaml(tmp_path, text: str | bytes, pixels: np.ndarray | None = None):
    Image.fromarray(np.full((6, 6), 254, np.uint8) if pixels is None else pixels).save(
        tmp_path / "m.pgm")
    path = tmp_path / "m.yaml"
    if isinstance(text, str):
        path.write_text(text)
    else:
        path.write_bytes(text)
    return path


def test_yaml_aliases_are_refused_before_they_expand(tmp_path) -> None:
    path = write_yaml(tmp_path, f"image: m.pgm\nresolution: 0.05\n{LAUGHS}")
    with pytest.raises(MapError, match=r"m.yaml: .*alias \*'a'.*no YAML aliases") as caught:
        read_ros_map(path)
    assert len(str(caught.value)) < 600


def test_quoting_a_value_is_bounded_whatever_it_holds() -> None:
    level: list = [1] * 9
    for _ in range(9):  # 9**10 numbers by reference
        level = [level] * 9
    assert len(quoted(level)) <= QUOTE_LIMIT
    assert quoted(10**5000) == "<int of 5001 digits>"
    assert "..." in quoted("x" * 10**6) and len(quoted("x" * 10**6)) <= QUOTE_LIMIT
    assert quoted([0.5, "a"]) == "[0.5, 'a']"


@pytest.mark.parametrize("text", ["5e-2", "'0.05'", "5.0e-2", "0.05", "1e-1"])
def test_numbers_yaml_reads_as_strings_are_numbers(tmp_path, text: str) -> None:
    path = write_yaml(tmp_path, f"image: m.pgm\nresolution: {text}\norigin: [1e-05, '2', 0]\n")
    ros = read_ros_map(path)
    assert ros.resolution == float(text.strip("'"))
    assert ros.origin == (1e-05, 2.0, 0.0)


@pytest.mark.parametrize(("line", "message"), [
    ("resolution: " + "1" * 401, "resolution: expected a finite number, got 1111"),
    ("resolution: " + "1" * 5000, "expected map_server YAML, got a parse error: Exceeds"),
    ("resolution: 1.0e+400", "resolution: expected a finite number, got inf"),
    ("resolution: nan", "resolution: expected a finite number, got 'nan'"),
    ("resolution: 'x' \norigin: [0, 0, 0]", "resolution: expected a finite number, got 'x'"),
    ("resolution: 0.05\norigin: ['1e999', 0, 0]", "origin: expected a finite number"),
])
def test_numbers_beyond_a_float_are_named(tmp_path, line: str, message: str) -> None:
    with pytest.raises(MapError, match=message):
        read_ros_map(write_yaml(tmp_path, f"image: m.pgm\n{line}\n"))


def test_a_pixel_size_that_puts_the_map_beyond_any_world_is_named(tmp_path) -> None:
    path = write_yaml(tmp_path, "image: m.pgm\nresolution: 1.0e+300\n")
    with pytest.raises(MapError, match=r"resolution: 1e\+300 m/px .* expected a world within"):
        World.from_ros_map(path)
    with pytest.raises(MapError, match="resolution: expected a positive pixel size"):
        World.from_image(np.zeros((3, 3)), 10**400)


@pytest.mark.parametrize(("data", "message"), [
    (b"image: m.pgm\nresolution: 0.05\n# caf\xe9\n", "expected UTF-8 text, got byte 0xe9 at"),
    (b'image: "m\\0.pgm"\nresolution: 0.05\n', r"image: expected a file name .*'m\\x00.pgm'"),
    (b"image: [m.pgm]\nresolution: 0.05\n", r"image: expected a file name .*\['m.pgm'\]"),
    (b"image: m.pgm\nresolution: 0.05\n" + b"#" * (1 << 20), "at most 1048576 bytes"),
    (b"image: m.pgm\nresolution: 0.05\n\xef\xbb\xbf", "parse error"),
])
def test_bytes_that_are_not_a_map_yaml_are_named(tmp_path, data: bytes, message: str) -> None:
    with pytest.raises(MapError, match=message):
        read_ros_map(write_yaml(tmp_path, data))


def test_a_yaml_with_a_byte_order_mark_reads(tmp_path) -> None:
    path = write_yaml(tmp_path, b"\xef\xbb\xbfimage: m.pgm\nresolution: 0.05\n")
    assert read_ros_map(path).resolution == 0.05


finite = st.floats(allow_nan=False, allow_infinity=False)


@settings(max_examples=60, deadline=None)
@given(resolution=st.floats(1e-4, 10.0) | st.sampled_from([1e-05, 5e-2, 1e-3]),
       x=st.floats(-1e5, 1e5) | st.sampled_from([1e-05, -1e-300, 5e-324]),
       y=st.floats(-1e5, 1e5), yaw=st.floats(-math.pi, math.pi) | st.just(1e-05))
def test_saved_maps_read_back_exactly(tmp_path_factory, resolution, x, y, yaw) -> None:
    folder = tmp_path_factory.mktemp("map")
    grid = np.zeros((4, 5))
    grid[1, 2] = 1.0
    path, _ = save_ros_map(folder / "m.yaml", grid, resolution, origin=(x, y, yaw))
    ros = read_ros_map(path)
    assert ros.resolution == resolution and ros.origin == (x, y, yaw)
    world = World.from_ros_map(ros)
    assert np.all(np.isfinite(world.bounds))


@pytest.mark.parametrize("origin", [(0, 0), (0, 0, "x"), (math.inf, 0, 0), "abc"])
def test_the_writer_names_a_bad_origin(tmp_path, origin) -> None:
    with pytest.raises(MapError, match="origin: expected"):
        save_ros_map(tmp_path / "m.yaml", np.zeros((2, 2)), 0.05, origin=origin)
