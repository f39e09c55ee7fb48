"""g2o I/O: round trip, odometry initial guess, and readable errors with line numbers."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from estimators.paths import SHARED_DATA
from estimators.slam.g2o import G2oFormatError, read_g2o, write_g2o
from estimators.slam.pose_graph import PoseGraph
from lidar_env.core.se2 import compose

DATA = SHARED_DATA / "g2o"
EDGE_INFO = "10 1 0 20 0 30"


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "graph.g2o"
    path.write_text(text)
    return path


def test_round_trip_keeps_ids_poses_edges_and_information(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    graph = PoseGraph()
    for node_id in (7, 3, 11):
        graph.add_node(rng.normal(size=3) * [5, 5, 1], node_id)
    info = np.array([[10.0, 1.0, 0.5], [1.0, 20.0, -0.3], [0.5, -0.3, 30.0]])
    graph.add_edge(0, 1, [1.0, 0.1, 0.2], info)
    graph.add_edge(1, 2, [-0.5, 2.0, -3.0], 2 * info)
    path = tmp_path / "out.g2o"
    write_g2o(graph, path)
    back = read_g2o(path)
    np.testing.assert_array_equal(back.ids, [7, 3, 11])
    np.testing.assert_array_equal(back.poses, graph.poses)
    np.testing.assert_array_equal(back.edges, graph.edges)
    np.testing.assert_array_equal(back.measurements, graph.measurements)
    np.testing.assert_array_equal(back.information, graph.information)
    assert path.read_text().splitlines()[3].startswith("EDGE_SE2 7 3 ")


def test_upper_triangle_fills_a_symmetric_information_matrix(tmp_path: Path) -> None:
    path = write(tmp_path, "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\n"
                           "EDGE_SE2 0 1 1 0 0 1 2 0 1 0 1\n")
    with pytest.raises(G2oFormatError, match=":3: .*positive-definite"):
        read_g2o(path)  # that matrix is symmetric but indefinite: the error names line 3
    path = write(tmp_path, "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\n"
                           "EDGE_SE2 0 1 1 0 0 4 1 0.5 5 2 6\n")
    expected = [[4, 1, 0.5], [1, 5, 2], [0.5, 2, 6]]
    np.testing.assert_array_equal(read_g2o(path).information[0], expected)


def test_missing_vertices_are_composed_from_odometry(tmp_path: Path) -> None:
    z01, z12 = np.array([1.0, 0.0, np.pi / 2]), np.array([2.0, 0.5, 0.1])
    text = (f"EDGE_SE2 0 1 {z01[0]} {z01[1]} {z01[2]} {EDGE_INFO}\n"
            f"EDGE_SE2 1 2 {z12[0]} {z12[1]} {z12[2]} {EDGE_INFO}\n"
            f"EDGE_SE2 0 2 3 3 1.6 {EDGE_INFO}\n")
    graph = read_g2o(write(tmp_path, text))
    # by hand: after (1, 0, 90 deg), moving 2 forward and 0.5 left goes to (0.5, 2)
    np.testing.assert_allclose(graph.poses[2], [1.0 - 0.5, 2.0, np.pi / 2 + 0.1])
    np.testing.assert_allclose(graph.poses[2], compose(compose(np.zeros(3), z01), z12))


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("VERTEX_SE2 0 0 0 0\nVERTEX_XYZ 1 0 0 0\n", r":2: unknown tag 'VERTEX_XYZ'; expected"),
        ("VERTEX_SE2 0 0 0\n", r":1: VERTEX_SE2 expects 4 values, got 3"),
        ("# comment\n\nVERTEX_SE2 0 0 zero 0\n", r":3: VERTEX_SE2: expected numbers"),
        ("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 0 1 0 0\n", r":2: vertex 0 defined twice"),
        ("VERTEX_SE2 0 0 0 nan\n", r":1: VERTEX_SE2: expected finite numbers"),
        (f"VERTEX_SE2 0 0 0 0\nEDGE_SE2 0 5 1 0 0 {EDGE_INFO}\n", r":2: .*undefined vertex 5"),
        (f"EDGE_SE2 0 1 1 0 0 {EDGE_INFO}\nEDGE_SE2 2 3 1 0 0 {EDGE_INFO}\n",
         r"no odometry edge 1 -> 2"),
        ("VERTEX_SE2 0 0 0 0\nEDGE_SE2 0 0 1 0 0 1 0 0 1\n", r":2: EDGE_SE2 expects 11 values"),
    ],
)
def test_bad_files_raise_with_line_numbers(tmp_path: Path, text: str, match: str) -> None:
    with pytest.raises(G2oFormatError, match=match):
        read_g2o(write(tmp_path, text))


@pytest.mark.realdata
@pytest.mark.skipif(not DATA.is_dir(), reason=f"g2o benchmark graphs absent: expected {DATA}")
@pytest.mark.parametrize(("name", "nodes", "edges"),
                         [("intel", 1728, 2512), ("manhattan", 3500, 5453)])
def test_public_graphs_load_with_their_published_sizes(name: str, nodes: int, edges: int) -> None:
    graph = read_g2o(DATA / f"{name}.g2o")
    assert (graph.n_nodes, graph.n_edges) == (nodes, edges)
    assert np.all(np.isfinite(graph.poses))
