"""Fuzz: CARMEN lines and g2o lines, valid ones with one field mutated."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from estimators.datasets.carmen import load_log
from estimators.slam.g2o import read_g2o
from estimators.slam.solver import optimize
from tests.fuzz.conftest import named_or_result

CARMEN = [
    "PARAM robot_frontlaser_offset 0.2 nohost 0",
    "ODOM 1.0 2.0 0.5 0.3 0.1 0.0 100.4 host 0.4",
    "FLASER 4 1.0 2.0 3.0 4.5 0.1 0.2 0.3 1.1 1.2 1.3 100.5 host 0.5",
    "ROBOTLASER1 0 -1.5 3.0 1.0 20.0 0.01 0 4 1.0 2.0 3.0 4.0 2 7 8 "
    "1.2 2.0 0.5 1.0 2.0 0.5 0.3 0.1 0.5 0.5 0.0 200.25 host 1.25",
]
G2O = [
    "VERTEX_SE2 0 0 0 0", "VERTEX_SE2 1 1 0 0", "VERTEX_SE2 2 2 0.1 0.1",
    "EDGE_SE2 0 1 1 0 0 100 0 0 100 0 1000", "EDGE_SE2 1 2 1 0 0 100 0 0 100 0 1000",
    "EDGE_SE2 0 2 2 0 0 50 0 0 50 0 500",
]
tokens = st.one_of(
    st.sampled_from(["nan", "inf", "-inf", "-1", "0", "1", "2", "abc", "", "1e308", "-0",
                     "4294967296", "1" * 30, "#", "FLASER", "\xe9"]),
    st.floats(allow_nan=False).map(repr), st.integers(-10**20, 10**20).map(str),
    st.text(max_size=4),
)


@st.composite
def mutated(draw, lines):
    """Valid lines with one token replaced, deleted or duplicated, or the line cut short."""
    lines = list(lines)
    index = draw(st.integers(0, len(lines) - 1))
    words = lines[index].split()
    position = draw(st.integers(0, len(words) - 1))
    action = draw(st.sampled_from(["replace", "delete", "duplicate", "truncate"]))
    if action == "replace":
        words[position] = draw(tokens)
    elif action == "delete":
        del words[position]
    elif action == "duplicate":
        words.insert(position, words[position])
    else:
        words = words[:position]
    lines[index] = " ".join(words)
    return "\n".join(lines) + "\n"


def read_text(tmp_path_factory, text, reader):
    """``reader`` of a fresh file holding ``text``, or None for a named error."""
    path = tmp_path_factory.mktemp("fuzz") / "input"
    path.write_bytes(text.encode("utf-8", "surrogatepass"))
    return named_or_result(lambda: reader(path))


@given(text=mutated(CARMEN))
def test_carmen_lines_are_named_or_read_correctly(tmp_path_factory, text):
    log = read_text(tmp_path_factory, text, load_log)
    if log is None:
        return
    for scan in log.scans:
        assert len(scan.ranges) == len(scan.angles) >= 2
        assert np.all(np.isfinite(scan.ranges)) and np.all(scan.ranges >= 0)
        assert np.all(np.isfinite(scan.laser_offset)) and np.isfinite(scan.timestamp)


@given(text=mutated(G2O))
def test_g2o_lines_are_named_or_optimised_to_finite_poses(tmp_path_factory, text):
    graph = read_text(tmp_path_factory, text, read_g2o)
    if graph is None:
        return
    result = named_or_result(lambda: optimize(graph))
    if result is not None:
        assert np.all(np.isfinite(result.poses))
