"""Fuzz: ROS map files (YAML values, PGM headers and rasters, raw bytes) and the batched env's
seeds and sizes: a named project error or a correct result."""

from __future__ import annotations

import numpy as np
from hypothesis import example, given, settings
from hypothesis import strategies as st

from lidar_env.world.ros_map import read_ros_map
from lidar_env.world.world import World
from tests.fuzz.conftest import named_or_result, scaled

yaml_values = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr), st.integers().map(str),
    st.sampled_from(["5e-2", "1e-05", "1.0e+300", "1" * 401, "'0.1'", "[]", "{}", "*a", "&a 1",
                     "!!python/object:os.system x", "null", "yes", "~", "'\\0'", "\"m\\0.pgm\""]),
    st.text(max_size=12).map(repr))
keys = st.sampled_from(["image", "resolution", "origin", "negate", "occupied_thresh",
                        "free_thresh", "mode"])


def write_pgm(folder, data: bytes) -> None:
    (folder / "m.pgm").write_bytes(data)


@settings(max_examples=scaled(40))
@example(key="origin", value="[&a 1, *a, *a]")
@example(key="resolution", value="1.0e+300")
@given(key=keys, value=yaml_values)
def test_map_yaml_values_are_named_or_read(tmp_path_factory, key, value) -> None:
    folder = tmp_path_factory.mktemp("map")
    write_pgm(folder, b"P5\n4 3\n255\n" + bytes([0, 254, 254, 205] * 3))
    meta = {"image": "m.pgm", "resolution": "0.05", key: value}
    (folder / "m.yaml").write_text("".join(f"{k}: {v}\n" for k, v in meta.items()))
    world = named_or_result(lambda: World.from_ros_map(folder / "m.yaml"))
    if world is not None:
        assert np.all(np.isfinite(world.bounds))


header_numbers = st.one_of(st.integers(-1, 70000).map(str), st.sampled_from(["", "x", "9" * 30]))


@settings(max_examples=scaled(60))
@example(magic=b"P5", width="100000", height="100000", maxval="255", raster=b"\x00" * 8)
@given(magic=st.sampled_from([b"P2", b"P5", b"P6", b"P1"]), width=header_numbers,
       height=header_numbers, maxval=header_numbers, raster=st.binary(max_size=64))
def test_pgm_headers_and_rasters_are_named_or_read(tmp_path_factory, magic, width, height,
                                                   maxval, raster) -> None:
    folder = tmp_path_factory.mktemp("pgm")
    write_pgm(folder, magic + f"\n{width} {height}\n{maxval}\n".encode() + raster)
    (folder / "m.yaml").write_text("image: m.pgm\nresolution: 0.1\n")
    ros = named_or_result(lambda: read_ros_map(folder / "m.yaml"))
    if ros is not None:
        assert ros.cells.shape == (int(height), int(width))
        assert set(np.unique(ros.cells)) <= {-1, 0, 100}


@settings(max_examples=scaled(40))
@given(data=st.binary(max_size=200))
def test_any_bytes_as_a_map_yaml_are_named_or_read(tmp_path_factory, data) -> None:
    folder = tmp_path_factory.mktemp("bytes")
    write_pgm(folder, b"P5\n2 2\n255\n\x00\xfe\xfe\xfe")
    (folder / "m.yaml").write_bytes(data)
    named_or_result(lambda: read_ros_map(folder / "m.yaml"))


@settings(max_examples=scaled(8))
@example(seed=-1, num_envs=2)
@example(seed=0, num_envs=10**20)
@given(seed=st.one_of(st.integers(-(2**70), 2**70), st.none(), st.just("7"),
                      st.lists(st.one_of(st.integers(-3, 3), st.none()), max_size=3)),
       num_envs=st.one_of(st.integers(-2, 3), st.just(10**20)))
def test_vector_env_seeds_and_sizes_are_named_or_reset(seed, num_envs) -> None:
    from lidar_env.vector import DualLidarVectorEnv

    env = named_or_result(lambda: DualLidarVectorEnv(num_envs, world="hallway"))
    if env is None:
        return
    result = named_or_result(lambda: env.reset(seed=seed))
    if result is not None:
        assert np.all(np.isfinite(result[1]["pose"]))
