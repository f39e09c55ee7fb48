"""Read and write SE(2) pose graphs in the g2o text format.

Lines (whitespace separated, ``#`` starts a comment, blank lines are skipped)::

    VERTEX_SE2 id x y theta
    EDGE_SE2 i j dx dy dtheta I11 I12 I13 I22 I23 I33

``(dx, dy, dtheta)`` is the pose of vertex ``j`` in the frame of vertex ``i`` and ``I..`` the
upper triangle of its 3x3 information matrix; metres and radians. A file without
``VERTEX_SE2`` lines (M3500, CSAIL) gets an initial guess by composing the odometry chain,
the edges ``i -> i + 1``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from estimators.slam.pose_graph import PoseGraph
from lidar_env.core import DualLidarError, LogFormatError
from lidar_env.core.se2 import compose

_FIELDS = {"VERTEX_SE2": 5, "EDGE_SE2": 12}  # words per line, tag included
_UPPER = np.triu_indices(3)


class G2oFormatError(LogFormatError):
    """A g2o file that cannot be read; the message names the file and line."""


def read_g2o(path: str | os.PathLike[str]) -> PoseGraph:
    """Load a g2o SE(2) pose graph; node ids keep the file's vertex ids, in first-seen order.

    Raises:
        G2oFormatError: unknown tag, wrong number of fields, a non-number, an edge between
            unknown vertices, a missing odometry link when vertices must be inferred, or an
            information matrix that is not positive definite.
    """
    path = Path(path)
    vertices: dict[int, NDArray[np.float64]] = {}
    vertex_lines: dict[int, int] = {}
    edges: list[tuple[int, int, int, NDArray[np.float64], NDArray[np.float64]]] = []
    with path.open("rb") as stream:
        for line_no, raw in enumerate(stream, start=1):
            where = f"{path}:{line_no}"
            words = _data_words(raw, where)
            if not words:
                continue
            tag = words[0]
            if tag not in _FIELDS:
                raise G2oFormatError(
                    f"{where}: unknown tag {tag!r}; expected one of {', '.join(_FIELDS)}"
                )
            if len(words) != _FIELDS[tag]:
                raise G2oFormatError(
                    f"{where}: {tag} expects {_FIELDS[tag] - 1} values, got {len(words) - 1}"
                )
            try:
                ids = [int(w) for w in words[1 : 2 if tag == "VERTEX_SE2" else 3]]
                values = np.array([float(w) for w in words[1 + len(ids) :]])
            except ValueError as err:
                raise G2oFormatError(f"{where}: {tag}: expected numbers ({err})") from None
            if not np.all(np.isfinite(values)):
                raise G2oFormatError(f"{where}: {tag}: expected finite numbers, got {values}")
            if tag == "VERTEX_SE2":
                if ids[0] in vertices:
                    raise G2oFormatError(f"{where}: vertex {ids[0]} defined twice")
                vertices[ids[0]] = values
                vertex_lines[ids[0]] = line_no
            else:
                info = np.zeros((3, 3))
                info[_UPPER] = values[3:]
                info = info + np.triu(info, 1).T
                edges.append((line_no, ids[0], ids[1], values[:3], info))

    if not vertices:
        vertices = _compose_odometry(path, edges)
    graph = PoseGraph()
    for node_id, pose in vertices.items():
        try:
            graph.add_node(pose, node_id)
        except DualLidarError as err:
            where = f"{path}:{vertex_lines[node_id]}" if node_id in vertex_lines else str(path)
            raise G2oFormatError(f"{where}: VERTEX_SE2 {node_id}: {err}") from None
    for line_no, i, j, z, info in edges:
        where = f"{path}:{line_no}"
        for node_id in (i, j):
            if node_id not in vertices:
                raise G2oFormatError(f"{where}: EDGE_SE2 refers to undefined vertex {node_id}")
        try:
            graph.add_edge(graph.index_of(i), graph.index_of(j), z, info)
        except DualLidarError as err:
            raise G2oFormatError(f"{where}: {err}") from None
    return graph


def _data_words(raw: bytes, where: str) -> list[str]:
    """The words of one line before its ``#`` comment (a comment may hold any bytes; the data
    must be UTF-8)."""
    data = raw.split(b"#", 1)[0]
    try:
        return data.decode("utf-8").split()
    except UnicodeDecodeError as err:
        raise G2oFormatError(
            f"{where}: expected UTF-8 text, got byte 0x{data[err.start]:02x} at column "
            f"{err.start + 1}"
        ) from None


def _compose_odometry(
    path: Path, edges: list[tuple[int, int, int, NDArray[np.float64], NDArray[np.float64]]]
) -> dict[int, NDArray[np.float64]]:
    """Initial poses from chaining the edges ``i -> i + 1``, from the smallest id at the origin."""
    if not edges:
        return {}
    odometry = {i: z for _, i, j, z, _ in edges if j == i + 1}
    all_ids = sorted({i for _, i, _, _, _ in edges} | {j for _, _, j, _, _ in edges})
    first = all_ids[0]
    poses = {first: np.zeros(3)}
    for node_id in all_ids[1:]:
        if node_id - 1 not in odometry:
            raise G2oFormatError(
                f"{path}: no VERTEX_SE2 lines and no odometry edge {node_id - 1} -> {node_id}; "
                "expected a chain of edges i -> i+1 to build the initial guess from"
            )
        poses[node_id] = compose(poses[node_id - 1], odometry[node_id - 1])
    return poses


def write_g2o(graph: PoseGraph, path: str | os.PathLike[str]) -> None:
    """Save ``graph`` (its current poses as vertices, all its edges) as a g2o file."""
    ids = graph.ids
    lines = [
        f"VERTEX_SE2 {node_id} {x:.17g} {y:.17g} {th:.17g}"
        for node_id, (x, y, th) in zip(ids, graph.poses, strict=True)
    ]
    for (i, j), z, info in zip(graph.edges, graph.measurements, graph.information, strict=True):
        values = " ".join(f"{v:.17g}" for v in (*z, *info[_UPPER]))
        lines.append(f"EDGE_SE2 {ids[i]} {ids[j]} {values}")
    Path(path).write_text("\n".join(lines) + "\n")
