"""The slam back end's faster forms against the plain ones they replace, bit for bit: the
vectorised descriptor distances, the keyframe table's arrays, the solver's Jacobian layout
and damping, the pose graph's kept edge arrays and connectivity."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage

from estimators.base import SensorSetup
from estimators.matching.likelihood_grids import distance_scores
from estimators.slam.graph_slam import GraphSlam
from estimators.slam.keyframe_table import Keyframe, KeyframeTable, largest_shift
from estimators.slam.place_descriptor import descriptor_distance, descriptor_distances
from estimators.slam.pose_graph import DisconnectedGraphError, PoseGraph
from estimators.slam.solver import _damped, _diagonal_positions, _WhitenedProblem
from lidar_env.core.se2 import inverse, transform_points, wrap_angle


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), rows=st.integers(1, 60),
       bins=st.sampled_from([1, 7, 8, 9, 16, 40, 41, 130]))
def test_descriptor_distances_equal_the_one_by_one_distances(seed: int, rows: int,
                                                             bins: int) -> None:
    rng = np.random.default_rng(seed)
    others = rng.random((rows, bins))
    others /= others.sum(axis=1, keepdims=True)
    a = rng.random(bins)
    a /= a.sum()
    one_by_one = np.array([descriptor_distance(a, row) for row in others])
    assert np.array_equal(descriptor_distances(a, others), one_by_one)


def test_keyframe_table_holds_every_row_as_appended() -> None:
    rng = np.random.default_rng(1)
    table = KeyframeTable()
    keyframes = [Keyframe(np.zeros((0, 2)), rng.random(40), np.zeros(3), float(k))
                 for k in range(50)]  # past two doublings
    noise, drift = rng.random((2, 50, 3, 3))
    for keyframe, one, other in zip(keyframes, noise, drift, strict=True):
        table.append(keyframe, one, other)
    assert np.array_equal(table.path_lengths, np.arange(50.0))
    assert np.array_equal(table.descriptors, np.array([k.descriptor for k in keyframes]))
    assert np.array_equal(table.noise_covariances, noise)
    assert np.array_equal(table.drift_covariances, drift)


def random_graph(rng: np.random.Generator, n: int, loops: int) -> PoseGraph:
    graph = PoseGraph()
    for _ in range(n):
        graph.add_node([*rng.normal(size=2) * 5, wrap_angle(rng.normal() * 3)])
    pairs = [(k, k + 1) for k in range(n - 1)]
    pairs += [tuple(sorted(rng.choice(n, 2, replace=False))) for _ in range(loops)]
    for i, j in pairs:
        root = rng.normal(size=(3, 3))
        graph.add_edge(int(i), int(j), rng.normal(size=3), root @ root.T + 0.1 * np.eye(3),
                       is_loop=(i, j) not in pairs[: n - 1])
    return graph


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2, 30), loops=st.integers(0, 20),
       fixed=st.integers(0, 29))
def test_jacobian_layout_and_damping_equal_scipys_own_forms(seed: int, n: int, loops: int,
                                                            fixed: int) -> None:
    rng = np.random.default_rng(seed)
    graph = random_graph(rng, n, loops)
    problem = _WhitenedProblem(graph, fixed % n)
    x = graph.poses[problem.free].ravel() + 0.1 * rng.normal(size=3 * (n - 1))
    weight = rng.random(graph.n_edges) + 0.1
    ours = problem.jacobian(x, weight)
    # the COO form it replaces, converted by scipy
    reference = sp.csr_matrix((problem.jacobian_entries(x, weight), (problem.rows, problem.cols)),
                              shape=problem.shape)
    assert np.array_equal(ours.indptr, reference.indptr)
    assert np.array_equal(ours.indices, reference.indices)
    assert np.array_equal(ours.data, reference.data)
    hessian = (ours.T @ ours).tocsc()
    hessian.sum_duplicates()
    damping = 10.0 ** rng.uniform(-12, 12) * np.maximum(hessian.diagonal(), 1e-9)
    expected = (hessian + sp.diags(damping, format="csc")).tocsc()
    expected.sum_duplicates()
    got = _damped(hessian, damping, _diagonal_positions(hessian))
    got.sum_duplicates()
    assert np.array_equal(got.indptr, expected.indptr)
    assert np.array_equal(got.indices, expected.indices)
    assert np.array_equal(got.data, expected.data)


def test_kept_edge_arrays_follow_every_change() -> None:
    graph = random_graph(np.random.default_rng(2), 6, 3)
    edges = graph.edges
    edges[0] = 99  # a copy: the graph's own arrays are not handed out
    assert graph.edges[0].tolist() == [0, 1]
    graph.add_edge(0, 5, np.zeros(3), np.eye(3), is_loop=True)
    assert graph.edges[-1].tolist() == [0, 5] and graph.is_loop[-1]
    assert len(graph.measurements) == len(graph.information) == graph.n_edges
    graph.remove_edges([0])
    assert graph.edges[0].tolist() == [1, 2] and graph.n_edges == len(graph.is_loop)


def test_connectivity_is_checked_again_after_a_node_or_a_removal() -> None:
    graph = random_graph(np.random.default_rng(3), 4, 0)
    graph.check_connected()
    graph.add_node([0.0, 0.0, 0.0])  # no edge yet
    with pytest.raises(DisconnectedGraphError):
        graph.check_connected()
    graph.add_edge(3, 4, np.zeros(3), np.eye(3))
    graph.check_connected()
    graph.remove_edges([1])  # 0-1 | 2-3-4
    with pytest.raises(DisconnectedGraphError):
        graph.check_connected()


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 6),
       scale=st.sampled_from([1e-6, 1e-3, 0.1, 3.0]))
def test_largest_shift_bounds_every_points_move(seed: int, n: int, scale: float) -> None:
    rng = np.random.default_rng(seed)
    before = np.column_stack([rng.normal(size=(n, 2)) * 3, rng.uniform(-np.pi, np.pi, n)])
    after = before + scale * rng.normal(size=(n, 3))
    clouds = [rng.normal(size=(20, 2)) * rng.uniform(0.1, 20) for _ in range(n)]
    reach = np.array([np.hypot(*c.T).max() for c in clouds])
    moved = max(np.hypot(*(transform_points(a, c) - transform_points(b, c)).T).max()
                for a, b, c in zip(after, before, clouds, strict=True))
    bound = largest_shift(before, after, reach)
    assert moved <= bound * (1 + 1e-9) + 1e-12
    # tight for the farthest point turned about its origin
    assert bound <= np.hypot(*(after[:, :2] - before[:, :2]).T).max() + 2 * np.abs(
        np.sin(0.5 * (after[:, 2] - before[:, 2]))).max() * reach.max() + 1e-12


def room_slam(**settings: float) -> GraphSlam:
    """A slam fed its car-frame view of a 6 m x 4 m room along a circle, by exact odometry."""
    corners = np.array([[0.0, 0.0], [6.0, 0.0], [6.0, 4.0], [0.0, 4.0], [0.0, 0.0]])
    t = np.linspace(0, 1, 300)[:, None]
    walls = np.concatenate([a + t * (b - a) for a, b in zip(corners[:-1], corners[1:],
                                                              strict=True)])
    slam = GraphSlam(**settings)
    angles = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    slam.reset(SensorSetup(np.zeros((1, 3)), angles, 10.0), np.array([4.5, 2.0, np.pi / 2]))
    rng = np.random.default_rng(4)
    for angle in np.linspace(0, 2 * np.pi, 60):
        pose = np.array([3 + 1.5 * np.cos(angle), 2 + 1.2 * np.sin(angle), angle + np.pi / 2])
        local = transform_points(inverse(pose), walls) + 0.005 * rng.normal(size=walls.shape)
        slam.add_scan(local, pose)
    return slam


@pytest.mark.parametrize(("tolerance", "kept"), [(1e-3, True), (1e-4, False), (0.0, False)])
def test_a_place_map_is_kept_while_its_points_moved_less_than_the_tolerance(
        tolerance: float, kept: bool) -> None:
    slam = room_slam(place_tolerance=tolerance, keyframe_distance=0.3)
    first = slam._place(3)
    assert slam._place(3) is first  # nothing moved
    slam.graph.set_pose(4, slam.graph.poses[4] + [5e-4, 0.0, 0.0])  # a neighbour, 0.5 mm
    assert (slam._place(3) is first) == kept


def test_at_most_max_places_maps_are_kept() -> None:
    slam = room_slam(max_places=2, keyframe_distance=0.3)
    for index in (2, 5, 8):
        slam._place(index)
    assert list(slam._places) == [(5, 2), (8, 2)]


@settings(max_examples=150, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), rows=st.integers(1, 90), cols=st.integers(1, 90),
       density=st.sampled_from([1e-4, 2e-3, 0.02, 0.3]), table=st.integers(1, 400))
def test_distance_scores_with_a_short_table_end_at_its_last_score(
        seed: int, rows: int, cols: int, density: float, table: int) -> None:
    """Parabolas at or beyond the table's end are left out of each row's envelope, and rows
    with none left get the last score: the values of the whole transform, clipped."""
    rng = np.random.default_rng(seed)
    occupied = rng.random((rows, cols)) < density
    occupied[tuple(rng.integers(0, (rows, cols)))] = True
    squared = np.rint(ndimage.distance_transform_edt(~occupied) ** 2)
    scores = rng.random(table)  # any table: each squared distance picks its entry
    assert np.array_equal(distance_scores(occupied, scores),
                          scores[np.minimum(squared, table - 1).astype(np.int64)])
