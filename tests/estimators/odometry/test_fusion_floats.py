"""The pose algebra on Python floats (``pc_fusion``'s) against :mod:`lidar_env.core.se2`'s batches,
bit for bit
(a step composes some thirty poses, whose array conversions cost more than the
arithmetic)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from lidar_env.core.se2 import (
    compose,
    compose_floats,
    inverse,
    inverse_floats,
    relative,
    relative_floats,
)

coordinates = st.floats(-100.0, 100.0, allow_nan=False)
poses = st.tuples(coordinates, coordinates, st.floats(-10.0, 10.0, allow_nan=False))


@settings(max_examples=300, deadline=None)
@given(poses, poses)
def test_compose_floats_is_se2_compose_bit_for_bit(
    a: tuple[float, float, float], b: tuple[float, float, float]
) -> None:
    expected = compose(np.array([a]), np.array([b]))[0]  # the batch path, not the float one
    assert np.array_equal(np.array(compose_floats(a, b)), expected)
    # and a relative pose, as the estimator chains them
    assert np.array_equal(np.array(compose_floats(inverse_floats(a), b)),
                          relative(np.array([a]), np.array([b]))[0])
    assert np.array_equal(np.array(relative_floats(a, b)),
                          relative(np.array([a]), np.array([b]))[0])


@settings(max_examples=300, deadline=None)
@given(poses)
def test_inverse_floats_is_se2_inverse_bit_for_bit(a: tuple[float, float, float]) -> None:
    assert np.array_equal(np.array(inverse_floats(a)), inverse(np.array([a]))[0])


def test_floats_compose_back_to_the_identity() -> None:
    pose = (1.5, -0.25, 2.0)
    assert np.allclose(compose_floats(pose, inverse_floats(pose)), 0.0, atol=1e-12)
