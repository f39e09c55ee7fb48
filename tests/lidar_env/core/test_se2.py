import numpy as np
import pytest

from lidar_env.core import se2


def random_poses(rng: np.random.Generator, n: int) -> np.ndarray:
    return np.column_stack([rng.uniform(-5, 5, (n, 2)), rng.uniform(-np.pi, np.pi, n)])


def as_matrix(pose: np.ndarray) -> np.ndarray:
    c, s = np.cos(pose[2]), np.sin(pose[2])
    return np.array([[c, -s, pose[0]], [s, c, pose[1]], [0.0, 0.0, 1.0]])


def test_compose_matches_homogeneous_matrices() -> None:
    rng = np.random.default_rng(0)
    a, b = random_poses(rng, 50), random_poses(rng, 50)
    composed = se2.compose(a, b)
    for pa, pb, pc in zip(a, b, composed, strict=True):
        np.testing.assert_allclose(as_matrix(pc), as_matrix(pa) @ as_matrix(pb), atol=1e-12)


def test_inverse_and_relative_round_trip() -> None:
    rng = np.random.default_rng(1)
    a, b = random_poses(rng, 20), random_poses(rng, 20)
    np.testing.assert_allclose(se2.compose(a, se2.inverse(a)), np.zeros((20, 3)), atol=1e-12)
    recovered = se2.compose(a, se2.relative(a, b))
    np.testing.assert_allclose(recovered[:, :2], b[:, :2], atol=1e-12)
    np.testing.assert_allclose(se2.wrap_angle(recovered[:, 2] - b[:, 2]), 0.0, atol=1e-12)


def test_wrap_angle_range() -> None:
    wrapped = se2.wrap_angle(np.linspace(-20, 20, 1001))
    assert np.all(wrapped >= -np.pi) and np.all(wrapped < np.pi)
    assert se2.wrap_angle(np.pi) == pytest.approx(-np.pi)


def test_wrap_float_is_wrap_angle_bit_for_bit() -> None:
    rng = np.random.default_rng(6)
    angles = np.concatenate([[0.0, -0.0, np.pi, -np.pi, 3 * np.pi, -3 * np.pi, 1e-300],
                             rng.uniform(-50, 50, 3000), rng.normal(0, 1e6, 200)])
    wrapped = np.array([se2.wrap_float(float(angle)) for angle in angles])
    np.testing.assert_array_equal(wrapped.view(np.uint64), se2.wrap_angle(angles).view(np.uint64))


def test_transform_points_rotates_then_translates() -> None:
    points = np.array([[1.0, 0.0], [0.0, 2.0]])
    moved = se2.transform_points((1.0, -1.0, np.pi / 2), points)
    np.testing.assert_allclose(moved, [[1.0, 0.0], [-1.0, -1.0]], atol=1e-12)


def test_one_pose_at_a_time_is_the_batch_bit_for_bit() -> None:
    rng = np.random.default_rng(5)
    a = np.column_stack([rng.normal(0, 50, 3000), rng.normal(0, 50, 3000),
                         rng.uniform(-10, 10, 3000)])
    b = np.column_stack([rng.normal(0, 5, 3000), rng.normal(0, 5, 3000),
                         rng.uniform(-10, 10, 3000)])
    a[:4, 2], b[:4, 2] = (np.pi, -np.pi, 0.0, 3 * np.pi), (np.pi, -np.pi, -0.0, np.pi)
    for one, batch in ((np.array([se2.compose(p, q) for p, q in zip(a, b, strict=True)]),
                        se2.compose(a, b)),
                       (np.array([se2.inverse(p) for p in a]), se2.inverse(a))):
        np.testing.assert_array_equal(one.view(np.uint64), batch.view(np.uint64))
