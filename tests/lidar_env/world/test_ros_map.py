"""ROS map_server maps (``lidar_env.world.ros_map``): the YAML keys honoured (negate, thresholds,
mode, origin with yaw), unknown cells as obstacles, readable errors for bad files, and the
round trip grid -> PGM + YAML -> World -> scan checked against pymunk's ray queries."""

import math

import numpy as np
import pytest
from PIL import Image

from lidar_env.core.errors import MapError
from lidar_env.sensors.lidar import cast_rays, pymunk_cast_rays
from lidar_env.world.ros_map import read_ros_map, save_ros_map
from lidar_env.world.world import World

RES = 0.05


def map_pixels() -> np.ndarray:
    """80 x 120 px: a 5 px unknown border (205), free inside (254), a 20 x 20 px block (0)
    whose top-left pixel is at row 20, column 70."""
    pixels = np.full((80, 120), 205, dtype=np.uint8)
    pixels[5:-5, 5:-5] = 254
    pixels[20:40, 70:90] = 0
    return pixels


def write_map(tmp_path, pixels=None, **keys):
    Image.fromarray(map_pixels() if pixels is None else pixels).save(tmp_path / "m.pgm")
    meta = {"image": "m.pgm", "resolution": RES, "origin": [0.0, 0.0, 0.0], "negate": 0,
            "occupied_thresh": 0.65, "free_thresh": 0.196, **keys}
    text = "".join(f"{k}: {v}\n" for k, v in meta.items() if v is not None)
    (tmp_path / "m.yaml").write_text(text)
    return tmp_path / "m.yaml"


def centre(row: float, col: float, height: int = 80) -> tuple[float, float]:
    """World (x, y) [m] of pixel (row, col) for an unrotated map at origin (0, 0)."""
    return ((col + 0.5) * RES, (height - row - 0.5) * RES)


def test_free_occupied_and_unknown_cells_land_where_the_image_says(tmp_path):
    ros = read_ros_map(write_map(tmp_path))
    assert np.mean(ros.cells == 0) == pytest.approx(70 * 110 / (80 * 120) - 400 / 9600)
    world = World.from_ros_map(tmp_path / "m.yaml")
    inside_block, free, border = centre(30, 80), centre(60, 20), centre(2, 60)
    assert world.contains(np.array([inside_block, free, border])).tolist() == [True, False, True]
    assert world.bounds == pytest.approx((0.0, 0.0, 120 * RES, 80 * RES))
    open_border = World.from_ros_map(tmp_path / "m.yaml", unknown_is_obstacle=False)
    assert open_border.contains(np.array([border, inside_block])).tolist() == [False, True]


def test_negate_thresholds_and_scale_mode(tmp_path):
    negated = 255 - map_pixels()
    ros = read_ros_map(write_map(tmp_path, negated, negate=1))
    np.testing.assert_array_equal(ros.cells, read_ros_map(write_map(tmp_path)).cells)
    grey = np.full((10, 10), 254, dtype=np.uint8)
    grey[:, :5] = 100  # p = 0.61: unknown in trinary mode, occupied (>= 0.5) in scale mode
    assert np.all(read_ros_map(write_map(tmp_path, grey)).cells[:, :5] == -1)
    assert np.all(read_ros_map(write_map(tmp_path, grey, mode="scale")).cells[:, :5] == 100)
    assert np.all(read_ros_map(write_map(tmp_path, grey, occupied_thresh=0.5)).cells[:, :5] == 100)


def test_origin_yaw_rotates_the_map_about_its_origin(tmp_path):
    yaw = math.pi / 2
    world = World.from_ros_map(write_map(tmp_path, origin=[1.0, 2.0, yaw]))
    x, y = centre(30, 80)  # inside the block in the map's own frame
    c, s = math.cos(yaw), math.sin(yaw)
    block = (1.0 + c * x - s * y, 2.0 + s * x + c * y)
    x, y = centre(60, 20)
    free = (1.0 + c * x - s * y, 2.0 + s * x + c * y)
    assert world.contains(np.array([block, free])).tolist() == [True, False]
    assert world.bounds == pytest.approx((1.0 - 80 * RES, 2.0, 1.0, 2.0 + 120 * RES))
    tilted = World.from_ros_map(write_map(tmp_path, origin=[0.0, 0.0, 0.3]))
    xmin, ymin, xmax, ymax = tilted.bounds
    # a bounding-box corner is outside the rotated image: solid, not free space
    assert tilted.contains(np.array([[xmin + 0.05, ymin + 0.05], [xmax - 0.05, ymax - 0.05]])).all()


@pytest.mark.parametrize(
    ("keys", "message"),
    [
        ({"image": None}, r"m.yaml: expected a 'image' key"),
        ({"resolution": None}, r"m.yaml: expected a 'resolution' key"),
        ({"image": "missing.pgm"}, r"m.yaml: image: no such file .*missing.pgm"),
        ({"resolution": -0.05}, r"resolution: expected a positive pixel size"),
        ({"occupied_thresh": 1.5}, r"occupied_thresh: expected a probability in \[0, 1\]"),
        ({"free_thresh": -0.1}, r"free_thresh: expected a probability in \[0, 1\]"),
        ({"mode": "raw"}, r"mode: expected one of trinary, scale, got 'raw'"),
        ({"origin": "[0, 0]"}, r"origin: expected \[x, y, yaw\]"),
    ],
)
def test_bad_map_files_raise_map_errors_naming_the_file_and_key(tmp_path, keys, message):
    with pytest.raises(MapError, match=message):
        World.from_ros_map(write_map(tmp_path, **keys))


def test_missing_yaml_is_a_map_error(tmp_path):
    with pytest.raises(MapError, match="no such map YAML"):
        World.from_ros_map(tmp_path / "none.yaml")


def test_round_trip_grid_to_ros_map_to_world_to_scan(tmp_path):
    rng = np.random.default_rng(3)
    probabilities = np.full((60, 90), 0.1)
    probabilities[:, :3] = probabilities[:, -3:] = probabilities[:3] = probabilities[-3:] = 0.9
    probabilities[25:35, 40:50] = 0.95
    probabilities[45:50, 10:20] = np.nan  # never seen: unknown, an obstacle when read back
    probabilities[10:12, 60:80] = 0.5  # undecided: unknown too
    yaml_path, image_path = save_ros_map(tmp_path / "grid.yaml", probabilities, RES, (-1.0, 2.0, 0))
    assert image_path.exists() and image_path.suffix == ".pgm"
    ros = read_ros_map(yaml_path)
    expected = np.where(probabilities > 0.65, 100, np.where(probabilities < 0.196, 0, -1))
    np.testing.assert_array_equal(ros.cells, expected)
    world = World.from_ros_map(yaml_path)
    rows, cols = np.mgrid[0:60, 0:90]
    centres = np.stack([-1.0 + (cols.ravel() + 0.5) * RES,
                        2.0 + (60 - rows.ravel() - 0.5) * RES], axis=1)
    np.testing.assert_array_equal(world.contains(centres), (expected != 0).ravel())
    space = world.build_space()
    angles = np.linspace(-math.pi, math.pi, 200, endpoint=False)
    free = centres[(expected == 0).ravel()]
    poses = np.column_stack([free[rng.choice(len(free), 5)], rng.uniform(-3, 3, 5)])
    np.testing.assert_allclose(cast_rays(world, poses, angles, 6.0),
                               pymunk_cast_rays(space, poses, angles, 6.0), atol=1e-6)



def test_world_from_ros_map_takes_a_ros_map_read_before(tmp_path):
    yaml_path = write_map(tmp_path, origin=[1.0, 2.0, 0.3])
    for unknown in (True, False):
        read_first = World.from_ros_map(read_ros_map(yaml_path), unknown_is_obstacle=unknown)
        direct = World.from_ros_map(yaml_path, unknown_is_obstacle=unknown)
        assert read_first.bounds == direct.bounds
        np.testing.assert_array_equal(read_first.segments, direct.segments)
    assert not np.array_equal(World.from_ros_map(yaml_path).segments,
                              World.from_ros_map(yaml_path, unknown_is_obstacle=False).segments)
