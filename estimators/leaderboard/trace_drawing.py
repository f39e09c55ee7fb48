"""Drawing helpers shared by the leaderboard's figures: the world's obstacles as a light fill
(:func:`draw_obstacles`), a trace clipped to the world with an arrow where it leaves
(:func:`draw_clipped_trace`, :func:`clip_to_bounds`), the position error along the distance
travelled (:func:`error_along_distance`) and a legend in a figure margin, off the data
(:func:`legend_outside`). Poses are ``(N, 3)`` car poses ``(x [m], y [m], heading [rad])``
in the world frame.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from estimators.leaderboard.style import (
    ESTIMATE_WIDTH,
    TRUTH,
    TRUTH_WIDTH,
    estimator_style,
    obstacle_colormap,
)

#: Pixel side [m] of the obstacle picture under the traces.
OBSTACLE_RESOLUTION = 0.05
#: Where truth and estimates sit in the drawing order (truth on top).
ESTIMATE_LAYER, TRUTH_LAYER, ARROW_LAYER = 3, 5, 6


def draw_obstacles(axes: Any, world: Any) -> tuple[float, float, float, float]:
    """Fill ``world``'s obstacles (a :class:`lidar_env.World`) on ``axes``; returns its bounds
    ``(xmin, ymin, xmax, ymax)`` [m]."""
    from scipy.ndimage import binary_dilation

    xmin, ymin, xmax, ymax = world.bounds
    # one pixel thicker, so that a wall drawn one pixel wide stays visible when scaled down
    occupied = binary_dilation(world.to_image(OBSTACLE_RESOLUTION) > 0)
    axes.imshow(occupied, cmap=obstacle_colormap(), vmin=0, vmax=1, interpolation="nearest",
                extent=(xmin, xmax, ymin, ymax), zorder=0)
    return xmin, ymin, xmax, ymax


def clip_to_bounds(points: NDArray[np.float64], bounds: Sequence[float]
                   ) -> tuple[NDArray[np.float64], list[tuple[NDArray[np.float64], float]]]:
    """``points`` (N, 2) [m] with every point outside ``bounds`` (xmin, ymin, xmax, ymax) set
    to NaN (so a line breaks there), and the exits: the last inside point before each run of
    outside points with the direction [rad] the trace takes there."""
    xmin, ymin, xmax, ymax = bounds
    inside = ((points[:, 0] >= xmin) & (points[:, 0] <= xmax) & (points[:, 1] >= ymin)
              & (points[:, 1] <= ymax))
    clipped = np.where(inside[:, None], points, np.nan)
    exits = []
    for index in np.flatnonzero(inside[:-1] & ~inside[1:]):
        step = points[index + 1] - points[index]
        exits.append((points[index], float(np.arctan2(step[1], step[0]))))
    return clipped, exits


def draw_clipped_trace(axes: Any, poses: NDArray[np.float64], bounds: Sequence[float],
                       name: str | None) -> None:
    """One trace on ``axes``: the truth (``name`` None, black, on top) or estimator ``name``
    in its fixed style, clipped to ``bounds`` with an arrow at each exit from the world."""
    style = TRUTH if name is None else estimator_style(name)
    points, exits = clip_to_bounds(np.asarray(poses, dtype=np.float64)[:, :2], bounds)
    axes.plot(points[:, 0], points[:, 1], "-", color=style.colour,
              linewidth=TRUTH_WIDTH if name is None else ESTIMATE_WIDTH,
              label="truth" if name is None else name,
              zorder=TRUTH_LAYER if name is None else ESTIMATE_LAYER)
    span = 0.04 * max(bounds[2] - bounds[0], bounds[3] - bounds[1])
    for point, direction in exits:
        tail = point - span * np.array([np.cos(direction), np.sin(direction)])
        axes.annotate("", xy=tuple(point), xytext=tuple(tail), zorder=ARROW_LAYER,
                      arrowprops={"arrowstyle": "-|>", "color": style.colour, "lw": 1.5,
                                  "mutation_scale": 14}, annotation_clip=False)


def error_along_distance(estimate: NDArray[np.float64], truth: NDArray[np.float64]
                         ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Distance travelled along the truth [m] and position error [m] at every step, for two
    ``(N, 3)`` pose arrays of the same steps."""
    distance = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(truth[:, :2], axis=0).T))])
    error = np.hypot(*(estimate[:, :2] - truth[:, :2]).T)
    return distance, error


def legend_outside(figure: Any, axes: Any, title: str | None = None) -> None:
    """One legend for the whole figure, in the right margin (it covers no data); entries of
    ``axes`` (and of every axes of the figure, without repeats)."""
    handles: dict[str, Any] = {}
    for each in [axes, *figure.axes]:
        for handle, label in zip(*each.get_legend_handles_labels(), strict=True):
            handles.setdefault(label, handle)
    if handles:
        figure.legend(list(handles.values()), list(handles), loc="outside right upper",
                      fontsize="small", title=title)
