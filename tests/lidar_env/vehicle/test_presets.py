"""Robot presets: each matches the spec table of docs/robots.md, overrides apply over it, the
default car is unchanged, and what depends on the body scales with it."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from lidar_env.config import EnvConfig
from lidar_env.core.errors import ConfigError
from lidar_env.vehicle.presets import ROBOT_NAMES, ROBOTS

DOCS = Path(__file__).resolve().parents[3] / "docs" / "robots.md"


def spec_table() -> dict[str, dict[str, str]]:
    """The rows of the preset table in docs/robots.md, by preset name."""
    lines = [line for line in DOCS.read_text().splitlines() if line.startswith("| ")]
    header = [cell.strip() for cell in lines[0].strip("|").split("|")]
    rows = {}
    for line in lines[1:]:
        cells = [cell.strip() for cell in line.strip("|").split("|")]
        if cells[0].startswith("`"):
            rows[cells[0].strip("`")] = dict(zip(header, cells, strict=True))
    return rows


def test_every_preset_has_a_row_in_the_docs_and_matches_it() -> None:
    table = spec_table()
    assert set(table) == set(ROBOT_NAMES)
    for name, row in table.items():
        config = EnvConfig.from_dict({"robot": name})
        assert config.car_length == float(row["length [m]"])
        assert config.car_width == float(row["width [m]"])
        assert config.max_speed == float(row["max speed [m/s]"])
        assert config.max_yaw_rate == float(row["max yaw rate [rad/s]"])
        assert config.control_dt == pytest.approx(1.0 / float(row["scan rate [Hz]"]))
        for lidar in config.lidars:
            assert lidar.n_beams == int(row["beams"])
            assert math.degrees(lidar.fov) == pytest.approx(float(row["field of view [deg]"]))
            assert lidar.min_range == float(row["min range [m]"])
            assert lidar.max_range == float(row["max range [m]"])
            assert lidar.range_noise_std == float(row["noise [m]"])
        # the collision checks stay a few centimetres of travel apart
        assert config.max_speed * config.control_dt / config.physics_substeps <= 0.042


def test_the_paper_car_preset_is_the_default_config() -> None:
    assert EnvConfig.from_dict({"robot": "paper_car"}) == EnvConfig()
    assert EnvConfig().trace_margin == 0.3 and EnvConfig().body_scale == 1.0


def test_any_key_overrides_the_preset_and_replace_applies_a_new_one() -> None:
    config = EnvConfig.from_dict({"robot": "turtlebot3_burger", "max_speed": 0.1})
    assert config.max_speed == 0.1 and config.max_yaw_rate == 2.84
    assert config.car_length == 0.138 and config.n_lidars == 1
    waffle = config.replace(robot="turtlebot3_waffle_pi")
    assert waffle.car_width == 0.306 and waffle.max_speed == 0.26
    assert EnvConfig.from_dict(config.to_dict()) == config
    with pytest.raises(ConfigError, match="robot: expected one of paper_car, turtlebot3_burger"):
        EnvConfig.from_dict({"robot": "roomba"})


def test_the_trace_margin_scales_with_the_body_unless_set() -> None:
    burger = EnvConfig.from_dict({"robot": "turtlebot3_burger"})
    assert burger.body_scale == pytest.approx(0.5 * math.hypot(0.138, 0.178)
                                              / (0.5 * math.hypot(0.8, 0.5)))
    assert burger.trace_margin == pytest.approx(0.3 * burger.body_scale)
    assert burger.replace(car_length=0.276).trace_margin > burger.trace_margin  # derived anew
    fixed = EnvConfig.from_dict({"robot": "turtlebot3_burger", "trace_margin": 0.05})
    assert fixed.trace_margin == 0.05 and fixed.replace(car_length=0.3).trace_margin == 0.05
    assert ROBOTS["f1tenth"].lidars[0].fov == pytest.approx(1.5 * math.pi)
