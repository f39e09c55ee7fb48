"""SE(2) poses as plain arrays ``(x [m], y [m], heading [rad])``.

Every function accepts a single pose of shape ``(3,)`` or a batch ``(N, 3)`` and
broadcasts; headings are wrapped to ``[-pi, pi)``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

Pose = NDArray[np.float64]
#: One pose (x [m], y [m], heading [rad]) as three Python floats (:func:`compose_floats`).
PoseFloats = tuple[float, float, float]
_TWO_PI = 2.0 * np.pi


def wrap_angle(angle: ArrayLike) -> NDArray[np.float64]:
    """Wrap angles [rad] to ``[-pi, pi)``."""
    return (np.asarray(angle, dtype=np.float64) + np.pi) % (2.0 * np.pi) - np.pi


def wrap_float(angle: float) -> float:
    """:func:`wrap_angle` of one Python float, on the float: the same operations, bit for bit
    (Python's float ``%`` takes the divisor's sign, as ``np.remainder``), without numpy's
    per-call cost."""
    return (angle + math.pi) % _TWO_PI - math.pi


def compose(a: ArrayLike, b: ArrayLike) -> Pose:
    """``a ⊕ b``: pose ``b`` (given in the frame of ``a``) expressed in the frame ``a`` lives in."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if a.shape == b.shape == (3,):  # one pose: the same operations on Python floats
        return np.array(compose_floats(a.tolist(), b.tolist()))
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = a[..., 0] + c * b[..., 0] - s * b[..., 1]
    y = a[..., 1] + s * b[..., 0] + c * b[..., 1]
    return np.stack([x, y, wrap_angle(a[..., 2] + b[..., 2])], axis=-1)


def compose_floats(a: Sequence[float], b: Sequence[float]) -> PoseFloats:
    """:func:`compose` of two poses of three Python floats: the batch's operations in its
    order, bit for bit (``math.cos``/``sin`` are the C library's, as numpy's float64 loops;
    Python's float ``%`` takes the divisor's sign, as ``np.remainder``), without the array
    conversions, which cost more than the arithmetic (a third of numpy scalars' cost)."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], wrap_float(a[2] + b[2])


def inverse_floats(a: Sequence[float]) -> PoseFloats:
    """:func:`inverse` of a pose of three Python floats, bit for bit (as :func:`compose_floats`)."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return -c * a[0] - s * a[1], s * a[0] - c * a[1], wrap_float(-a[2])


def relative_floats(a: Sequence[float], b: Sequence[float]) -> PoseFloats:
    """:func:`relative` of two poses of three Python floats, bit for bit (as
    :func:`compose_floats`): pose ``b`` in the frame of pose ``a``."""
    return compose_floats(inverse_floats(a), b)


def inverse(a: ArrayLike) -> Pose:
    """``a⁻¹``: the pose of the parent frame seen from frame ``a``."""
    a = np.asarray(a, dtype=np.float64)
    if a.shape == (3,):  # one pose: the same operations on Python floats
        return np.array(inverse_floats(a.tolist()))
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = -c * a[..., 0] - s * a[..., 1]
    y = s * a[..., 0] - c * a[..., 1]
    return np.stack([x, y, wrap_angle(-a[..., 2])], axis=-1)


def relative(a: ArrayLike, b: ArrayLike) -> Pose:
    """``a⁻¹ ⊕ b``: pose ``b`` expressed in the frame of pose ``a`` (both in the same parent)."""
    return compose(inverse(a), b)


def rotate(angle: ArrayLike, vectors: ArrayLike) -> NDArray[np.float64]:
    """``R(angle) v``: vectors ``(2,)`` or ``(N, 2)`` turned CCW by ``angle`` [rad], one angle
    for all or one per row ``(N,)``."""
    angle = np.asarray(angle, dtype=np.float64)
    vectors = np.asarray(vectors, dtype=np.float64)
    c, s = np.cos(angle), np.sin(angle)
    x, y = vectors[..., 0], vectors[..., 1]
    return np.stack([c * x - s * y, s * x + c * y], axis=-1)


def transform_points(pose: ArrayLike, points: ArrayLike) -> NDArray[np.float64]:
    """Map points ``(N, 2)`` given in the frame ``pose`` into that pose's parent frame:
    ``rotate(pose[2], points) + pose[:2]``, computed as one matrix product (whose rounding
    differs from :func:`rotate`'s in the last bit; every stored trajectory was made with it)."""
    pose = np.asarray(pose, dtype=np.float64)
    points = np.asarray(points, dtype=np.float64)
    c, s = np.cos(pose[2]), np.sin(pose[2])
    rotation = np.array([[c, -s], [s, c]])
    return points @ rotation.T + pose[:2]
