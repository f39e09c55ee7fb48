"""Pure polygon geometry in the plane, on numpy arrays (coordinates in metres, any frame).

What :class:`~lidar_env.world.world.World` needs to validate and fill its polygons: the input
validators (:func:`as_rows`, :func:`as_polygon`), the shoelace area, a polygon's edges as
``x1, y1, x2, y2`` rows, point-to-segment distances, the even-odd point-in-polygon test, and
the convex decomposition pymunk needs to make a polygon solid (with collinear-vertex removal
and an ear-clipping fallback). A polygon is a ``(k, 2)`` float64 array of vertices, closed
implicitly, in either orientation (counter-clockwise has positive area).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lidar_env.core.errors import MapError


def as_float_array(values: ArrayLike, what: str, shape: str) -> NDArray[np.float64]:
    """``values`` as float64, or a :class:`MapError` naming ``what`` (strings, ragged nesting,
    complex numbers, None) that says the ``shape`` expected."""
    try:
        if np.iscomplexobj(values):
            raise MapError(f"{what}: expected real numbers of shape {shape}, got complex values")
        return np.asarray(values, dtype=np.float64)
    except MapError:
        raise
    except (TypeError, ValueError) as error:
        raise MapError(
            f"{what}: expected numbers of shape {shape}, got {str(values)[:60]!r} ({error})"
        ) from None


def as_rows(values: ArrayLike, width: int, what: str) -> NDArray[np.float64]:
    """``values`` as a finite float64 ``(N, width)`` array (empty input gives ``(0, width)``)."""
    array = as_float_array(values, what, f"(N, {width})")
    if array.size == 0:
        return np.zeros((0, width))
    if array.ndim == 1 and array.shape[0] == width:
        array = array[None, :]
    if array.ndim != 2 or array.shape[1] != width:
        raise MapError(f"{what}: expected shape (N, {width}), got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise MapError(f"{what}: expected finite values, got NaN or inf")
    return array


def as_polygon(vertices: ArrayLike, index: int) -> NDArray[np.float64]:
    """One polygon as ``(k, 2)`` float64 with k >= 3 distinct vertices, closing vertex dropped."""
    polygon = as_float_array(vertices, f"polygons[{index}]", "(k, 2)")
    if polygon.ndim != 2 or polygon.shape[1] != 2:
        raise MapError(f"polygons[{index}]: expected shape (k, 2), got {polygon.shape}")
    if not np.all(np.isfinite(polygon)):
        raise MapError(f"polygons[{index}]: expected finite vertices, got NaN or inf")
    # Drop repeated consecutive vertices (including a closing copy of the first): they would
    # make zero-length edges.
    polygon = polygon[np.any(polygon != np.roll(polygon, 1, axis=0), axis=1)].copy()
    if len(polygon) < 3:
        raise MapError(f"polygons[{index}]: expected >= 3 distinct vertices, got {len(polygon)}")
    crossing = first_crossing(polygon_edges(polygon))
    if crossing is not None:
        raise MapError(
            f"polygons[{index}]: expected a simple polygon, got edges {crossing[0]} and "
            f"{crossing[1]} crossing (a self-intersecting outline such as a bowtie or a "
            "pentagram has no consistent inside: split it into simple polygons)"
        )
    if abs(signed_area(polygon)) <= 0.0:
        raise MapError(f"polygons[{index}]: expected a non-zero area, got collinear vertices")
    return polygon


def first_crossing(edges: NDArray[np.float64], block: int = 256) -> tuple[int, int] | None:
    """The first pair ``(i, j)`` of non-adjacent ``edges`` ``(k, 4)`` of one closed outline
    that cross properly (touching at a point does not count), or None. Vectorised in blocks
    of ``block`` edges against all later ones: O(k^2) work, O(block k) memory."""
    k = len(edges)
    a, b = edges[:, 0:2], edges[:, 2:4]
    for start in range(0, k, block):
        i = np.arange(start, min(start + block, k))[:, None]
        j = np.arange(k)[None, :]
        candidate = (j > i + 1) & ~((i == 0) & (j == k - 1))  # not itself, not neighbours
        if not candidate.any():
            continue
        p, r = a[i[:, 0]][:, None, :], (b - a)[i[:, 0]][:, None, :]
        q, s = a[None, :, :], (b - a)[None, :, :]
        d1 = _cross(r, q - p)
        d2 = _cross(r, q + s - p)
        d3 = _cross(s, p - q)
        d4 = _cross(s, p + r - q)
        hits = candidate & (d1 * d2 < 0) & (d3 * d4 < 0)
        if hits.any():
            row, col = np.argwhere(hits)[0]
            return int(i[row, 0]), int(col)
    return None


def _cross(u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def signed_area(polygon: NDArray[np.float64]) -> float:
    """Shoelace area [m^2] of a ``(k, 2)`` polygon, positive when counter-clockwise; taken
    about the first vertex, so a small polygon far from the origin keeps its area."""
    x, y = (polygon - polygon[0]).T
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def polygon_edges(polygon: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(k, 4)`` edges ``x1, y1, x2, y2`` of a closed polygon."""
    return np.hstack([polygon, np.roll(polygon, -1, axis=0)])


def segment_distances(points: NDArray[np.float64], segments: NDArray[np.float64]) -> NDArray:
    """``(N, M)`` Euclidean distance [m] from each point ``(N, 2)`` to each segment ``(M, 4)``."""
    start = segments[None, :, 0:2]
    edge = segments[None, :, 2:4] - start
    offset = points[:, None, :] - start
    length2 = np.maximum(np.sum(edge * edge, axis=-1), np.finfo(float).tiny)
    u = np.clip(np.sum(offset * edge, axis=-1) / length2, 0.0, 1.0)
    return np.linalg.norm(offset - u[..., None] * edge, axis=-1)


def even_odd_inside(points: NDArray[np.float64], edges: NDArray[np.float64]) -> NDArray[np.bool_]:
    """``(N,)`` True where a point has an odd number of ``edges`` (``(M, 4)``) to its right.

    The crossing-number test of a horizontal ray towards +x: with the edges of closed polygons it
    is the even-odd fill rule.
    """
    px, py = points[:, None, 0], points[:, None, 1]
    x1, y1, x2, y2 = (edges[None, :, i] for i in range(4))
    spans = (y1 > py) != (y2 > py)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_cross = x1 + (py - y1) * (x2 - x1) / (y2 - y1)
    crossings = spans & (px < x_cross)
    return (np.count_nonzero(crossings, axis=1) % 2) == 1


def convex_pieces(polygon: NDArray[np.float64]) -> list[NDArray[np.float64]]:
    """Convex pieces exactly covering a simple polygon: itself if convex, else pymunk's convex
    decomposition, or (if that fails or loses area) an ear-clip triangulation."""
    if _is_convex(polygon):
        return [polygon]
    from pymunk import autogeometry

    ccw = polygon if signed_area(polygon) > 0 else polygon[::-1]
    extent = float(np.ptp(polygon, axis=0).max())
    try:
        pieces = autogeometry.convex_decomposition([*map(tuple, ccw), tuple(ccw[0])], 0.0)
    except AssertionError:  # pymunk's way of rejecting a polygon it cannot decompose
        return _ear_clip(polygon)
    arrays = [
        cleaned
        for piece in pieces
        if len(cleaned := _drop_collinear(np.array([(v.x, v.y) for v in piece]), extent)) >= 3
    ]
    area = sum(abs(signed_area(piece)) for piece in arrays)
    if not np.isclose(area, abs(signed_area(polygon)), rtol=1e-9, atol=0.0):
        return _ear_clip(polygon)
    return arrays


def _drop_collinear(polygon: NDArray[np.float64], extent: float) -> NDArray[np.float64]:
    """The polygon without repeated vertices and vertices on the line through their
    neighbours (to 1e-12 of ``extent`` [m] squared, the size of the polygon it was cut from);
    fewer than 3 rows left means it had no area (pymunk's decomposition can return such
    slivers, e.g. 7.3.1 on a star)."""
    points = polygon
    while len(points) >= 3:
        before, after = np.roll(points, 1, axis=0), np.roll(points, -1, axis=0)
        cross = (points[:, 0] - before[:, 0]) * (after[:, 1] - before[:, 1]) - (
            points[:, 1] - before[:, 1]
        ) * (after[:, 0] - before[:, 0])
        keep = np.abs(cross) > 1e-12 * extent**2
        if keep.all():
            return points
        if not keep.any():
            return points[:0]
        # Drop one vertex at a time: removing both ends of a short edge at once could cut area.
        points = np.delete(points, int(np.argmin(np.abs(cross))), axis=0)
    return points[:0]


def _is_convex(polygon: NDArray[np.float64]) -> bool:
    edge = np.roll(polygon, -1, axis=0) - polygon
    turn = edge[:, 0] * np.roll(edge[:, 1], -1) - edge[:, 1] * np.roll(edge[:, 0], -1)
    return bool(np.all(turn >= 0) or np.all(turn <= 0))


def _ear_clip(polygon: NDArray[np.float64]) -> list[NDArray[np.float64]]:
    """Triangles of a simple polygon by ear clipping (O(k^2)); collinear slivers are dropped."""
    vertices = polygon if signed_area(polygon) > 0 else polygon[::-1]
    remaining = list(range(len(vertices)))
    triangles: list[NDArray[np.float64]] = []
    guard = 0
    while len(remaining) > 3 and guard < len(remaining):
        k = len(remaining)
        for position in range(k):
            i, j, m = remaining[position - 1], remaining[position], remaining[(position + 1) % k]
            a, b, c = vertices[i], vertices[j], vertices[m]
            cross = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
            if cross < 0:
                continue
            others = vertices[[v for v in remaining if v not in (i, j, m)]]
            if cross > 0 and np.any(_in_triangle(others, a, b, c)):
                continue
            if cross > 0:
                triangles.append(np.array([a, b, c]))
            del remaining[position]
            guard = 0
            break
        else:
            guard = len(remaining)  # no ear found: not a simple polygon; keep what we have
    if len(remaining) == 3:
        tri = vertices[remaining]
        if abs(signed_area(tri)) > 0:
            triangles.append(tri)
    return triangles


def _in_triangle(points: NDArray, a: NDArray, b: NDArray, c: NDArray) -> NDArray[np.bool_]:
    """``(N,)`` True where points lie inside or on the CCW triangle ``a, b, c``."""
    def side(p: NDArray, q: NDArray) -> NDArray:
        return (q[0] - p[0]) * (points[:, 1] - p[1]) - (q[1] - p[1]) * (points[:, 0] - p[0])

    return (side(a, b) >= 0) & (side(b, c) >= 0) & (side(c, a) >= 0)
