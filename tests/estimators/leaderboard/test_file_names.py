"""File names safe on every shell and file system, and the leaderboard's TUM files named so."""

from __future__ import annotations

import re

from hypothesis import given
from hypothesis import strategies as st

from estimators.leaderboard.file_names import MAX_NAME_LENGTH, safe_file_name

SAFE = re.compile(r"[A-Za-z0-9_+][A-Za-z0-9._+-]*")


def test_a_parameterised_scenario_label_reads_plainly() -> None:
    label = "closed_to_open?feature_density=0.9&feature_seed=0/zigzag/s0"
    assert safe_file_name(label) == "closed_to_open_feature_density-0.9_feature_seed-0_zigzag_s0"
    assert safe_file_name("hallway/zigzag/s0/world") == "hallway_zigzag_s0_world"
    assert safe_file_name("lidar_odometry") == "lidar_odometry"


def test_edge_cases() -> None:
    assert safe_file_name("") == safe_file_name("???") == "unnamed"
    assert safe_file_name("-rf") == "_-rf"
    assert safe_file_name(".hidden") == "_.hidden"
    assert safe_file_name("my drive (1).bag") == "my_drive_1_.bag"


@given(st.text(max_size=400))
def test_every_name_is_safe_short_and_long_names_stay_apart(text: str) -> None:
    name = safe_file_name(text)
    assert SAFE.fullmatch(name), name
    assert len(name) <= MAX_NAME_LENGTH
    if len(text) > MAX_NAME_LENGTH and text.isalnum() and text.isascii():
        assert safe_file_name(text + "x") != name
