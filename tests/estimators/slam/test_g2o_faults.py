"""Hostile g2o files: a named ``LogFormatError`` with file and line, never a
bare decoding error, an overflow at write time, or a "converged" optimisation that did nothing."""

from __future__ import annotations

from pathlib import Path

import pytest

from estimators.slam.g2o import G2oFormatError, read_g2o, write_g2o
from estimators.slam.solver import optimize
from lidar_env.core.errors import LogFormatError

EDGE_INFO = "100 0 0 100 0 1000"
GOOD = (
    "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nVERTEX_SE2 2 2 0.1 0\n"
    f"EDGE_SE2 0 1 1 0 0 {EDGE_INFO}\nEDGE_SE2 1 2 1 0 0 {EDGE_INFO}\n"
)


def write(tmp_path: Path, data: bytes) -> Path:
    path = tmp_path / "graph.g2o"
    path.write_bytes(data)
    return path


def test_a_non_utf8_byte_in_a_comment_is_ignored(tmp_path):
    path = write(tmp_path, b"# caf\xe9 graph\n" + GOOD.encode())
    assert read_g2o(path).n_nodes == 3


def test_a_non_utf8_byte_in_the_data_is_named_with_its_line(tmp_path):
    path = write(tmp_path, GOOD.encode() + b"VERTEX_SE2 3 \xff 0 0\n")
    with pytest.raises(G2oFormatError, match=r":6: expected UTF-8 text, got byte 0xff"):
        read_g2o(path)


@pytest.mark.parametrize(
    ("line", "match"),
    [
        ("VERTEX_SE2 1180591620717411303424 3 0 0", r":6: VERTEX_SE2 \d+: node id: expected a 64"),
        ("VERTEX_SE2 3 1e200 0 0", r":6: VERTEX_SE2 3: node pose: expected \|x\|, \|y\| <= 1e\+09"),
        ("EDGE_SE2 0 2 1e200 0 0 " + EDGE_INFO, r":6: edge 0->2 measurement: expected \|x\|"),
        ("EDGE_SE2 0 2 2 0 0 1e-300 0 0 1e-300 0 1e-300", r":6: edge 0->2 information: expected "
                                                         "eigenvalues in"),
    ],
)
def test_out_of_range_values_are_named_with_their_line(tmp_path, line, match):
    path = write(tmp_path, (GOOD + line + "\n").encode())
    with pytest.raises(LogFormatError, match=match):
        read_g2o(path)


def test_a_graph_that_reads_writes_and_optimises(tmp_path):
    graph = read_g2o(write(tmp_path, GOOD.encode()))
    write_g2o(graph, tmp_path / "out.g2o")
    again = read_g2o(tmp_path / "out.g2o")
    result = optimize(again)
    assert result.converged
    assert float(result.chi2.sum()) < 1e-12
    assert abs(result.poses[2, 1]) < 1e-6  # the edges pull vertex 2 back onto the x axis
